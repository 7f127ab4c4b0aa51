"""Flight processes forked warm (`simbridge/zygote.py`) behave as the processes `python -m`
starts: their output, exit codes, signals, titles and timeouts; flights flown through them
are tested everywhere else (`fly` starts both of a flight's processes this way)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from simbridge.launch import LISTENING, SIM_IMPORTS, sim_command
from simbridge.zygote import WarmProcess, popen, reaped_cpu_s

PIPES = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True}


def groundfx(*args: str) -> list[str]:
    return [sys.executable, "-m", "mission.cli", *args]


def test_a_forked_command_prints_and_exits_as_python_m_would() -> None:
    warm = popen(groundfx("sim", "--help"), SIM_IMPORTS, **PIPES)
    assert isinstance(warm, WarmProcess)
    out, err = warm.communicate(timeout=60)
    assert warm.returncode == 0 and out.startswith("usage: groundfx sim") and err == ""
    cold = subprocess.run(groundfx("sim", "--help"), capture_output=True, text=True, timeout=60)
    assert out == cold.stdout
    bad = popen(groundfx("sim", "--speedup", "fast"), SIM_IMPORTS, **PIPES)
    out, err = bad.communicate(timeout=60)
    assert bad.returncode == 2 and "--speedup" in err and out == ""


def test_a_forked_simulator_shows_its_command_waits_and_dies_by_its_signal(tmp_path: Path) -> None:
    """... and its CPU time is counted, as a child's would be (a campaign's records)."""
    cpu_s = reaped_cpu_s()
    sim = popen(sim_command("default"), SIM_IMPORTS, cwd=tmp_path, **PIPES)
    try:
        assert sim.stdout is not None and sim.stdout.readline().startswith(LISTENING)
        title = Path(f"/proc/{sim.pid}/cmdline").read_bytes().replace(b"\0", b" ").split()
        assert title[1:4] == [b"-m", b"mission.cli", b"sim"]
        assert Path(f"/proc/{sim.pid}/cwd").resolve() == tmp_path.resolve()
        assert sim.poll() is None
        with pytest.raises(subprocess.TimeoutExpired):
            sim.wait(timeout=0.2)
        os.kill(sim.pid, signal.SIGKILL)
        assert sim.wait(timeout=30) == -signal.SIGKILL
        assert reaped_cpu_s() > cpu_s  # it loaded its world and opened its port
    finally:
        if sim.poll() is None:
            sim.kill()
        sim.communicate(timeout=30)


def test_warm_start_can_be_turned_off_and_other_commands_start_as_asked(monkeypatch) -> None:
    monkeypatch.setenv("GROUNDFX_WARM_START", "0")
    off = popen(groundfx("sim", "--help"), SIM_IMPORTS, **PIPES)
    assert not isinstance(off, WarmProcess) and off.communicate(timeout=60)[0]
    monkeypatch.delenv("GROUNDFX_WARM_START")
    other = popen([sys.executable, "-c", "print('cold')"], (), **PIPES)
    assert not isinstance(other, WarmProcess) and other.communicate(timeout=60)[0] == "cold\n"


def test_a_launcher_without_stdin_starts_its_children_warm() -> None:
    """A multiprocessing worker (every campaign's flights) has closed its stdin: the child
    reads /dev/null."""
    script = (
        "import os, subprocess, sys\n"
        "os.close(0)\n"
        "from simbridge.launch import SIM_IMPORTS\n"
        "from simbridge.zygote import popen\n"
        "p = popen([sys.executable, '-m', 'mission.cli', 'sim', '--help'], SIM_IMPORTS,\n"
        "          stdout=subprocess.PIPE, text=True)\n"
        "out, _ = p.communicate(timeout=60)\n"
        "print(type(p).__name__, out.split()[0], p.returncode)\n"
    )
    command = [sys.executable, "-c", script]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.stdout.split() == ["WarmProcess", "usage:", "0"], done.stderr


def test_a_command_whose_imports_fail_reports_it_as_python_m_would(tmp_path: Path) -> None:
    """The zygote imports nothing it cannot: the child raises the error and the next flight
    process still starts warm."""
    (tmp_path / "broken_command.py").write_text("import no_such_module_here\n")
    broken = popen([sys.executable, "-m", "broken_command"], ("broken_command",), cwd=tmp_path,
                   **PIPES)  # fmt: skip
    err = broken.communicate(timeout=60)[1]
    assert isinstance(broken, WarmProcess) and broken.returncode == 1
    assert "ModuleNotFoundError: No module named 'no_such_module_here'" in err
    after = popen(groundfx("sim", "--help"), SIM_IMPORTS, **PIPES)
    assert isinstance(after, WarmProcess) and after.communicate(timeout=60)[0]
