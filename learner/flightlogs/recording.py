"""The flight recording: its layout (entity paths, series, units) and its reader.

Every flight writes one rerun recording (`autopilot.recording.recorder`); this module is the one
place that knows what is in it, for the writer, the default blueprint, the tests and any later
analysis. `read_recording(path)` loads a `.rrd` file into numpy arrays with `rerun.chunk` (rerun
0.41 has no `rr.dataframe`; its dataframe reader needs `datafusion`, which we do not need for this).
A recording cut short by a crash has no footer and may end in half a message: it is still read, up
to its last whole message, and says so (`complete` is False).

Frames and units as everywhere in groundfx: world x east, y north, z up, metres, seconds,
newtons, rad/s. Time is the `sim_time` timeline: the simulator's `time_usec`.
"""

from __future__ import annotations

import json
import struct
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

TIMELINE = "sim_time"
APPLICATION_ID = "groundfx"
LAYOUT_VERSION = 1
GE_ARROW_M_PER_N = 1.0  # ground-effect arrows in the 3-D view: 1 m per newton

# The 3-D world. Static unless noted.
WORLD = "world"  # ViewCoordinates RIGHT_HAND_Z_UP
GROUND = "world/ground"  # a thin slab whose top is z = 0
OBSTACLES = "world/obstacles"  # boxes of the world file (only when it has any)
WAYPOINTS = "world/mission/waypoints"  # points, logged when the flight starts
MISSION_LABELS = "world/mission/labels"  # their labels, lifted above them (not over the drone)
MISSION_PATH = "world/mission/path"  # start, take-off point, waypoints, landing point
DRONE = "world/drone"  # Transform3D at 50 Hz (the pose; body frame FLU); plots: every step
DRONE_BODY = "world/drone/body"  # the body box, in the body frame
DRONE_ARMS = "world/drone/arms"  # centre to each rotor
DRONE_ROTORS = "world/drone/rotors"  # rotor discs of the ground-effect model's radius
TRAJECTORY = "world/trajectory"  # the path flown: segments <k> of 10 s, each redrawn as it grows
GE_TRUE_ARROW = "world/ground_effect/true"  # the simulator's true force at the drone, 50 Hz
GE_PREDICTED_ARROW = "world/ground_effect/predicted"  # the controller's estimate, 50 Hz

# Time series (Scalars): entity path -> names of its series, in order.
SERIES: dict[str, tuple[str, ...]] = {
    "plots/z": ("z", "z setpoint"),  # m
    "plots/height": ("height",),  # m above the surface below, as the autopilot estimates it
    "plots/position": ("x", "y", "z"),  # m, the true state (HIL_STATE_QUATERNION)
    "plots/velocity": ("vx", "vy", "vz"),  # m/s
    "plots/setpoint": ("x", "y", "z"),  # m; NaN while there is none
    "plots/ground_effect/x/true": ("true",),  # N, world frame; when GE_TRUE arrives
    "plots/ground_effect/x/predicted": ("predicted",),  # N, what the controller used
    "plots/ground_effect/y/true": ("true",),
    "plots/ground_effect/y/predicted": ("predicted",),
    "plots/ground_effect/z/true": ("true",),
    "plots/ground_effect/z/predicted": ("predicted",),
    "plots/rotors/commanded": ("n0", "n1", "n2", "n3"),  # rad/s, sent to the simulator
    "plots/rotors/actual": ("n0", "n1", "n2", "n3"),  # rad/s, ESC telemetry, when it arrives
    "plots/errors/position": ("x", "y", "z"),  # m, setpoint - position
    "plots/errors/velocity": ("vx", "vy", "vz"),  # m/s, setpoint - velocity
    "plots/errors/attitude": ("roll", "pitch"),  # rad, desired - actual
    "plots/mode": ("mode",),  # index into meta["modes"]
    # for the gap diagnosis (learner/gap): the state's attitude and body rates, and the
    # accelerometer-derived acceleration of the control period ending at the step
    "plots/attitude": ("qw", "qx", "qy", "qz"),  # body FLU to world ENU
    "plots/rates": ("p", "q", "r"),  # rad/s, body FLU
    "plots/acceleration": ("ax", "ay", "az"),  # m/s^2, world, gravity removed
    "plots/learner/loss": ("loss",),  # online learner's loss (standardised units)
    "plots/learner/log10_loss": ("log10 loss",),  # the same on a log scale, for the viewer
    "plots/learner/version": ("version",),  # weight-snapshot version the controller uses
    # the review's differences, for the viewer: two series that lie on top of each other
    # read as one, their difference reads at its own scale
    "plots/height_error_mm": ("z - setpoint",),  # mm, every step with a setpoint
    "plots/model_error_mn": ("predicted - true",),  # mN, vertical ground effect, with the truth
    **{  # rad/s, commanded minus measured (ESC), when the telemetry arrives
        f"plots/rotors/difference/{i}": (f"n{i} commanded - measured",) for i in range(4)
    },
}
# The difference series and the two series each is the difference of: (path, column) pairs.
DIFFERENCES: dict[str, tuple[tuple[str, int], tuple[str, int]]] = {
    "plots/height_error_mm": (("plots/z", 0), ("plots/z", 1)),
    "plots/model_error_mn": (
        ("plots/ground_effect/z/predicted", 0),
        ("plots/ground_effect/z/true", 0),
    ),
    **{
        f"plots/rotors/difference/{i}": (("plots/rotors/commanded", i), ("plots/rotors/actual", i))
        for i in range(4)
    },
}
COUNTERS = ("received", "dropped", "rejected")  # MAVLink counters per link, cumulative
MAVLINK = "plots/mavlink"  # one entity per link: plots/mavlink/<link> with COUNTERS
EVENTS = "events"  # TextLog: modes, arming, failsafes, link events, the end of the flight
STATES = "states"  # StateChange, named states as they change: STATES/phase, STATES/flight_mode
PHASE_STATE = f"{STATES}/phase"
FLIGHT_MODE_STATE = f"{STATES}/flight_mode"
MODEL_STATE = f"{STATES}/model"  # the ground-effect model in use: its name, version, ground
LEARNER_UPDATES = "learner/updates"  # TextLog: each online update, accepted or not, and why
REVIEW = "review"  # static TextDocument: the landing and the learner in a sentence each
META = "meta"  # static TextDocument: JSON with the flight's configuration and mode names
SUMMARY = "summary"  # static TextDocument: JSON, the flight's summary (figures, how it ended)

# What every recorder file holds (OBSTACLES only for worlds with obstacles; the counters of
# each link under MAVLINK).
ENTITY_PATHS: tuple[str, ...] = (
    WORLD,
    GROUND,
    WAYPOINTS,
    MISSION_PATH,
    DRONE,
    DRONE_BODY,
    DRONE_ARMS,
    DRONE_ROTORS,
    f"{TRAJECTORY}/0",
    GE_TRUE_ARROW,
    GE_PREDICTED_ARROW,
    *SERIES,
    f"{MAVLINK}/sim",
    EVENTS,
    PHASE_STATE,
    FLIGHT_MODE_STATE,
    MODEL_STATE,
    META,
)

_PROPERTIES = "/__properties"
_TRAJECTORY_PARTS = ("plots/velocity", "plots/z", "plots/height", "plots/mode")


@dataclass
class Entity:
    """One entity's chunks in the order written: their times (s; None for static data) and
    the values of each component column (`Scalars:scalars`, `Transform3D:translation`, ...)."""

    path: str
    chunks: list[tuple[np.ndarray | None, dict[str, Any]]] = field(default_factory=list)

    def temporal(self, component: str | None = None) -> list[tuple[np.ndarray, dict[str, Any]]]:
        return [
            (t, columns)
            for t, columns in self.chunks
            if t is not None and (component is None or component in columns)
        ]


@dataclass
class Recording:
    path: Path
    entities: dict[str, Entity]
    complete: bool  # False: cut short (no footer; e.g. the autopilot was killed)
    meta: dict[str, Any]

    def entity_paths(self) -> list[str]:
        return sorted(self.entities)

    def times(self, path: str, component: str | None = None) -> np.ndarray:
        """The sim_time (s) of each row of an entity (that has `component`), in the order
        written; empty for static data."""
        parts = [t for t, _ in self._entity(path).temporal(component)]
        return np.concatenate(parts) if parts else np.zeros(0)

    def values(self, path: str, component: str) -> np.ndarray:
        """A component of fixed width over time as one array [rows, width], rows as `times`
        (e.g. `Transform3D:translation` gives [N, 3], `Scalars:scalars` [N, k])."""
        parts = [columns[component] for _, columns in self._entity(path).temporal(component)]
        if not parts:
            raise KeyError(f"{self.path}: {path} has no {component} over time")
        return np.concatenate(parts)

    def static(self, path: str, component: str) -> Any:
        """The value of a static component (the last one logged)."""
        found = [c[component] for t, c in self._entity(path).chunks if t is None and component in c]
        if not found:
            raise KeyError(f"{self.path}: {path} has no static {component}")
        return found[-1][-1]

    def scalars(self, path: str) -> tuple[np.ndarray, np.ndarray]:
        """A time series: (times s [N], values [N, k]) with k = len(SERIES[path])."""
        return self.times(path, "Scalars:scalars"), self.values(path, "Scalars:scalars")

    def texts(self, path: str = EVENTS) -> list[tuple[float, str, str]]:
        """A text log: (time s, level, text) per row."""
        rows: list[tuple[float, str, str]] = []
        for t, columns in self._entity(path).temporal("TextLog:text"):
            levels = columns.get("TextLog:level", [None] * len(t))
            rows += zip(t.tolist(), levels, columns["TextLog:text"], strict=True)
        return rows

    def trajectory(self) -> np.ndarray:
        """The flown trajectory as the autopilot logs it (autopilot.metrics.COLUMNS):
        time, x, y, z, vx, vy, vz, z setpoint, height, mode; one row per control step."""
        t, p = self.scalars("plots/position")
        parts = [p] + [self.values(path, "Scalars:scalars") for path in _TRAJECTORY_PARTS]
        n = min(len(t), *(len(part) for part in parts))  # a cut file may end between entities
        v, z, h, mode = (part[:n] for part in parts[1:])
        return np.column_stack((t[:n], p[:n], v, z[:, 1], h[:, 0], mode[:, 0]))

    def _entity(self, path: str) -> Entity:
        try:
            return self.entities[path.strip("/")]
        except KeyError:
            raise KeyError(f"{self.path}: no entity {path!r} in the recording") from None


class RecordingError(Exception):
    """Not a readable recording; the message says why."""


def read_recording(path: str | Path) -> Recording:
    """Load every entity of the recording at `path` (the first recording store in the file)."""
    import rerun.chunk as rc

    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path}: no such file")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            chunks = list(rc.RrdReader(path).stream())
            cut = False
        except (RuntimeError, ValueError) as err:
            chunks, cut = _read_whole_messages(path, err), True
    complete = not cut and not any("no footer" in str(w.message) for w in caught)
    entities: dict[str, Entity] = {}
    for chunk in chunks:
        if chunk.entity_path == _PROPERTIES:
            continue
        _add_chunk(entities, chunk.entity_path.strip("/"), chunk.to_record_batch())
    recording = Recording(path=path, entities=entities, complete=complete, meta={})
    if META in entities:
        recording.meta = json.loads(recording.static(META, "TextDocument:text"))
    return recording


def _add_chunk(entities: dict[str, Entity], path: str, batch: pa.RecordBatch) -> None:
    names = batch.schema.names
    times = None
    if TIMELINE in names:
        times = batch.column(TIMELINE).cast(pa.int64()).to_numpy(zero_copy_only=False) * 1e-9
    # components are list columns; the rest are indices (our timeline, and the log_time and
    # log_tick of recordings written by other rerun programs)
    columns = {
        name: _to_numpy(batch.column(name))
        for name in names
        if not name.startswith("rerun.") and _is_list(batch.column(name).type)
    }
    entities.setdefault(path, Entity(path)).chunks.append((times, columns))


def _is_list(kind: pa.DataType) -> bool:
    return bool(pa.types.is_list(kind) or pa.types.is_large_list(kind))


def _to_numpy(column: pa.Array) -> Any:
    """A list column as [rows, width] when every row has the same width of numbers, else as
    a list of per-row Python values."""
    if _is_list(column.type):
        flat = column.flatten()
        lengths = column.value_lengths().to_numpy(zero_copy_only=False)
        inner = flat.type
        if pa.types.is_fixed_size_list(inner):
            flat = flat.flatten()
            lengths = lengths * inner.list_size
        if (
            len(lengths)
            and (pa.types.is_floating(flat.type) or pa.types.is_integer(flat.type))
            and np.all(lengths == lengths[0])
        ):
            return flat.to_numpy(zero_copy_only=False).reshape(len(lengths), -1)
        if pa.types.is_string(flat.type):
            return [row[0] if len(row) == 1 else row for row in column.to_pylist()]
    return column.to_pylist()


# The framing of an .rrd file (rerun's re_log_encoding): a 12-byte stream header starting
# with b"RRF2", then messages of (kind: u64, length: u64, payload); kind 0 ends the stream
# and a footer follows it.
_STREAM_HEADER = 12
_MESSAGE_HEADER = struct.Struct("<QQ")


def _read_whole_messages(path: Path, err: Exception) -> list[Any]:
    """A file cut off in the middle of a message (a killed writer): read the messages before
    the cut. rerun's reader refuses the whole file otherwise."""
    import rerun.chunk as rc

    data = path.read_bytes()
    if not data.startswith(b"RRF2"):
        raise RecordingError(f"{path}: not a rerun recording (.rrd)") from None
    end = offset = _STREAM_HEADER
    while offset + _MESSAGE_HEADER.size <= len(data):
        kind, length = _MESSAGE_HEADER.unpack_from(data, offset)
        stop = offset + _MESSAGE_HEADER.size + length
        if kind == 0 or stop > len(data):
            break
        end = offset = stop
    if end == len(data):
        raise RecordingError(f"{path}: unreadable: {err}") from None
    with tempfile.TemporaryDirectory() as tmp:
        whole = Path(tmp) / path.name
        whole.write_bytes(data[:end])
        try:
            return list(rc.RrdReader(whole).stream())
        except (RuntimeError, ValueError) as again:
            raise RecordingError(f"{path}: unreadable: {again}") from None
