"""The flight recorder: every flight as one rerun recording, written by the autopilot.

The simulator's truth reaches the autopilot over MAVLink (the true state in
HIL_STATE_QUATERNION, the true ground-effect force in DEBUG_VECT "GE_TRUE", the actual rotor
speeds in ESC telemetry), so the autopilot alone writes truth and its own view side by side:
one process, one file, one recording id. The layout is `learner.flightlogs.recording`'s.

The loop must not wait for it. `step` appends one tuple per control step; every `flush_every_s` of
simulated time (or FLUSH_WALL_S of wall time, if that comes first) the rows become numpy columns and
leave as a few Arrow record batches (`autopilot.recording.recorder_rows`,
`autopilot.recording.rrbatch`: one per set of entities sharing their times, not one call per
entity); rerun encodes and writes them on its own thread. A SIGKILL loses at most the rows since the
last flush (and the footer: the reader copes).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol

from autopilot.recording.record_options import RecordOptions

if TYPE_CHECKING:
    from autopilot.commander.mission_items import PlanStep
    from autopilot.control.controller import ControlOutput
    from autopilot.types import FlightState, Setpoint, Step
    from simbridge.frames import Vec3
    from simbridge.rotors import Quad
    from simbridge.vehicle import Vehicle


class Recorder(Protocol):
    """What the flight loop calls; `NullRecorder` when recording is off."""

    def step(
        self,
        t_s: float,
        msgs: Step,
        state: FlightState,
        height_m: float,
        mode: str,
        armed: bool,
        setpoint: Setpoint | None,
        ge_n: Vec3,
        speeds_rad_s: Quad,
        output: ControlOutput | None,
        flight_mode: str = "",
    ) -> None: ...
    def event(self, text: str, level: str = "INFO", t_s: float | None = None) -> None: ...
    def learner(
        self,
        t_s: float,
        loss: float | None = None,
        version: int | None = None,
        note: str = "",
        ground: str | None = None,
    ) -> None: ...
    def estimator(
        self, t_s: float, errors: Sequence[float], test_ratios: dict[str, float]
    ) -> None: ...
    def watch_counters(self, link: str, read: Callable[[], Sequence[int]]) -> None: ...
    def mission(
        self, plan: Sequence[PlanStep], start_m: Vec3, home_m: Vec3 | None, t_s: float
    ) -> None: ...
    def close(self, ended: str, summary: dict[str, Any] | None = None) -> None: ...
    def stats(self) -> dict[str, float]: ...


class NullRecorder:
    """Recording off."""

    def step(self, *args: object, **kwargs: object) -> None:
        pass

    def event(self, text: str, level: str = "INFO", t_s: float | None = None) -> None:
        pass

    def learner(self, *args: object, **kwargs: object) -> None:
        pass

    def estimator(self, t_s: float, errors: Sequence[float], test_ratios: dict[str, float]) -> None:
        pass

    def watch_counters(self, link: str, read: Callable[[], Sequence[int]]) -> None:
        pass

    def mission(
        self, plan: Sequence[PlanStep], start_m: Vec3, home_m: Vec3 | None, t_s: float
    ) -> None:
        pass

    def close(self, ended: str, summary: dict[str, Any] | None = None) -> None:
        pass

    def stats(self) -> dict[str, float]:
        return {}


def open_recorder(
    options: RecordOptions | None,
    vehicle: Vehicle,
    modes: Sequence[str],
) -> Recorder:
    if options is None:
        return NullRecorder()
    # imported here: rerun takes a quarter of a second to import, which an autopilot that
    # does not record should not wait for
    from autopilot.recording.flight_recorder import FlightRecorder

    return FlightRecorder(options, vehicle, modes)
