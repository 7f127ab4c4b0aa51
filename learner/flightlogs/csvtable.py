"""CSV flight logs as columns of numbers, as people write them.

Lines starting with `#` are comments, except a `#` line just before the first row of numbers
with as many fields as that row: that is the header (`# time[ms],x[m],...`, as the
Crazyflie tools and many loggers write it). Cells holding lists as text (`"[1.0, 2.0]"`, as
pandas writes list columns, e.g. Neural-Fly's) become one column per element, addressed as
`p[0]`, `p[1]`, ... (`R[0][1]` for nested lists). Empty cells are NaN.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np

from simbridge.config import ConfigError


def read_csv_columns(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The file's columns by header name, and the list columns' names with how to address
    them (for messages)."""
    try:
        lines = Path(path).read_text().splitlines()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text (CSV) file") from None
    numbered = [(i + 1, line) for i, line in enumerate(lines) if line.strip()]
    first = next((k for k, (_, line) in enumerate(numbered) if not _comment(line)), None)
    if first is None:
        raise ConfigError(f"{path}: no rows (only comments or nothing)")
    first_cells = _cells(numbered[first][1])
    before = numbered[first - 1][1] if first > 0 else ""
    if _comment(before) and _all_values(first_cells):
        header = _cells(before.lstrip()[1:])
        if len(header) != len(first_cells) or len(header) < 2:
            raise ConfigError(
                f"{path}: line {numbered[first][0]}: the first row has {len(first_cells)} "
                f"fields but the '#' header line above it has {len(header)}; a header must "
                f"name every field"
            )
        body = numbered[first:]
    else:
        header, body = first_cells, numbered[first + 1 :]
    header = [h.strip() for h in header]
    duplicate = next((h for h in header if header.count(h) > 1), None)
    if duplicate is not None:
        raise ConfigError(f"{path}: header: column {duplicate!r} appears twice")
    rows = [(n, _cells(line)) for n, line in body if not _comment(line)]
    if not rows:
        raise ConfigError(f"{path}: no rows below the header")
    for n, cells in rows:
        if len(cells) != len(header):
            raise ConfigError(
                f"{path}: line {n}: {len(cells)} fields, the header names {len(header)}"
            )
    columns: dict[str, np.ndarray] = {}
    lists: dict[str, str] = {}
    for j, name in enumerate(header):
        cells = [r[j].strip() for _, r in rows]
        if any(c.startswith("[") for c in cells):
            parts = _list_column(path, name, cells, [n for n, _ in rows])
            columns.update(parts)
            lists[name] = ", ".join(list(parts)[:4]) + (", ..." if len(parts) > 4 else "")
        else:
            columns[name] = _number_column(path, name, cells, [n for n, _ in rows])
    return columns, lists


def _comment(line: str) -> bool:
    return line.lstrip().startswith("#")


def _cells(line: str) -> list[str]:
    return next(csv.reader([line]))


def _all_values(cells: list[str]) -> bool:
    for c in cells:
        c = c.strip()
        if c == "" or c.startswith("["):
            continue
        try:
            float(c)
        except ValueError:
            return False
    return True


def _number_column(path: Path, name: str, cells: list[str], line_no: list[int]) -> np.ndarray:
    try:
        return np.array([c if c else "nan" for c in cells], dtype=float)
    except ValueError:
        for n, c in zip(line_no, cells, strict=True):
            try:
                float(c or "nan")
            except ValueError:
                raise ConfigError(
                    f"{path}: line {n}, column {name!r}: {c!r} is not a number"
                ) from None
        raise  # unreachable: some cell failed above


def _list_column(
    path: Path, name: str, cells: list[str], line_no: list[int]
) -> dict[str, np.ndarray]:
    values = []
    for n, c in zip(line_no, cells, strict=True):
        try:
            # Python's repr writes nan and inf; JSON spells them NaN and Infinity
            text = re.sub(r"\binf\b", "Infinity", re.sub(r"\bnan\b", "NaN", c))
            values.append(json.loads(text) if c else None)
        except json.JSONDecodeError:
            raise ConfigError(
                f"{path}: line {n}, column {name!r}: {c[:40]!r} is not a list of numbers"
            ) from None
    shape = next(np.shape(v) for v in values if v is not None)
    rows = []
    for n, v in zip(line_no, values, strict=True):
        a = np.full(shape, np.nan) if v is None else np.asarray(v, dtype=object)
        if a.shape != shape:
            raise ConfigError(
                f"{path}: line {n}, column {name!r}: a list of shape {a.shape}, the rows "
                f"above hold {shape}"
            )
        try:
            rows.append(a.astype(float))
        except (TypeError, ValueError):
            raise ConfigError(
                f"{path}: line {n}, column {name!r}: the list holds a non-number"
            ) from None
    data = np.stack(rows)
    return {
        name + "".join(f"[{i}]" for i in index): data[(slice(None), *index)]
        for index in np.ndindex(*shape)
    }
