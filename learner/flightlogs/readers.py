"""Any flight log into a `FlightLog`: one reader per format, chosen by the file's suffix
(`READERS`), else by its first bytes (`SNIFFERS`: a Crazyflie's microSD card names its logs
`log00`, `cf50_01`, without a suffix). A new format is one entry in either table."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.tables import ColumnMapping, read_table_log
from simbridge.config import ConfigError
from simbridge.vehicle import Vehicle

# (path, mapping or None, vehicle or its name or None) -> FlightLog
Reader = Callable[[Path, ColumnMapping | None, Vehicle | str | None], FlightLog]


def _recording(path: Path, mapping: ColumnMapping | None, vehicle: Vehicle | str | None):
    # imported here: the recording reader loads rerun, which other logs do not need
    from learner.flightlogs.recording_log import read_recording_log

    return read_recording_log(path)


def _cfusd(path: Path, mapping: ColumnMapping | None, vehicle: Vehicle | str | None):
    from learner.flightlogs.cfusd import read_cfusd_log

    return read_cfusd_log(path, mapping, vehicle)


def _autopilot(module: str, function: str) -> Reader:
    # imported when used: pyulog and pymavlink's log readers load only for their logs
    def read(path: Path, mapping: ColumnMapping | None, vehicle: Vehicle | str | None):
        import importlib

        return getattr(importlib.import_module(module), function)(path, mapping, vehicle)

    return read


def _is_cfusd(head: bytes) -> bool:
    from learner.flightlogs.cfusd import looks_like_cfusd

    return looks_like_cfusd(head)


def is_dataflash_text(head: bytes) -> bool:
    """An ArduPilot DataFlash log as text (Mission Planner's `.log`): its first line declares
    the FMT message."""
    return head.lstrip().startswith(b"FMT,")


def _is_csv(head: bytes) -> bool:
    """Text whose first line that is not a comment has a comma: a CSV under another suffix."""
    if b"\x00" in head:
        return False
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return False
    lines = [ln for ln in text.splitlines()[:-1] if ln.strip() and not ln.lstrip().startswith("#")]
    return bool(lines) and "," in lines[0]


# Suffix (lower case) -> reader.
READERS: dict[str, Reader] = {
    ".csv": read_table_log,
    ".parquet": read_table_log,
    ".rrd": _recording,
    # autopilot logs (learner/flightlogs/ulog.py, mavlog.py)
    ".ulg": _autopilot("learner.flightlogs.ulog", "read_ulog"),
    ".bin": _autopilot("learner.flightlogs.mavlog", "read_dataflash"),
    ".tlog": _autopilot("learner.flightlogs.mavlog", "read_tlog"),
}

# For suffixes not in READERS, in order: (what it is, test on the first 4 KiB, reader).
SNIFFERS: list[tuple[str, Callable[[bytes], bool], Reader]] = [
    ("Crazyflie microSD log", _is_cfusd, _cfusd),
    (
        "ArduPilot DataFlash text log",
        is_dataflash_text,
        _autopilot("learner.flightlogs.mavlog", "read_dataflash"),
    ),
    ("CSV", _is_csv, read_table_log),
]


def read_log(
    path: Path, mapping: ColumnMapping | None = None, vehicle: Vehicle | str | None = None
) -> FlightLog:
    """A flight log of any known format: CSV or Parquet through `mapping` (default: our own
    column names), one of our rerun recordings (.rrd, a fixed layout), a Crazyflie microSD log
    (through `mapping`, default the packaged Crazyflie one). `vehicle` (a Vehicle, a packaged
    name or a YAML; default nano) turns logged thrust into rotor speeds through its C_T."""
    path = Path(path)
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        reader = _sniff(path)
    return reader(path, mapping, vehicle)


def _sniff(path: Path) -> Reader:
    try:
        with path.open("rb") as f:
            head = f.read(4096)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such flight log") from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    for _, test, reader in SNIFFERS:
        if test(head):
            return reader
    suffixes = ", ".join(READERS)
    sniffed = ", ".join(what for what, _, _ in SNIFFERS)
    raise ConfigError(
        f"{path}: not a flight log format we know (suffix {path.suffix or 'none'}); known: "
        f"{suffixes} by suffix, and by content: {sniffed}"
    )
