"""Start `groundfx sim` as a separate process on an ephemeral port and learn its port."""

from __future__ import annotations

import ctypes
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from simbridge.zygote import popen

LISTENING = "groundfx sim: listening on tcp:"  # the line that gives the port
# what `groundfx sim` imports before its first step, for a zygote to import once
SIM_IMPORTS = ("mission.cli", "mission.cli.main", "mission.cli.sim", "simbridge.server")


class SimProcessError(RuntimeError):
    pass


def sim_command(
    world: str | Path = "default",
    *,
    speedup: str = "max",
    start: str | None = None,
    extra: list[str] | None = None,
    lockstep_start: bool = False,
    unix_path: str | Path | None = None,
) -> list[str]:
    """The command line of a `groundfx sim` process (on an ephemeral TCP port, or on a
    Unix-domain socket at `unix_path`)."""
    cmd = [sys.executable, "-m", "mission.cli", "sim", "--world", str(world)]
    cmd += ["--port", "0"] if unix_path is None else ["--unix", str(unix_path)]
    cmd += ["--speedup", speedup]
    if start is not None:
        cmd.append(f"--start={start}")  # a leading minus would read as an option
    if lockstep_start:
        cmd.append("--lockstep-start")
    return cmd + (extra or [])


def start_sim(
    world: str | Path = "default",
    *,
    speedup: str = "max",
    start: str | None = None,
    extra: list[str] | None = None,
    supervised: bool = False,
    lockstep_start: bool = False,
) -> tuple[subprocess.Popen[str], int]:
    """The simulator process and the TCP port it listens on (it prints it first).
    `lockstep_start`: for our own autopilot's reproducible flights (`groundfx sim --help`);
    `supervised`: see `supervised_options`."""
    cmd = sim_command(
        world, speedup=speedup, start=start, extra=extra, lockstep_start=lockstep_start
    )
    pipes: dict[str, Any] = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True}
    if supervised:
        proc = subprocess.Popen(cmd, **pipes, **supervised_options())
    else:
        proc = popen(cmd, SIM_IMPORTS, **pipes)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith(LISTENING):
        proc.kill()
        _, err = proc.communicate(timeout=10)
        raise SimProcessError(f"groundfx sim did not start: {(line + err).strip()}")
    return proc, int(line.rsplit(":", 1)[1])


def spawn_local_sim(
    world: str | Path,
    unix_path: Path,
    *,
    speedup: str = "max",
    start: str | None = None,
    extra: list[str] | None = None,
) -> subprocess.Popen[str]:
    """A simulator for an autopilot of ours, on a Unix-domain socket, in lockstep from its
    first tick; not waited for: the autopilot, started beside it, connects as soon as it
    listens (it retries), so that the two processes' start-ups overlap."""
    cmd = sim_command(
        world, speedup=speedup, start=start, extra=extra, lockstep_start=True, unix_path=unix_path
    )
    return popen(cmd, SIM_IMPORTS, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(proc: subprocess.Popen[str], timeout_s: float = 10.0) -> str:
    """Wait for the simulator to end after its client left; returns its last stdout line,
    or, from a simulator that failed without a last word, how it ended."""
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    lines = [ln for ln in (out or "").splitlines() if ln.strip()]
    if proc.returncode == 0 or (lines and proc.returncode > 0):
        return lines[-1] if lines else ""
    return exit_reason(proc, err or "")


def exit_reason(proc: subprocess.Popen[str], stderr: str) -> str:
    """How a simulator process that failed ended: its exit code or signal, and its last
    line on stderr (a traceback's error) if it left one."""
    code = proc.returncode
    how = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exited with code {code}"
    last = [ln for ln in stderr.splitlines() if ln.strip()]
    return f"groundfx sim {how}" + (f": {last[-1].strip()}" if last else "")


def supervised_options() -> dict[str, Any]:
    """Popen options for a child its parent stops in order (`groundfx sitl`): in a process
    group of its own, so a terminal's Ctrl-C reaches only the parent, and (on Linux) sent
    SIGTERM if the parent dies without stopping it, so nothing is left holding ports."""
    return {"process_group": 0, "preexec_fn": _terminate_with_parent}


def _terminate_with_parent() -> None:
    if sys.platform.startswith("linux"):
        pr_set_pdeathsig = 1
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGTERM))
