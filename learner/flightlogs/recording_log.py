"""Our own flight recordings (`.rrd`, learner/flightlogs/recording.py) as gap-diagnosis logs.

A recording holds every control step: the true state (position, velocity, attitude, body
rates), the rotor speeds commanded at the step (applied over the next control period), and the
accelerometer-derived acceleration of the period ending at the step. The log keeps the airborne
steps, as `--flight-log` does, with each row's rotor speeds those applied over the period that
ends at it (the previous step's command): the same rows as the CSV the autopilot writes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from simbridge.config import ConfigError

STEP_SERIES = (
    "plots/position", "plots/velocity", "plots/attitude", "plots/rates", "plots/acceleration",
    "plots/rotors/commanded", "plots/height", "plots/mode",
)  # fmt: skip


def read_recording_log(path: Path) -> FlightLog:
    """The airborne control steps of the recording at `path` as a FlightLog."""
    from learner.flightlogs.recording import RecordingError, read_recording
    from simbridge.vehicle import load_vehicle

    try:
        rec = read_recording(path)
    except RecordingError as err:
        raise ConfigError(str(err)) from None
    try:
        t = rec.times("plots/position", "Scalars:scalars")
        cols = {s: rec.values(s, "Scalars:scalars") for s in STEP_SERIES}
    except KeyError as err:
        missing = "plots/acceleration" not in rec.entities
        why = "it predates the attitude, rates and acceleration series" if missing else err
        raise ConfigError(f"{path}: not usable as a flight log ({why})") from None
    n = min(len(t), *(len(c) for c in cols.values()))  # a cut file may end between entities
    t, cols = t[:n], {k: v[:n] for k, v in cols.items()}
    commanded = cols["plots/rotors/commanded"]
    applied = np.vstack([np.zeros((1, 4)), commanded[:-1]])  # over the period ending at the row
    modes = rec.meta.get("modes", [])
    if "airborne_modes" not in rec.meta:
        raise ConfigError(f"{path}: not usable as a flight log (it predates airborne_modes)")
    airborne_modes = [i for i, m in enumerate(modes) if m in rec.meta["airborne_modes"]]
    vehicle = load_vehicle(rec.meta.get("vehicle", "nano"))
    resting_m = vehicle.body_size_m[2] / 2.0  # as the runner: the range sensor at the centre
    keep = np.isin(cols["plots/mode"][:, 0], airborne_modes) & (
        cols["plots/height"][:, 0] > resting_m + rec.meta["airborne_margin_m"]
    )
    keep[0] = False  # its applied rotor speeds are unknown
    if keep.sum() < 2:
        raise ConfigError(f"{path}: the recording holds no airborne flight")
    q = cols["plots/attitude"][keep]
    # the autopilot's parameters too: a replay of the flight flies with them
    meta = {k: rec.meta[k] for k in ("mission", "world", "vehicle", "parameters") if k in rec.meta}
    meta["frame"] = "world"  # the simulator's: the diagnosis does not look for the ground
    return FlightLog(
        Path(path).stem, t[keep], cols["plots/position"][keep], cols["plots/velocity"][keep],
        q / np.linalg.norm(q, axis=1, keepdims=True), cols["plots/rates"][keep], applied[keep],
        acceleration_m_s2=cols["plots/acceleration"][keep], meta=meta,
    )  # fmt: skip
