"""Recordings on the command line: where a flight's recording goes, and the record options.

Every flight records by default, to `logs/<date>-<time>-<mission>-<model>.rrd`, or
`...-<model>-online-<method>.rrd` for a flight that learns online (the folder is
`$GROUNDFX_LOGS` when set, e.g. by the tests); `--record PATH` chooses the file and
`--no-record` turns recording off.
"""

from __future__ import annotations

import argparse
import os
from datetime import datetime
from pathlib import Path

from simbridge.config import ConfigError

LOGS_ENV = "GROUNDFX_LOGS"


def logs_dir() -> Path:
    return Path(os.environ.get(LOGS_ENV) or "logs")


def recording_label(model: str, online: str | None = None) -> str:
    """What a recording's name says of the flight: the model, and the online method if any
    (an online flight is not the offline one)."""
    return model if not online else f"{model}-online-{online}"


def default_recording_path(mission: Path, model: str, logs: Path | None = None) -> Path:
    """A new file name in the logs folder: date, time to the millisecond, mission, model."""
    now = datetime.now()
    stamp = now.strftime("%Y%m%d-%H%M%S-") + f"{now.microsecond // 1000:03d}"
    folder = logs_dir() if logs is None else logs
    path = folder / f"{stamp}-{mission.stem}-{model}.rrd"
    n = 1
    while path.exists():  # two flights in the same millisecond
        n += 1
        path = folder / f"{stamp}-{mission.stem}-{model}-{n}.rrd"
    return path


def record_path(args: argparse.Namespace, label: str) -> Path | None:
    """The recording file the options ask for (None: off), named with `label`
    (`recording_label`); its folder made, or a message.
    Without a mission on the command line (one a ground station uploads) it is named `gcs`."""
    if args.no_record:
        return None
    mission = args.mission if args.mission is not None else Path("gcs")
    path = args.record or default_recording_path(mission, label)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"--record: cannot write {path}: {err.strerror}") from None
    if path.is_dir() or not os.access(path.parent, os.W_OK):
        raise ConfigError(f"--record: cannot write {path}")
    return path
