"""The vehicle: one frozen, validated dataclass loaded from the vehicle YAML.

Both the simulator and the autopilot read this; it is the one place for the vehicle's facts.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from pathlib import Path

from simbridge.config import build, load_yaml, param, resolve_packaged

VEHICLES_DIR = Path(__file__).parent / "vehicles"
GRAVITY_M_S2 = 9.81

# Rotor layout in the body frame (x forward, y left), as multiples of half the rotor spacing,
# numbered as thesis equation 3.6 (see `simbridge.rotors`).
ROTOR_LAYOUT = ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0))


@dataclass(frozen=True)
class Vehicle:
    name: str = param(doc="vehicle name")
    mass_kg: float = param(unit="kg", lo=0.0, hi=10.0, lo_open=True, doc="mass")
    body_size_m: tuple[float, float, float] = param(
        unit="m", lo=0.0, hi=2.0, lo_open=True, doc="collision box length, width, height"
    )
    rotor_spacing_m: float = param(
        unit="m", lo=0.0, hi=2.0, lo_open=True, doc="smallest distance between two rotors"
    )
    rotor_radius_m: float = param(unit="m", lo=0.0, hi=1.0, lo_open=True, doc="rotor radius R")
    thrust_coefficient_n_s2: float = param(
        unit="N/(rad/s)^2", lo=0.0, hi=1.0, lo_open=True, doc="C_T, f = C_T n^2"
    )
    max_rotor_speed_rad_s: float = param(
        unit="rad/s", lo=0.0, hi=10000.0, lo_open=True, doc="n_max"
    )
    yaw_moment_coefficient_m: float = param(
        unit="m", lo=0.0, hi=1.0, lo_open=True, doc="k_z, rotor drag torque per thrust"
    )
    inertia_kg_m2: tuple[float, float, float] = param(
        unit="kg m^2", lo=0.0, hi=10.0, lo_open=True, doc="principal moments Ixx, Iyy, Izz"
    )
    rotor_height_m: float = param(0.0, unit="m", lo=-0.5, hi=0.5, doc="rotor plane above CoM")
    range_sensor_max_m: float = param(
        4.0, unit="m", lo=0.0, hi=100.0, lo_open=True, doc="downward range sensor maximum"
    )
    actuator_channels: tuple[int, int, int, int] = param(
        (0, 1, 2, 3), lo=0, hi=15, doc="HIL_ACTUATOR_CONTROLS channel of rotors 0..3"
    )

    def __post_init__(self) -> None:
        if len(set(self.actuator_channels)) != 4:
            raise ValueError(
                f"actuator_channels must be 4 distinct channels, got {self.actuator_channels}"
            )
        if self.hover_rotor_speed_rad_s >= self.max_rotor_speed_rad_s:
            raise ValueError(
                f"max_rotor_speed_rad_s {self.max_rotor_speed_rad_s:g} cannot lift the vehicle "
                f"(hover needs {self.hover_rotor_speed_rad_s:.1f} rad/s)"
            )
        ixx, iyy, izz = self.inertia_kg_m2
        if ixx + iyy < izz or ixx + izz < iyy or iyy + izz < ixx:
            raise ValueError(f"inertia_kg_m2 {self.inertia_kg_m2} violates the triangle inequality")

    @property
    def arm_m(self) -> float:
        """Moment arm k of thesis equation 3.6 about body x and y: half the rotor spacing."""
        return 0.5 * self.rotor_spacing_m

    @property
    def weight_n(self) -> float:
        return self.mass_kg * GRAVITY_M_S2

    @property
    def hover_rotor_speed_rad_s(self) -> float:
        """Rotor speed at which four rotors carry the weight out of ground effect."""
        return math.sqrt(self.weight_n / (4.0 * self.thrust_coefficient_n_s2))

    def rotor_positions_body_m(self) -> tuple[tuple[float, float, float], ...]:
        """Rotor hub positions in the body frame (x forward, y left, z up), rotors 0..3."""
        a = self.arm_m
        return tuple((sx * a, sy * a, self.rotor_height_m) for sx, sy in ROTOR_LAYOUT)


def resolve_vehicle_path(name_or_path: str | Path) -> Path:
    """A packaged vehicle name (`nano`) or a path to a vehicle YAML."""
    return resolve_packaged(name_or_path, VEHICLES_DIR, ".yaml", "vehicle")


def load_vehicle(name_or_path: str | Path = "nano") -> Vehicle:
    path = resolve_vehicle_path(name_or_path)
    return build(Vehicle, load_yaml(path), str(path))


@functools.lru_cache(maxsize=1)
def nano_vehicle() -> Vehicle:
    """The thesis's nano quadrotor: the vehicle the effects' defaults are stated for."""
    return load_vehicle("nano")


def vehicle_fields(vehicle: Vehicle) -> dict[str, object]:
    """A vehicle as the plain mapping of its YAML file (tuples as lists)."""
    return {
        f.name: list(v) if isinstance(v := getattr(vehicle, f.name), tuple) else v
        for f in dataclasses.fields(vehicle)
    }


def with_fields(vehicle: Vehicle, where: str, **fields: object) -> Vehicle:
    """`vehicle` with `fields` replaced, checked as a vehicle file's are (range, unit)."""
    return build(Vehicle, {**vehicle_fields(vehicle), **fields}, where)
