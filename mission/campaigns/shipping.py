"""A campaign task's files, carried with it to a machine that may not see the driver's disk
and back: the files its arguments name go with the task, and what it writes under its
declared outputs comes back in its record and is written on the machine that started the
campaign. On the worker, everything lives under a private folder that mirrors the driver's
absolute paths, so a task reads and writes the same relative layout it would at home.

Ray tasks are always carried this way (a cluster's machines share no folder); the local
pool's tasks run in place.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path, PurePath
from typing import Any

FILES_KEY = "_files"  # a record's carried files: driver path -> bytes
MAX_INPUT_BYTES = 256 << 20  # a file this large is not carried (and not expected as input)


def _path_like(value: Any) -> Path | None:
    """`value` as a path, where it is one: a Path, or a string that names a path (it holds a
    separator; a world's or a vehicle's name does not)."""
    if isinstance(value, PurePath):
        return Path(value)
    if isinstance(value, str) and os.sep in value and "\n" not in value and len(value) < 4096:
        return Path(value)
    return None


def _walk(value: Any, visit: Callable[[Any], Any]) -> Any:
    """`value` with `visit` applied to every leaf, through tuples, lists, dicts and frozen
    dataclasses (a changed dataclass is a replaced copy)."""
    if isinstance(value, tuple):
        return tuple(_walk(v, visit) for v in value)
    if isinstance(value, list):
        return [_walk(v, visit) for v in value]
    if isinstance(value, dict):
        return {k: _walk(v, visit) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        changes = {}
        for field in dataclasses.fields(value):
            old = getattr(value, field.name)
            new = _walk(old, visit)
            if new is not old:
                changes[field.name] = new
        return dataclasses.replace(value, **changes) if changes else value
    return visit(value)


def input_files(args: tuple[Any, ...], folders: tuple[Path, ...] = ()) -> dict[str, bytes]:
    """Every file the arguments name that exists here, and every file under `folders`: by
    absolute path."""
    found: dict[str, bytes] = {}

    def take(path: Path) -> None:
        if path.is_file() and path.stat().st_size <= MAX_INPUT_BYTES:
            found[str(path.resolve())] = path.read_bytes()

    def visit(leaf: Any) -> Any:
        path = _path_like(leaf)
        if path is not None:
            take(path.absolute())
        return leaf

    _walk(args, visit)
    for folder in folders:
        for path in sorted(Path(folder).rglob("*")) if Path(folder).is_dir() else ():
            take(path)
    return found


def _under(path: Path, roots: list[Path]) -> bool:
    """Whether `path` is a root, under one, or holds one."""
    return any(path == r or r in path.parents or path in r.parents for r in roots)


def localise(args: tuple[Any, ...], root: Path, shipped: list[Path]) -> tuple[Any, ...]:
    """The arguments with every path that was shipped, or lies under, on or above an output
    (`shipped`: absolute paths), moved under `root`; of the argument's own type."""

    def visit(leaf: Any) -> Any:
        path = _path_like(leaf)
        if path is None:
            return leaf
        absolute = Path(os.path.abspath(path))
        if not _under(absolute, shipped):
            return leaf
        moved = root / absolute.relative_to(absolute.anchor)
        return moved if isinstance(leaf, PurePath) else str(moved)

    return _walk(args, visit)


def delocalise(record: dict[str, Any], root: Path) -> dict[str, Any]:
    """The record with the worker's paths (under `root`) given back as the driver's."""
    prefix = str(root)

    def visit(leaf: Any) -> Any:  # a path, or a message that names one
        return leaf.replace(prefix + os.sep, os.sep) if isinstance(leaf, str) else leaf

    return _walk(record, visit)


def run_carried(
    run: Callable[..., dict[str, Any]],
    task: Any,
    files: dict[str, bytes],
) -> dict[str, Any]:
    """`run(task)` on a worker under a private folder: `files` written there first, the
    task's paths moved there, and what it wrote under its outputs returned in the record
    (`FILES_KEY`)."""
    outputs = [Path(os.path.abspath(p)) for p in task.outputs]
    root = Path(tempfile.mkdtemp(prefix="groundfx-task-"))
    try:
        for name, data in files.items():
            path = root / Path(name).relative_to(Path(name).anchor)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        for out in outputs:  # the folder an output goes into exists, as on the driver
            local = root / out.relative_to(out.anchor)
            (local.parent if out.suffix else local).mkdir(parents=True, exist_ok=True)
        shipped = [Path(name) for name in files] + outputs
        carried = dataclasses.replace(task, args=localise(task.args, root, shipped))
        record = delocalise(run(carried), root)
        written: dict[str, bytes] = {}
        for out in outputs:
            local = root / out.relative_to(out.anchor)
            paths = [local] if local.is_file() else sorted(local.rglob("*"))
            for path in paths:
                if path.is_file():
                    driver = Path(os.sep) / path.relative_to(root)
                    if files.get(str(driver)) != (data := path.read_bytes()):
                        written[str(driver)] = data
        return {**record, FILES_KEY: written} if written else record
    finally:
        shutil.rmtree(root, ignore_errors=True)


def land(record: dict[str, Any]) -> dict[str, Any]:
    """On the driver: the record's carried files written where the task meant them (each
    whole or not at all), and the record without them."""
    files = record.pop(FILES_KEY, None) or {}
    for name, data in files.items():
        path = Path(name)
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(path.name + ".part")
        partial.write_bytes(data)
        partial.replace(path)
    return record
