"""Start `groundfx sim` as a separate process on an ephemeral port and learn its port."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

LISTENING = "groundfx sim: listening on tcp:"


class SimProcessError(RuntimeError):
    pass


def start_sim(
    world: str | Path = "default",
    *,
    speedup: str = "max",
    start: str | None = None,
    extra: list[str] | None = None,
) -> tuple[subprocess.Popen[str], int]:
    """The simulator process and the TCP port it listens on (it prints it first)."""
    cmd = [
        sys.executable,
        "-m",
        "mission.cli",
        "sim",
        "--world",
        str(world),
        "--port",
        "0",
        "--speedup",
        speedup,
    ]
    if start is not None:
        cmd.append(f"--start={start}")  # a leading minus would read as an option
    cmd += extra or []
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith(LISTENING):
        proc.kill()
        _, err = proc.communicate(timeout=10)
        raise SimProcessError(f"groundfx sim did not start: {(line + err).strip()}")
    return proc, int(line.rsplit(":", 1)[1])


def finish(proc: subprocess.Popen[str], timeout_s: float = 10.0) -> str:
    """Wait for the simulator to end after its client left; returns its last stdout line."""
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    lines = [ln for ln in out.splitlines() if ln.strip()]
    return lines[-1] if lines else ""
