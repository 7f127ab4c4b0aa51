"""The actuator side and the accelerometer as vehicles log them, turned into our format.

Our format carries rotor speeds (rad/s) and the world-frame kinematic acceleration. Real logs
carry rotor speeds (rad/s or rpm), per-rotor thrust (N or grams-force), collective thrust,
normalised throttle (per rotor or collective, with a hover throttle) or PWM through a thrust
curve, and an accelerometer with or without gravity, in the body or the world frame. Thrust
becomes rotor speed through the vehicle's own thrust coefficient, n = sqrt(f / C_T), so the
diagnosis sees the thrust the log says, whatever the vehicle's rotors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from simbridge.config import ConfigError
from simbridge.frames import quat_to_matrices
from simbridge.vehicle import GRAVITY_M_S2, Vehicle

KINDS = ("rotor_speed", "rotor_thrust", "collective_thrust", "throttle", "pwm")
SPEED_UNITS = {"rad/s": 1.0, "rpm": 2.0 * math.pi / 60.0}
THRUST_UNITS = {"N": 1.0, "gf": GRAVITY_M_S2 / 1000.0, "kgf": GRAVITY_M_S2}
GRAVITY = ("removed", "included")  # included: at rest the accelerometer reads +g upwards
ACCEL_FRAMES = ("world", "body")


@dataclass(frozen=True)
class ActuatorModel:
    """What the actuator columns hold. `rotor_speed` (unit rad/s or rpm), `rotor_thrust` (N,
    gf or kgf per rotor), `collective_thrust` (one column, shared equally), `throttle` (0..1,
    per rotor or one collective column; thrust = weight/4 x throttle / hover_throttle unless a
    thrust curve is given) or `pwm` (through `thrust_curve_n`: per-rotor N = a u^2 + b u + c)."""

    kind: str = "rotor_speed"
    unit: str = "rad/s"
    hover_throttle: float | None = None  # collective throttle that carries the weight
    thrust_curve_n: tuple[float, float, float] | None = None
    # a log column holding the hover throttle row by row (it follows the battery voltage)
    hover_throttle_column: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError(f"actuators.kind: {self.kind!r} is not one of {', '.join(KINDS)}")
        units = SPEED_UNITS if self.kind == "rotor_speed" else THRUST_UNITS
        if self.kind in ("rotor_speed", "rotor_thrust", "collective_thrust") and (
            self.unit not in units
        ):
            raise ConfigError(
                f"actuators.unit: {self.unit!r} is not one of {', '.join(units)} "
                f"for kind {self.kind}"
            )
        if self.kind == "pwm" and self.thrust_curve_n is None:
            raise ConfigError(
                "actuators.thrust_curve_n: kind pwm needs [a, b, c] (N = a u^2 + b u + c)"
            )
        if (
            self.kind == "throttle"
            and self.thrust_curve_n is None
            and (self.hover_throttle_column is None)
        ):
            h = self.hover_throttle
            if h is None or not 0.0 < h <= 1.0:
                raise ConfigError(
                    f"actuators.hover_throttle: kind throttle needs a value in (0, 1] "
                    f"(or thrust_curve_n), got {h!r}"
                )
        if self.thrust_curve_n is not None and len(self.thrust_curve_n) != 3:
            raise ConfigError("actuators.thrust_curve_n: expected three numbers [a, b, c]")

    @property
    def collective(self) -> bool:
        """Whether one column stands for all four rotors."""
        return self.kind == "collective_thrust"


def actuator_model(data: dict[str, Any] | None) -> ActuatorModel:
    """From a mapping's `actuators:` block (kind, unit, hover_throttle, thrust_curve_n)."""
    if not data:
        return ActuatorModel()
    unknown = sorted(set(data) - {"kind", "unit", "hover_throttle", "thrust_curve_n", "columns"})
    if unknown:
        raise ConfigError(f"actuators: unknown key {unknown[0]!r}")
    kind = str(data.get("kind", "rotor_speed"))
    default_unit = "rad/s" if kind == "rotor_speed" else "N"
    curve, hover = data.get("thrust_curve_n"), data.get("hover_throttle")
    hover_column = hover if isinstance(hover, str) else None
    hover = None if hover_column is not None else hover
    try:
        curve = None if curve is None else tuple(float(c) for c in curve)
        hover = None if hover is None else float(hover)
    except (TypeError, ValueError):
        raise ConfigError(
            f"actuators: hover_throttle must be a number or a column name and thrust_curve_n a "
            f"list of three numbers, got {hover!r} and {curve!r}"
        ) from None
    return ActuatorModel(kind, str(data.get("unit", default_unit)), hover, curve, hover_column)


def rotor_thrust_n(
    values: np.ndarray,
    model: ActuatorModel,
    vehicle: Vehicle,
    hover_throttle: np.ndarray | None = None,
) -> np.ndarray:
    """Per-rotor thrust (N, 4 columns) from the logged actuator values: (N, 4), or (N, 1)
    for a collective column (collective thrust, or a collective throttle). `hover_throttle`:
    the hover throttle row by row (the model's `hover_throttle_column`), else the model's."""
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[:, None]
    if model.kind == "rotor_speed":
        n = v * SPEED_UNITS[model.unit]
        return vehicle.thrust_coefficient_n_s2 * n * np.abs(n)
    if model.kind == "rotor_thrust":
        f = v * THRUST_UNITS[model.unit]
    elif model.kind == "collective_thrust":
        f = v * THRUST_UNITS[model.unit] / 4.0
    elif model.thrust_curve_n is not None:  # throttle or pwm through the curve
        a, b, c = model.thrust_curve_n
        f = a * v * v + b * v + c
    else:  # throttle, linear about the hover throttle
        hover = model.hover_throttle if hover_throttle is None else hover_throttle
        if hover is None:
            raise ConfigError(
                f"actuators.hover_throttle: column {model.hover_throttle_column!r} not given"
            )
        h = np.asarray(hover, dtype=float)
        f = vehicle.weight_n / 4.0 * v / (h[:, None] if h.ndim == 1 else h)
    return np.broadcast_to(f, (len(f), 4)).copy()


def rotor_speeds_rad_s(
    values: np.ndarray,
    model: ActuatorModel,
    vehicle: Vehicle,
    hover_throttle: np.ndarray | None = None,
) -> np.ndarray:
    """Rotor speeds (rad/s) that give the logged thrust through the vehicle's C_T."""
    if model.kind == "rotor_speed":
        n = np.asarray(values, dtype=float) * SPEED_UNITS[model.unit]
        return np.broadcast_to(n if n.ndim > 1 else n[:, None], (len(n), 4)).copy()
    f = rotor_thrust_n(values, model, vehicle, hover_throttle)
    return np.sqrt(np.maximum(f, 0.0) / vehicle.thrust_coefficient_n_s2)


def kinematic_acceleration(
    acc: np.ndarray, q_wxyz: np.ndarray, gravity: str = "removed", frame: str = "world"
) -> np.ndarray:
    """World-frame kinematic acceleration (m/s^2) from an accelerometer-like column set:
    `frame` body (turned by the attitude) or world; `gravity` included (a specific force:
    +g upwards at rest) or removed."""
    if gravity not in GRAVITY:
        raise ConfigError(f"accelerometer.gravity: {gravity!r} is not one of {', '.join(GRAVITY)}")
    if frame not in ACCEL_FRAMES:
        raise ConfigError(f"accelerometer.frame: {frame!r} is not one of {', '.join(ACCEL_FRAMES)}")
    a = np.asarray(acc, dtype=float)
    if frame == "body":
        a = np.einsum("nij,nj->ni", quat_to_matrices(q_wxyz), a)
    if gravity == "included":
        a = a - np.array([0.0, 0.0, GRAVITY_M_S2])
    return a
