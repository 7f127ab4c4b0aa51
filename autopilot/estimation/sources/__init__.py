"""The estimator's sources, each declared once: the simulator's sensor it reads, its
parameters (PX4's EKF2 names), what it sets in each `--sensors` set, and its fusion.

A declaration names the simulator's sensor it reads (`simbridge.sensors`, or `imu` for
HIL_SENSOR); the parameter table (`autopilot.params`), the sensor sets of the command line and
the estimator (`navigation`) read these declarations. Sources fuse in the order of `SOURCES`
(the order of the Kalman updates: one order, one flight). Sources outside this package are
declared by modules named in GROUNDFX_AUTOPILOT_SENSORS (comma-separated), imported here;
each calls `register`.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from autopilot.estimation import estimator as ekf
    from autopilot.estimation.estimator_params import EstimatorParams
    from autopilot.estimation.sensors import Imu
    from autopilot.types import Step

PLUGINS_ENV = "GROUNDFX_AUTOPILOT_SENSORS"
SLOW_FUSION_EVERY = 5  # heading, barometer, rest: every fifth control step (50 Hz)


class Navigation(Protocol):
    """What a source's fusion reads and corrects of the estimator
    (`autopilot.estimation.navigation.Navigation`)."""

    estimate: ekf.Estimate | None
    params: EstimatorParams
    quality: Any  # counts per source (`navigation.Quality`)
    events: list[str]
    memory: dict[str, Any]  # what the sources keep from step to step
    range_m: float | None  # the step's downward range, for the height fusion
    height_source: str
    origin: tuple[float, float, float]
    resting_height_m: float

    @property
    def steps(self) -> int: ...

    def settings(self, source: str) -> Any: ...

    def seen(self, label: str, t: float) -> None: ...

    def alive(self, label: str, t: float) -> bool: ...

    def at_capture(self, time_us: int) -> tuple[Any, Any]: ...

    def fuse(self, source: str, fused: ekf.Fused) -> bool: ...


@dataclass(frozen=True)
class Alignment:
    """What a source gives the filter's initial state; None where it gives nothing."""

    position_m: tuple[float, float, float] | None = None
    position_sd_m: float = 0.0
    quaternion: tuple[float, float, float, float] | None = None  # (w, x, y, z) body to world
    attitude_sd_rad: float = 0.0
    seen: bool = False  # counts as the source's first sample (its loss is then timed)


WAIT = Alignment()  # the source is on and has not spoken yet: no alignment this step


def _never(settings: Any) -> bool:
    return False


def _always(nav: Navigation, settings: Any) -> bool:
    return True


@dataclass(frozen=True)
class Source:
    name: str  # its parameter group, and its settings' key in `EstimatorParams.sources`
    label: str  # as the estimator's events and counts name it
    sensor: str  # the simulator's declaration it reads (`imu`: HIL_SENSOR)
    settings: type  # a frozen dataclass of its parameters, with `param()` metadata
    names: Mapping[str, str]  # parameter name -> settings field
    fuse: Callable[[Navigation, Step, Imu, Any, float], None]  # (nav, step, imu, settings, t)
    # on, as the settings say (the sources the estimator's events list)
    active: Callable[[Navigation, Any], bool] = _always
    switch: str | None = None  # its on/off parameter, 0 in the sensor sets that omit it
    sets: Mapping[str, Mapping[str, float]] = dataclasses.field(default_factory=dict)
    gives_position: Callable[[Any], bool] = _never  # horizontal position, lost if it stops
    align: Callable[[Navigation, Step, Imu, Any], Alignment | None] | None = None


SOURCES: dict[str, Source] = {}


def register(source: Source) -> Source:
    """Adds `source`, fused after those registered before it."""
    if source.name in SOURCES:
        raise ValueError(f"estimator source {source.name!r} is declared twice")
    SOURCES[source.name] = source
    return source


def parameter_names() -> dict[str, tuple[str, str]]:
    """Each source's parameters: name -> (group, field), for the parameter table."""
    return {
        name: (source.name, field)
        for source in SOURCES.values()
        for name, field in source.names.items()
    }


def sensor_sets() -> dict[str, dict[str, float]]:
    """`--sensors NAME`: the parameters each sensor set sets; a set turns off (0) the
    switched sources it does not name."""
    names = [name for source in SOURCES.values() for name in source.sets]
    out: dict[str, dict[str, float]] = {}
    for set_name in dict.fromkeys(names):
        values: dict[str, float] = {}
        for source in SOURCES.values():
            if source.switch is not None:
                values[source.switch] = 0
        for source in SOURCES.values():
            values.update(source.sets.get(set_name, {}))
        out[set_name] = values
    return out


def _load() -> None:
    # the packaged sources first, in the order they fuse
    for name in ("mocap", "gps", "range", "magnetometer", "flow"):
        importlib.import_module(f"autopilot.estimation.sources.{name}")
    for module in filter(None, os.environ.get(PLUGINS_ENV, "").split(",")):
        importlib.import_module(module.strip())


_load()
