"""Effects outside the diagnosis's catalogue: the gap bench flies them so that the diagnosis
is tested on physics it cannot name (it must locate them, decline to name a catalogue effect
with confidence, and learn them as a residual). The simulator applies them like any other.

- ground_effect_exponential: another shape of ground effect, per rotor and vertical,
      f_i * gain * exp(-h_i / (decay_radii R))
  with h_i the rotor's height above the surface below it (a ray, as for equation 3.4): finite
  at the surface where equation 3.4 is singular, and with a longer tail for decay_radii > 1.
  Optionally fading with horizontal speed, exp(-(v_h / fade_speed_m_s)^2), and acting only
  over a patch of floor (a landing pad of another surface than the floor around it).
- thrust_decay: C_T falls linearly over the flight (battery sag),
      scale(t) = max(1 - rate_per_s * t, floor)
  with t the time since take-off (`Simulation.time_since_takeoff_s`).
- rotor_asymmetry: per-rotor thrust scales (a chipped propeller, a weak motor); the moments
  follow through equation 3.6.
- ground_outwash: a horizontal world-frame force near the ground (the outwash of a rotor wake
  spreading unevenly over the floor),
      gain * T * exp(-h / (decay_radii R))  along direction_deg
  with T the total thrust and h the centre's height above the surface below it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.config import param

TAKEOFF_HEIGHT_M = 0.005  # above its resting height by this much, the vehicle has taken off


@dataclass(frozen=True)
class GroundEffectExponentialParams:
    """A ground effect of exponential shape, per rotor, as a thrust gain."""

    gain: float = param(0.3, lo=0.0, hi=5.0, doc="extra thrust over rotor thrust at h = 0")
    decay_radii: float = param(
        1.5, unit="R", lo=0.0, hi=20.0, lo_open=True, doc="decay length in rotor radii"
    )
    ray_length_m: float = param(
        3.0, unit="m", lo=0.1, hi=100.0, doc="beyond this nothing is below (no force)"
    )
    fade_speed_m_s: float = param(
        0.0, unit="m/s", lo=0.0, hi=20.0,
        doc="above 0: the gain falls as exp(-(v_h / fade)^2) with the horizontal speed v_h",
    )  # fmt: skip
    patch_center_m: tuple[float, float] = param(
        [0.0, 0.0], unit="m", lo=-1000.0, hi=1000.0, doc="the patch's centre (x, y)"
    )
    patch_radius_m: float = param(
        0.0, unit="m", lo=0.0, hi=1000.0,
        doc="above 0: acts only while the centre of mass is over a disc of this radius about "
        "patch_center_m (a landing pad unlike the floor around it)",
    )  # fmt: skip


def exponential_scale(
    params: GroundEffectExponentialParams, x_m: float, y_m: float, horizontal_speed_m_s: float
) -> float:
    """What multiplies the exponential gain at a position and speed: 0 off the patch (where
    there is one), the speed's fade (where there is one), else 1."""
    if params.patch_radius_m > 0.0:
        cx, cy = params.patch_center_m
        if math.hypot(x_m - cx, y_m - cy) > params.patch_radius_m:
            return 0.0
    if params.fade_speed_m_s > 0.0:
        return math.exp(-((horizontal_speed_m_s / params.fade_speed_m_s) ** 2))
    return 1.0


def exponential_gain(height_m: float, gain: float, decay_m: float) -> float:
    """Extra thrust over rotor thrust at `height_m` (inf: nothing below, 0)."""
    if height_m == math.inf:
        return 0.0
    return gain * math.exp(-max(height_m, 0.0) / decay_m)


def exponential_gain_array(height_m: np.ndarray, gain: float, decay_m: float) -> np.ndarray:
    """`exponential_gain` over arrays of heights (inf reads as nothing below)."""
    h = np.asarray(height_m, dtype=float)
    finite = np.where(np.isinf(h), 0.0, np.maximum(h, 0.0))
    return np.where(np.isinf(h), 0.0, gain * np.exp(-finite / decay_m))


@dataclass(frozen=True)
class ThrustDecayParams:
    """C_T of every rotor falls linearly with the time since take-off (battery sag)."""

    rate_per_s: float = param(
        0.002, unit="1/s", lo=0.0, hi=0.1, doc="fraction of C_T lost per second of flight"
    )
    floor: float = param(0.5, lo=0.1, hi=1.0, doc="the scale never falls below this")


def thrust_decay_scale(params: ThrustDecayParams, time_since_takeoff_s: float) -> float:
    """C_T scale after `time_since_takeoff_s` (0 before take-off: 1)."""
    return max(1.0 - params.rate_per_s * max(time_since_takeoff_s, 0.0), params.floor)


@dataclass(frozen=True)
class RotorAsymmetryParams:
    """Per-rotor thrust scales, rotors numbered as equation 3.6 (0 front-left, 1 back-left,
    2 back-right, 3 front-right)."""

    scales: tuple[float, float, float, float] = param(
        (1.0, 1.0, 0.85, 1.0), lo=0.2, hi=2.0, doc="true thrust over modelled, per rotor"
    )


def asymmetric_forces_n(
    params: RotorAsymmetryParams, rotor_forces_n: tuple[float, ...]
) -> tuple[float, float, float, float]:
    s0, s1, s2, s3 = params.scales
    f0, f1, f2, f3 = rotor_forces_n
    return (f0 * s0, f1 * s1, f2 * s2, f3 * s3)


@dataclass(frozen=True)
class GroundOutwashParams:
    """A horizontal force near the ground along a fixed world direction."""

    gain: float = param(0.1, lo=-2.0, hi=2.0, doc="horizontal force over total thrust at h = 0")
    decay_radii: float = param(
        2.0, unit="R", lo=0.0, hi=20.0, lo_open=True, doc="decay length in rotor radii"
    )
    direction_deg: float = param(
        90.0, unit="deg", lo=-180.0, hi=180.0, doc="direction from world +x (east) toward +y"
    )
    ray_length_m: float = param(
        3.0, unit="m", lo=0.1, hi=100.0, doc="beyond this nothing is below (no force)"
    )

    def unit_vector(self) -> tuple[float, float]:
        a = math.radians(self.direction_deg)
        return (math.cos(a), math.sin(a))


def outwash_force_n(
    params: GroundOutwashParams, total_thrust_n: float, height_m: float, rotor_radius_m: float
) -> tuple[float, float, float]:
    """The world-frame force at centre height `height_m` (inf: nothing below, no force)."""
    if height_m == math.inf:
        return (0.0, 0.0, 0.0)
    size = exponential_gain(height_m, params.gain, params.decay_radii * rotor_radius_m)
    ux, uy = params.unit_vector()
    return (size * total_thrust_n * ux, size * total_thrust_n * uy, 0.0)
