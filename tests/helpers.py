"""Helpers for tests that run the `groundfx` command line."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def run_groundfx(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mission.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
    )


def groundfx_in_process(*args: str) -> subprocess.CompletedProcess[str]:
    """The command line run in this process: its parser, its printing and its exit code, as
    a new process has them, without a new interpreter's imports (a diagnosis's torch and
    scipy: 3.5 s of CPU), for commands whose libraries the tests have loaded already."""
    from mission.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as exit_:  # argparse's refusals
            code = exit_.code if isinstance(exit_.code, int) else 1
    return subprocess.CompletedProcess(["groundfx", *args], code, out.getvalue(), err.getvalue())


def wait_for(
    condition: Callable[[], bool],
    what: str,
    process: subprocess.Popen | None = None,
    timeout_s: float = 300.0,
    interval_s: float = 0.1,
) -> None:
    """Wait for a state, not for a time: poll `condition` until it holds. The timeout only
    ends a test that would otherwise hang; `process` must stay alive meanwhile. A costly
    `condition` (a screenshot) is polled less often (`interval_s`)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if process is not None and process.poll() is not None:
            out, err = process.communicate()
            raise AssertionError(f"the process ended before {what}: {out}\n{err}")
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {timeout_s:g} s")
        time.sleep(interval_s)


def recorded_s(path: Path) -> float:
    """How far a recording being written has got (simulated seconds; 0 before it has rows)."""
    from learner.flightlogs.recording import RecordingError, read_recording

    try:
        t = read_recording(path).trajectory()[:, 0]
    except (RecordingError, OSError, ValueError, KeyError, IndexError):
        return 0.0
    return float(t[-1]) if len(t) else 0.0


def ideal_sensor_noise() -> dict[str, float]:
    """A world file's `sensor_noise:` with every error off (units, frames and link timing
    are tested without noise; the errors have tests of their own)."""
    import dataclasses

    from simbridge.sensor_noise import SensorNoise

    return {k: v for k, v in dataclasses.asdict(SensorNoise.ideal()).items() if k != "seed"}


def stop_process(proc: subprocess.Popen, timeout_s: float = 10.0) -> None:
    """Terminate `proc` if it still runs, wait for it, kill it if it will not end."""
    if proc.poll() is None:
        proc.terminate()
    try:
        proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()


@contextlib.contextmanager
def cpu_bound(count: int = 2) -> Iterator[None]:
    """`count` processes that only burn CPU, beside what the block runs: a busy machine."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]
    try:
        yield
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
