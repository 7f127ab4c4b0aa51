"""Shared fixtures: real `groundfx sim` processes on ephemeral loopback ports, always cleaned up."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import yaml

import mission.cli  # noqa: F401  (before numpy: one BLAS thread, as the command line runs)

os.environ.setdefault("MAVLINK20", "1")


@pytest.fixture(autouse=True, scope="session")
def _recordings_in_a_temporary_folder(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Flights record by default; in the tests, not into the repository's logs/."""
    from mission.recordings import LOGS_ENV

    os.environ[LOGS_ENV] = str(tmp_path_factory.mktemp("logs"))


@pytest.fixture
def sim_process() -> Iterator[Callable[..., tuple[subprocess.Popen[str], int]]]:
    """Start `groundfx sim --port 0 ...`; returns (process, port). Killed at teardown."""
    from simbridge.launch import start_sim

    started: list[subprocess.Popen[str]] = []

    def start(world: str | Path = "default", **kwargs: object) -> tuple[subprocess.Popen[str], int]:
        proc, port = start_sim(world, **kwargs)  # type: ignore[arg-type]
        started.append(proc)
        return proc, port

    yield start
    for proc in started:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)


@pytest.fixture
def write_world(tmp_path: Path) -> Callable[[dict], Path]:
    """Write a world YAML (defaults filled in) to a temporary file."""

    def write(data: dict, name: str = "world.yaml") -> Path:
        path = tmp_path / name
        path.write_text(yaml.safe_dump(data))
        return path

    return write


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own, which reads the marker
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests that share a module-scoped fixture (a bench case flown once, a trained model)
    run on one worker, so that it is made once; every other test goes to whichever worker
    is free (`make test`: `-n 2 --dist loadgroup`), so two long files cannot leave one
    worker idle at the end."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        defs = info.name2fixturedefs.values() if info is not None else ()
        if any(d.scope == "module" for chain in defs for d in chain):
            item.add_marker(pytest.mark.xdist_group(item.path.name))
