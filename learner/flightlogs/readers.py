"""Any flight log into a `FlightLog`: one reader per format, chosen by the file's suffix."""

from __future__ import annotations

from pathlib import Path

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.tables import ColumnMapping, read_table_log


def read_log(path: Path, mapping: ColumnMapping | None = None) -> FlightLog:
    """A CSV or Parquet flight log through `mapping` (default: our own column names), or one
    of our rerun recordings (.rrd: their layout is fixed, no mapping)."""
    path = Path(path)
    if path.suffix == ".rrd":
        # imported here: the recording reader loads rerun, which CSV logs do not need
        from learner.flightlogs.recording_log import read_recording_log

        return read_recording_log(path)
    return read_table_log(path, mapping)
