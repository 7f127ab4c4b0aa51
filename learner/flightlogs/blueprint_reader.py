"""The viewer layout a recording carries: its views as the rerun viewer will show them.

A recording file holds blueprint stores beside its recording (the one it opened with, and
one sent when a mission told where the flight lands); the last is the default the viewer
uses. Each view: its kind, name, origin, contents query and, for time series, the y range.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class View:
    kind: str  # "TimeSeries", "3D", "TextLog"
    name: str
    origin: str
    query: tuple[str, ...]  # "$origin/**" or entity paths
    y_range: tuple[float, float] | None  # a time series' fixed range, if any


def _last(batch: Any, column: str) -> Any:
    if column not in batch.schema.names or batch.num_rows == 0:
        return None
    value = batch.column(column).to_pylist()[-1]
    return value[0] if isinstance(value, list) and len(value) == 1 else value


def read_views(path: str | Path) -> list[View]:
    """The views of the recording's last blueprint."""
    import rerun.chunk as rc

    reader = rc.RrdReader(Path(path))
    stores = reader.blueprints()
    if not stores:
        return []
    fields: dict[str, dict[str, Any]] = {}
    for chunk in reader.stream(store=stores[-1]):
        batch = chunk.to_record_batch()
        entry = fields.setdefault(chunk.entity_path.strip("/"), {})
        for name in batch.schema.names:
            if ":" in name and (value := _last(batch, name)) is not None:
                entry[name] = value
    views = []
    for entity, f in fields.items():
        if "ViewBlueprint:class_identifier" not in f:
            continue
        query = fields.get(f"{entity}/ViewContents", {}).get("ViewContents:query", [])
        axis = fields.get(f"{entity}/ScalarAxis", {}).get("ScalarAxis:range")
        views.append(
            View(
                kind=f["ViewBlueprint:class_identifier"],
                name=f.get("ViewBlueprint:display_name", ""),
                origin=f.get("ViewBlueprint:space_origin", ""),
                query=tuple(query if isinstance(query, list) else [query]),
                y_range=(float(axis[0]), float(axis[1])) if axis else None,
            )
        )
    return views
