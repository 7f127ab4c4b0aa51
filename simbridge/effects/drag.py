"""Aerodynamic drag and wind.

- rotor drag (blade flapping and induced drag): f_body = -k_d * (n0 + n1 + n2 + n3) * v_air,body,
  per body axis (the linear model identified for nano quadrotors, e.g. Foerster 2015);
- body drag: f_body = -0.5 rho_air C_d A_axis |v_air| v_air,axis;
- wind: a constant field plus gusts; drag acts on the air-relative velocity v - w(t).
Gusts are a sum of sinusoids with seeded phases and log-spaced frequencies, a pure function
of time whose standard deviation per axis is `gust_std_m_s`.
"""

from __future__ import annotations

import functools
import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, replace

from simbridge.config import param
from simbridge.vehicle import Vehicle, nano_vehicle

Vec3 = tuple[float, float, float]


# The defaults are the nano's (the reference vehicle). A world that names rotor_drag or
# body_drag without values on another vehicle gets them restated for it (`for_vehicle`):
# rotor drag at the same share of the weight per m/s at hover, the body's own areas. The
# nano's values on a Crazyflie (rotor speeds of about 1700 rad/s, not 76) were a drag of
# 45% of its weight per m/s, 21 times what Foerster 2015 measured on one.
# Scaled from the Crazyflie's 9.2e-7, 10.3e-7 kg/rad at its ~7000 rad/s rotor-speed sum to
# the nano's ~300 rad/s, keeping the drag per m/s at hover (about 6.7e-3 N s/m).
NANO_ROTOR_DRAG_N_S_M: Vec3 = (2.2e-5, 2.2e-5, 1.0e-5)


@dataclass(frozen=True)
class RotorDragParams:
    coefficient_n_s_m: Vec3 | None = param(
        None,
        unit="N/((rad/s) (m/s))",
        lo=0.0,
        hi=1e-2,
        doc="k_d per body axis x, y, z; null: the nano's (2.2e-5, 2.2e-5, 1e-5) at the same "
        "share of the vehicle's weight per m/s at hover",
    )


@dataclass(frozen=True)
class BodyDragParams:
    drag_coefficient: float = param(1.0, lo=0.0, hi=5.0, doc="C_d")
    area_m2: Vec3 | None = param(
        None,
        unit="m^2",
        lo=0.0,
        hi=1.0,
        doc="reference area facing body x, y, z; null: the faces of the vehicle's body_size_m "
        "box (the nano's: 0.002016, 0.002016, 0.0064)",
    )
    air_density_kg_m3: float = param(1.225, unit="kg/m^3", lo=0.5, hi=1.5, doc="rho_air")


def body_areas_m2(body_size_m: Sequence[float]) -> Vec3:
    """The body-drag reference areas facing body x, y and z of a box body (m^2)."""
    x, y, z = body_size_m
    return (y * z, x * z, x * y)


def rotor_drag_scale(vehicle: Vehicle) -> float:
    """How much larger a rotor-drag coefficient is on `vehicle` than on the nano for the same
    share of the weight per m/s at hover: (weight / hover rotor speed) over the nano's."""
    nano = nano_vehicle()
    return (vehicle.weight_n / vehicle.hover_rotor_speed_rad_s) / (
        nano.weight_n / nano.hover_rotor_speed_rad_s
    )


def rotor_drag_for(params: RotorDragParams, vehicle: Vehicle) -> RotorDragParams:
    if params.coefficient_n_s_m is not None:
        return params
    f = rotor_drag_scale(vehicle)
    kx, ky, kz = NANO_ROTOR_DRAG_N_S_M
    return RotorDragParams(coefficient_n_s_m=(kx * f, ky * f, kz * f))


def body_drag_for(params: BodyDragParams, vehicle: Vehicle) -> BodyDragParams:
    if params.area_m2 is not None:
        return params
    return replace(params, area_m2=body_areas_m2(vehicle.body_size_m))


@dataclass(frozen=True)
class WindParams:
    mean_m_s: Vec3 = param((0.0, 0.0, 0.0), unit="m/s", lo=-30.0, hi=30.0, doc="world-frame wind")
    gust_std_m_s: float = param(0.0, unit="m/s", lo=0.0, hi=20.0, doc="gust standard deviation")
    gust_min_hz: float = param(0.05, unit="Hz", lo=0.001, hi=50.0, doc="lowest gust frequency")
    gust_max_hz: float = param(2.0, unit="Hz", lo=0.001, hi=50.0, doc="highest gust frequency")
    gust_seed: int = param(0, lo=0, hi=2**31 - 1, doc="seed of the gust phases")

    def __post_init__(self) -> None:
        if self.gust_max_hz < self.gust_min_hz:
            raise ValueError("gust_max_hz must be at least gust_min_hz")


GUST_COMPONENTS = 8


@functools.lru_cache(maxsize=64)
def gust_components(params: WindParams) -> tuple[tuple[float, float, float], ...]:
    """(axis, angular frequency rad/s, phase rad) of each sinusoid; amplitudes are equal."""
    rng = random.Random(params.gust_seed)
    lo, hi = math.log(params.gust_min_hz), math.log(params.gust_max_hz)
    parts = []
    for axis in range(3):
        for k in range(GUST_COMPONENTS):
            f_hz = math.exp(lo + (hi - lo) * (k + rng.random()) / GUST_COMPONENTS)
            parts.append((float(axis), 2.0 * math.pi * f_hz, 2.0 * math.pi * rng.random()))
    return tuple(parts)


def wind_velocity_m_s(params: WindParams, time_s: float) -> Vec3:
    """Wind at `time_s` in the world frame."""
    if params.gust_std_m_s == 0.0:
        return params.mean_m_s
    amplitude = params.gust_std_m_s * math.sqrt(2.0 / GUST_COMPONENTS)
    w = list(params.mean_m_s)
    for axis, omega, phase in gust_components(params):
        w[int(axis)] += amplitude * math.sin(omega * time_s + phase)
    return (w[0], w[1], w[2])


def rotor_drag_n(params: RotorDragParams, rotor_speed_sum_rad_s: float, v_air_body: Vec3) -> Vec3:
    """Body-frame rotor drag force (floats, or numpy arrays of speeds and components); the
    coefficients restated for the vehicle first (`rotor_drag_for`)."""
    kx, ky, kz = params.coefficient_n_s_m
    s = -rotor_speed_sum_rad_s
    return (s * kx * v_air_body[0], s * ky * v_air_body[1], s * kz * v_air_body[2])


def body_drag_n(params: BodyDragParams, v_air_body: Vec3) -> Vec3:
    """Body-frame quadratic drag force (floats, or numpy arrays of components); the areas
    restated for the vehicle first (`body_drag_for`)."""
    vx, vy, vz = v_air_body
    speed = (vx * vx + vy * vy + vz * vz) ** 0.5
    q = -0.5 * params.air_density_kg_m3 * params.drag_coefficient * speed
    ax, ay, az = params.area_m2
    return (q * ax * vx, q * ay * vy, q * az * vz)
