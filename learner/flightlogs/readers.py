"""Any flight log into a `FlightLog` through one entry point, `read_log`.

Each format is one `LogFormat` declaration passed to `register`: its name, its reader, the
suffixes it is known by and, for files whose suffix says nothing (a Crazyflie's microSD card
names its logs `log00`, `cf50_01`), a test on the file's first bytes. `read_log`, its error
messages and the command line's help read the registered formats; nothing else lists them.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from simbridge.config import ConfigError

if TYPE_CHECKING:
    from learner.flightlogs.flightlog import FlightLog
    from learner.flightlogs.tables import ColumnMapping
    from simbridge.vehicle import Vehicle

# (path, mapping or None, vehicle or its name or None) -> FlightLog
Reader = Callable[[Path, "ColumnMapping | None", "Vehicle | str | None"], "FlightLog"]
Sniff = Callable[[bytes], bool]  # the first SNIFF_BYTES of a file -> whether it is the format
SNIFF_BYTES = 4096


@dataclass(frozen=True)
class LogFormat:
    """One flight-log format: what it is called, how to read it and how to recognise it."""

    name: str  # in messages and --help, e.g. "PX4 ULog"
    read: Reader
    suffixes: tuple[str, ...] = ()  # lower case with the dot: a file with one is this format
    sniff: Sniff | None = None  # for a file no suffix claims


FORMATS: list[LogFormat] = []


def register(log_format: LogFormat) -> LogFormat:
    """Make `read_log` read `log_format`. A suffix belongs to one format. Content tests run
    newest first: a format registered later is more specific than the loose tests declared
    first (any text whose first line has a comma is a CSV)."""
    for suffix in log_format.suffixes:
        if not suffix.startswith(".") or suffix != suffix.lower():
            raise ValueError(f"{log_format.name}: suffix {suffix!r} is not like '.csv'")
        if (owner := _by_suffix(suffix)) is not None:
            raise ValueError(f"{log_format.name}: suffix {suffix} is already {owner.name}'s")
    if not log_format.suffixes and log_format.sniff is None:
        raise ValueError(f"{log_format.name}: needs a suffix or a content test")
    FORMATS.append(log_format)
    return log_format


def lazy(module: str, function: str) -> Callable[..., Any]:
    """`module.function`, imported when first called: pyulog, pymavlink and rerun load only
    for their own logs."""

    def call(*args: Any) -> Any:
        return getattr(importlib.import_module(module), function)(*args)

    return call


def read_log(
    path: Path, mapping: ColumnMapping | None = None, vehicle: Vehicle | str | None = None
) -> FlightLog:
    """A flight log of any registered format: CSV or Parquet through `mapping` (default: our
    own column names), one of our rerun recordings (.rrd, a fixed layout), a Crazyflie microSD
    log (through `mapping`, default the packaged Crazyflie one), PX4 and ArduPilot logs.
    `vehicle` (a Vehicle, a packaged name or a YAML; default nano) turns logged thrust into
    rotor speeds through its C_T."""
    path = Path(path)
    log_format = _by_suffix(path.suffix.lower()) or _sniff(path)
    return log_format.read(path, mapping, vehicle)


def known_formats() -> str:
    """The registered formats in a sentence, for --help and messages."""
    return ", ".join(f"{f.name} ({_recognised_by(f)})" for f in FORMATS)


def _recognised_by(log_format: LogFormat) -> str:
    suffixes = ", ".join(log_format.suffixes)
    if log_format.sniff is None:
        return suffixes
    return f"{suffixes} or by content" if suffixes else "by content"


def _by_suffix(suffix: str) -> LogFormat | None:
    return next((f for f in FORMATS if suffix in f.suffixes), None)


def _sniff(path: Path) -> LogFormat:
    try:
        with path.open("rb") as f:
            head = f.read(SNIFF_BYTES)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such flight log") from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    sniffing = [(f, f.sniff) for f in reversed(FORMATS) if f.sniff is not None]
    for log_format, sniff in sniffing:
        if sniff(head):
            return log_format
    suffixes = ", ".join(s for f in FORMATS for s in f.suffixes)
    sniffed = ", ".join(f.name for f, _ in sniffing)
    raise ConfigError(
        f"{path}: not a flight log format we know (suffix {path.suffix or 'none'}); known: "
        f"{suffixes} by suffix, and by content: {sniffed}"
    )


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


def _recording(path: Path, mapping: ColumnMapping | None, vehicle: Vehicle | str | None):
    # a fixed layout: no mapping, and rotor speeds recorded as such
    from learner.flightlogs.recording_log import read_recording_log

    return read_recording_log(path)


_TABLE = lazy("learner.flightlogs.tables", "read_table_log")
_MAVLOG = "learner.flightlogs.mavlog"

# Content tests run from the last declared up: the loosest (CSV) is declared first.
register(LogFormat("CSV", _TABLE, (".csv",), _is_csv))
register(LogFormat("Parquet", _TABLE, (".parquet",)))
register(LogFormat("groundfx rerun recording", _recording, (".rrd",)))
register(LogFormat("PX4 ULog", lazy("learner.flightlogs.ulog", "read_ulog"), (".ulg",)))
register(LogFormat("MAVLink telemetry log", lazy(_MAVLOG, "read_tlog"), (".tlog",)))
register(
    LogFormat(
        "ArduPilot DataFlash log", lazy(_MAVLOG, "read_dataflash"), (".bin",), is_dataflash_text
    )
)
register(
    LogFormat(
        "Crazyflie microSD log",
        lazy("learner.flightlogs.cfusd", "read_cfusd_log"),
        sniff=lazy("learner.flightlogs.cfusd", "looks_like_cfusd"),
    )
)
