"""The world: ground, obstacles, geodetic origin, start pose, rates and physical effects.

Loaded from a world YAML into frozen dataclasses. World frame: x east, y north, z up (m).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from simbridge.config import ConfigError, build, load_yaml, param, resolve_packaged
from simbridge.effects import EffectSet, parse_effects
from simbridge.sensor_noise import SensorNoise
from simbridge.sensors import SENSORS, SimSensor

WORLDS_DIR = Path(__file__).parent / "worlds"
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class GeodeticOrigin:
    lat_deg: float = param(59.3498, unit="deg", lo=-90.0, hi=90.0, doc="latitude of x = y = 0")
    lon_deg: float = param(18.0707, unit="deg", lo=-180.0, hi=180.0, doc="longitude")
    alt_m: float = param(28.0, unit="m", lo=-500.0, hi=9000.0, doc="ground altitude AMSL")
    magnetic_field_ned_gauss: Vec3 = param(
        (0.155, 0.015, 0.49), unit="gauss", lo=-1.0, hi=1.0, doc="Earth field, north east down"
    )


@dataclass(frozen=True)
class StartPose:
    xy_m: tuple[float, float] = param((0.0, 0.0), unit="m", lo=-1000.0, hi=1000.0, doc="x, y")
    altitude_m: float | None = param(
        None,
        unit="m",
        lo=-100.0,
        hi=1000.0,
        doc="centre-of-mass height; null rests the vehicle on the surface below",
    )
    roll_deg: float = param(
        0.0,
        unit="deg",
        lo=-180.0,
        hi=180.0,
        doc="initial roll about body x (forward); positive: right side down",
    )
    pitch_deg: float = param(
        0.0,
        unit="deg",
        lo=-90.0,
        hi=90.0,
        doc="initial pitch about body y (left); positive: nose down (REP 103)",
    )
    yaw_deg: float = param(0.0, unit="deg", lo=-180.0, hi=180.0, doc="initial yaw (from east)")


@dataclass(frozen=True)
class Box:
    """A box resting in the world: centre, full size, yaw."""

    center_m: Vec3 = param(unit="m", lo=-1000.0, hi=1000.0, doc="centre of the box")
    size_m: Vec3 = param(
        unit="m", lo=0.0, hi=1000.0, lo_open=True, doc="full length, width, height"
    )
    yaw_deg: float = param(0.0, unit="deg", lo=-180.0, hi=180.0, doc="rotation about z")


@dataclass(frozen=True)
class Wall:
    """A vertical wall standing on the ground, `start_m` to `end_m` along its base line."""

    start_m: tuple[float, float] = param(unit="m", lo=-1000.0, hi=1000.0, doc="one end, x y")
    end_m: tuple[float, float] = param(unit="m", lo=-1000.0, hi=1000.0, doc="other end, x y")
    height_m: float = param(2.0, unit="m", lo=0.0, hi=100.0, lo_open=True, doc="height")
    thickness_m: float = param(0.1, unit="m", lo=0.0, hi=10.0, lo_open=True, doc="thickness")

    def as_box(self) -> Box:
        (x0, y0), (x1, y1) = self.start_m, self.end_m
        length = math.hypot(x1 - x0, y1 - y0)
        if length == 0.0:
            raise ValueError("wall start_m and end_m coincide")
        return Box(
            center_m=((x0 + x1) / 2, (y0 + y1) / 2, self.height_m / 2),
            size_m=(length, self.thickness_m, self.height_m),
            yaw_deg=math.degrees(math.atan2(y1 - y0, x1 - x0)),
        )


@dataclass(frozen=True)
class Step:
    """A table-like raised platform from the ground to `height_m` over a rectangle."""

    min_xy_m: tuple[float, float] = param(unit="m", lo=-1000.0, hi=1000.0, doc="one corner")
    max_xy_m: tuple[float, float] = param(unit="m", lo=-1000.0, hi=1000.0, doc="opposite corner")
    height_m: float = param(unit="m", lo=0.0, hi=100.0, lo_open=True, doc="top surface height")

    def as_box(self) -> Box:
        (x0, y0), (x1, y1) = self.min_xy_m, self.max_xy_m
        if x1 <= x0 or y1 <= y0:
            raise ValueError("max_xy_m must exceed min_xy_m on both axes")
        return Box(
            center_m=((x0 + x1) / 2, (y0 + y1) / 2, self.height_m / 2),
            size_m=(x1 - x0, y1 - y0, self.height_m),
        )


OBSTACLE_KINDS: dict[str, type] = {"box": Box, "wall": Wall, "step": Step}


@dataclass(frozen=True)
class _Rates:
    """Rates of the HIL messages besides HIL_SENSOR and HIL_STATE_QUATERNION (every step).

    A sensor samples on the first control step of each of its own periods, so its mean rate is
    the one given (100 Hz at a 250 Hz control rate: every 2nd and 3rd step in turn); rates
    above the control rate give a message every step. A declared sensor's rate is a field
    named by its `rate_key` (simbridge/sensors), its default the declared one.
    """

    odometry_until_s: float | None = param(
        None,
        unit="s",
        lo=0.0,
        hi=1e6,
        doc="motion capture stops at this simulated time (tracking lost); null: never",
    )
    truth_hz: float = param(
        250.0,
        unit="Hz",
        lo=0.0,
        hi=1000.0,
        doc="DEBUG_VECT GE_TRUE, the true ground-effect force, for evaluation only",
    )

    def rate_hz(self, sensor: str) -> float:
        """The rate of the declared sensor `sensor` (its declared one if this world's fields
        were made before it was declared)."""
        declared = SENSORS[sensor]
        return getattr(self, declared.rate_key, declared.rate_hz)


def _rate_field(sensor: SimSensor) -> tuple[str, type, Any]:
    rate = param(sensor.rate_hz, unit="Hz", lo=0.0, hi=1000.0, doc=sensor.doc)
    return (sensor.rate_key, float, rate)


SensorRates = dataclasses.make_dataclass(
    "SensorRates", [_rate_field(s) for s in SENSORS.values()], bases=(_Rates,), frozen=True
)
SensorRates.__module__, SensorRates.__doc__ = __name__, _Rates.__doc__


@dataclass(frozen=True)
class World:
    vehicle: str = param("nano", doc="packaged vehicle name or path to a vehicle YAML")
    origin: GeodeticOrigin = param(GeodeticOrigin(), doc="geodetic origin of the local frame")
    start: StartPose = param(StartPose(), doc="initial pose")
    physics_rate_hz: int = param(1000, unit="Hz", lo=50, hi=10000, doc="physics step rate")
    control_period_s: float = param(
        0.004, unit="s", lo=0.0005, hi=0.1, doc="HIL period; a whole number of physics steps"
    )
    ground_friction: float = param(0.8, lo=0.0, hi=5.0, doc="lateral friction of all surfaces")
    ceiling_height_m: float | None = param(
        None, unit="m", lo=0.05, hi=1000.0, doc="height of a ceiling over everything; null: none"
    )
    obstacles: tuple[Box, ...] = ()
    sensors: SensorRates = param(SensorRates(), doc="HIL message rates")
    sensor_noise: SensorNoise = param(
        SensorNoise(), doc="sensor errors (sources: simbridge/sensor_noise.py, simbridge/sensors)"
    )
    effects: EffectSet = EffectSet()

    def __post_init__(self) -> None:
        steps = self.control_period_s * self.physics_rate_hz
        if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
            raise ValueError(
                f"control_period_s {self.control_period_s:g} must be a whole number of physics "
                f"steps of 1/{self.physics_rate_hz} s"
            )

    @property
    def physics_dt_s(self) -> float:
        return 1.0 / self.physics_rate_hz

    @property
    def substeps(self) -> int:
        """Physics steps per control period."""
        return round(self.control_period_s * self.physics_rate_hz)

    @property
    def control_period_us(self) -> int:
        return round(self.control_period_s * 1e6)

    def samples_per_step(self, rate_hz: float) -> float:
        """A message rate in samples per control step (0: never; above 1: every step)."""
        return max(0.0, rate_hz) * self.control_period_s


def resolve_world_path(name_or_path: str | Path) -> Path:
    """A packaged world name (`default`, `rho2`, ...) or a path to a world YAML."""
    return resolve_packaged(name_or_path, WORLDS_DIR, ".yaml", "world")


def _parse_obstacles(entries: Any, where: str) -> tuple[Box, ...]:
    if entries is None:
        return ()
    if not isinstance(entries, list):
        raise ConfigError(f"{where}: expected a list of obstacles, got {entries!r}")
    boxes = []
    for i, entry in enumerate(entries):
        at = f"{where}[{i}]"
        if not isinstance(entry, dict) or entry.get("kind") not in OBSTACLE_KINDS:
            raise ConfigError(f"{at}.kind: expected one of {', '.join(OBSTACLE_KINDS)}")
        cls = OBSTACLE_KINDS[entry["kind"]]
        shape = build(
            cls, {k: v for k, v in entry.items() if k != "kind"}, f"{at} ({entry['kind']})"
        )
        try:
            boxes.append(shape if isinstance(shape, Box) else shape.as_box())
        except ValueError as err:
            raise ConfigError(f"{at}: {err}") from None
    return tuple(boxes)


def parse_world(data: dict[str, Any], where: str) -> World:
    data = dict(data)
    obstacles = _parse_obstacles(data.pop("obstacles", None), f"{where}: obstacles")
    effects = parse_effects(data.pop("effects", None), f"{where}: effects")
    world = build(World, data, where)
    return dataclasses.replace(world, obstacles=obstacles, effects=effects)


def load_world(name_or_path: str | Path = "default") -> World:
    path = resolve_world_path(name_or_path)
    world = parse_world(load_yaml(path), str(path))
    learned = world.effects.learned_residual
    if learned is not None:  # a model file beside the world file, read from there
        model = Path(learned.model_path)
        if not model.is_absolute():
            model = path.parent / model
        if not model.is_file():
            raise ConfigError(f"{path}: effects: learned_residual.model_path: no such file {model}")
        effects = world.effects.replace(
            learned_residual=dataclasses.replace(learned, model_path=str(model.resolve())),
        )
        world = dataclasses.replace(world, effects=effects)
    return world


def parse_start(text: str) -> tuple[float, float, float]:
    """`--start X,Y,Z` into metres; raises ConfigError naming the option."""
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--start: expected X,Y,Z in metres, got {text!r}") from None
    if not all(math.isfinite(v) and abs(v) <= 1000.0 for v in (x, y, z)):
        raise ConfigError(f"--start: each of X,Y,Z must be in [-1000, 1000] m, got {text!r}")
    return (x, y, z)


def with_start(world: World, position_m: tuple[float, float, float]) -> World:
    start = dataclasses.replace(world.start, xy_m=position_m[:2], altitude_m=position_m[2])
    return dataclasses.replace(world, start=start)


def with_ideal_sensors(world: World) -> World:
    """The world with every sensor error off (`--ideal-sensors`): truth, on time."""
    return dataclasses.replace(world, sensor_noise=SensorNoise.ideal())
