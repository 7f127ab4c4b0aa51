"""A Ray task's files go with it and come back: on the worker it reads the inputs its
arguments name and writes under its outputs in a private folder; the driver's disk changes
only when its record lands there."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from mission.campaigns.runner import Task, _run
from mission.campaigns.shipping import FILES_KEY, input_files, land, run_carried


def copy_upper(source: str, out: Path) -> dict[str, Any]:
    """A task: reads `source`, writes its text in capitals into the folder `out`."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "sub").mkdir(exist_ok=True)
    (out / "sub" / "upper.txt").write_text(Path(source).read_text().upper())
    return {"written": str(out / "sub" / "upper.txt"), "read": source}


def test_a_carried_task_reads_and_writes_in_a_private_folder_and_its_files_land_here(
    tmp_path: Path,
) -> None:
    source = tmp_path / "inputs" / "mission.txt"
    source.parent.mkdir()
    source.write_text("takeoff, land")
    out = tmp_path / "campaign" / "case"
    task = Task("case", "k", copy_upper, (str(source), out), outputs=(out,))

    files = input_files(task.args)
    assert list(files) == [str(source)]
    record = run_carried(_run, task, files)

    # nothing written here yet; the record names the driver's paths
    assert not out.exists()
    assert record["written"] == str(out / "sub" / "upper.txt")
    assert record["read"] == str(source)
    assert list(record[FILES_KEY]) == [str(out / "sub" / "upper.txt")]
    json.dumps({k: v for k, v in record.items() if k != FILES_KEY})  # the rest is a plain record

    landed = land(record)
    assert FILES_KEY not in landed
    assert (out / "sub" / "upper.txt").read_text() == "TAKEOFF, LAND"
    assert sorted(p.name for p in out.rglob("*")) == ["sub", "upper.txt"]


def test_a_carried_task_that_fails_gives_its_error_and_no_files(tmp_path: Path) -> None:
    out = tmp_path / "case"
    task = Task("case", "k", copy_upper, (str(tmp_path / "missing.txt"), out), outputs=(out,))
    record = run_carried(_run, task, input_files(task.args))
    assert record["error"].startswith("FileNotFoundError")
    assert str(tmp_path / "missing.txt") in record["error"]  # the driver's path, not the worker's
    assert FILES_KEY not in record
    land(record)
    assert not out.exists()
