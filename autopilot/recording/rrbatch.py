"""Many entities' columns on one time index, sent to rerun as one Arrow record batch.

`rr.send_columns` costs about 0.1-0.2 ms per call whatever the number of rows (archetype
conversion in Python, one chunk per call); a recording of twenty-odd entities flushed twice a
second would spend most of its time there. One record batch holding every entity that shares
the control step's times costs one conversion: rerun splits it into one chunk per entity.

The column types and rerun's metadata are taken from what rerun's own archetype builders make
(`rr.Scalars.columns(...)` and so on, once, at construction), so this module only renames
the columns to `/entity:component` and fills them from numpy arrays.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.chunk as rc


class ColumnBatch:
    """The layout of one record batch: a time column, then entity components in order."""

    def __init__(self, timeline: str) -> None:
        self._timeline = timeline
        self._time_field: pa.Field | None = None
        self._fields: dict[str, pa.Field] = {}

    def add(self, entity: str, sample: Iterable[rr.ComponentColumn]) -> None:
        """Add the components of `sample` (one row, e.g. `rr.Scalars.columns(scalars=[[0, 0]])`)
        as columns of `entity`; their values later come under the key `entity:component`."""
        zero = rr.TimeColumn(self._timeline, duration=np.zeros(1, dtype="timedelta64[ns]"))
        schema = rc.Chunk.from_columns(entity, [zero], sample).to_record_batch().schema
        for f in schema:
            metadata = dict(f.metadata or {})
            kind = metadata.get(b"rerun:kind")
            if kind == b"index":
                self._time_field = f
            elif kind == b"data":
                metadata[b"rerun:entity_path"] = entity.encode()
                key = f"{entity}:{f.name}"
                self._fields[key] = f.with_name(f"/{key}").with_metadata(metadata)

    def keys(self) -> list[str]:
        return list(self._fields)

    def send(self, rec: rr.RecordingStream, time_ns: np.ndarray, values: Mapping[str, Any]) -> None:
        # Chunk.from_record_batch + send_chunks is what rr.send_record_batch does, measured
        # faster called directly here.
        rr.send_chunks(rc.Chunk.from_record_batch(self.batch(time_ns, values)), recording=rec)

    def batch(self, time_ns: np.ndarray, values: Mapping[str, Any]) -> pa.RecordBatch:
        """One row per time (int64 ns); `values[key]` is [rows, width] (or [rows]), or for
        line strips a list of one [points, 3] array per row."""
        assert self._time_field is not None, "add an entity first"
        arrays = [pa.array(time_ns.astype("timedelta64[ns]"), self._time_field.type)]
        arrays += [_list_column(f.type, values[key]) for key, f in self._fields.items()]
        fields = [self._time_field, *self._fields.values()]
        return pa.RecordBatch.from_arrays(arrays, schema=pa.schema(fields))


def _list_column(kind: pa.DataType, values: np.ndarray | list[np.ndarray]) -> pa.Array:
    """Rows of `values` as a list column of type `kind`: list<number> (several instances per
    row, as Scalars with several series), list<fixed_size_list<number, k>> (one vector per
    row, as a translation), or list<list<fixed_size_list<number, k>>> (one line strip per
    row, `values` then a list of [points, k] arrays)."""
    inner = kind.value_type
    if pa.types.is_list(inner):
        return _strips_column(kind, values)
    a = np.asarray(values)
    rows = a.shape[0]
    width = int(np.prod(a.shape[1:])) if a.ndim > 1 else 1
    if pa.types.is_fixed_size_list(inner):
        items = _fixed_size(inner, a)
        per_row = width // inner.list_size
    else:
        items = pa.array(np.ascontiguousarray(a, inner.to_pandas_dtype()).reshape(-1), inner)
        per_row = width
    offsets = pa.array(np.arange(0, rows * per_row + 1, per_row, dtype=np.int32))
    return pa.ListArray.from_arrays(offsets, items, type=kind)


def _fixed_size(kind: pa.DataType, a: np.ndarray) -> pa.Array:
    """Rows of `a` as fixed-size lists (vectors) of type `kind`."""
    number = kind.value_type
    flat = np.ascontiguousarray(a, number.to_pandas_dtype()).reshape(-1)
    return pa.FixedSizeListArray.from_arrays(pa.array(flat, number), type=kind)


def _strips_column(kind: pa.DataType, strips: list[np.ndarray]) -> pa.Array:
    strip = kind.value_type
    points = _fixed_size(strip.value_type, np.concatenate(strips))
    lengths = np.fromiter((len(s) for s in strips), dtype=np.int32, count=len(strips))
    inner = np.concatenate(([0], np.cumsum(lengths))).astype(np.int32)
    per_row = pa.ListArray.from_arrays(pa.array(inner), points, type=strip)
    outer = pa.array(np.arange(len(strips) + 1, dtype=np.int32))
    return pa.ListArray.from_arrays(outer, per_row, type=kind)
