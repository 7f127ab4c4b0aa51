"""The effect catalogue as fit candidates: each effect's physical parameters (units, bounds, a
typical magnitude) and one force model of the whole world, built on simbridge/effects' formulas.

`world_force(values, data, vehicle)` is the force, besides gravity, that a world whose effects
have parameters `values` (name -> array, or absent) puts on the logged flight: rotor thrust
(with motor lag and thrust-coefficient scale), ground, ceiling and wall effects, rotor and body
drag on the air-relative velocity, and the measurement terms an accelerometer bias or delay add.
Mass and thrust-coefficient errors scale the residual identically (m a = s T + ... and
k m a = T + ...), so they are one candidate, `thrust_mass`, with c = s / k - 1.

Bounds and typical magnitudes are the nano's (`REFERENCE`), scaled to any other vehicle by
`catalogue(vehicle)`, so that the same relative effect sits at the same place in its range.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from learner.gap.flightdata import FlightData, as_differentiated
from learner.gap.rotor_forces import Values, rotor_forces_n
from simbridge.effects import EffectSet
from simbridge.effects.actuators import thrust_axis_body
from simbridge.effects.drag import (
    BodyDragParams,
    RotorDragParams,
    body_areas_m2,
    body_drag_n,
    rotor_drag_n,
    rotor_drag_scale,
)
from simbridge.effects.ground import (
    CeilingEffectParams,
    GroundEffectParams,
    thrust_gain_array,
)
from simbridge.effects.proximity import WallEffectParams, wall_force_array
from simbridge.vehicle import Vehicle, nano_vehicle


@dataclass(frozen=True)
class Candidate:
    name: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    typical: tuple[float, ...]  # a magnitude worth finding: the excitation test's probe
    effects: tuple[str, ...]  # catalogue effects it stands for
    # what a real vehicle shows (`PHYSICAL`); a fit outside it is reported as implausible
    plausible_lo: tuple[float, ...] = ()
    plausible_hi: tuple[float, ...] = ()
    needs_accelerometer: bool = False  # models the accelerometer: no candidate without one
    # the parameters at which it adds nothing (empty: zeros; a thrust curve's exponent: 1)
    null: tuple[float, ...] = ()

    def null_values(self) -> np.ndarray:
        """The parameters at which the candidate adds nothing."""
        return np.array(self.null, dtype=float) if self.null else np.zeros(len(self.params))


# The reference vehicle the catalogue's magnitudes were chosen for is the thesis's nano
# quadrotor (simbridge/vehicles/nano.yaml); other vehicles get them scaled (`catalogue`).
# A fitted rho of 21 gives 17% more thrust at three rotor radii, the most real Crazyflies
# show (6-17% at 2-3 radii); 25 leaves room above it without reaching the simulator's 50.
RHO_MAX = 25.0
# Half of g: a larger bias is gravity left in the accelerometer, which the residual's
# plausibility check (learner/gap/plausibility.py) stops before any fit.
BIAS_MAX_M_S2 = 5.0
# Wind the reference vehicle could still be flown in (a nano quadrotor's drag at 20 m/s is
# about its weight); the Neural-Fly tunnel blew 12 m/s. Scaled with the vehicle, and never
# past the simulator's own range (simbridge/effects/drag.py: +-30 m/s).
WIND_MAX_M_S = 20.0
SIM_WIND_MAX_M_S = 30.0
# The fit's range of a thrust axis's lean, well past the physical 3 deg (PHYSICAL), so that a
# steady force read as a lean is seen at its value and called implausible
TILT_MAX_DEG = 15.0
# A thrust curve's exponent about hover, f = (W/4) (f_model / (W/4))^gamma: how far real rotors'
# thrust departs from the model a log's thrust was converted with. A curve thrust = (1 - e) u
# + e u^2 of a command u, read as linear, has the local exponent d ln f / d ln u = (1 - e +
# 2 e u) / (1 - e + e u) about hover:
# - PX4's THR_MDL_FAC is that e ("thrust = (1-factor) PWM + factor PWM^2", 0-1, default 0):
#   a log read with e 0 of rotors that follow e 0.5 at a hover command of 0.4 is gamma 1.29;
# - ArduCopter's MOT_THST_EXPO is that e (default 0.65; ESCs that linearise themselves
#   0-0.2, its Motor Thrust Scaling page): 1.39 at the default and a 0.35 hover throttle
#   (MOT_THST_HOVER's default), 1.08 at 0.2, 2 at e 1 (a pure square);
# - a Crazyflie firmware's PWM-to-thrust model (power_distribution_cf2.c of the research
#   forks: each rotor's force turned into PWM through thrust = a pwm^2 + b pwm, a 0.0915 N,
#   b 0.0677 N, pwm in 0-1): read as linear in pwm it would be 1.47 about a 34 g vehicle's
#   hover; a polynomial off by a share of its square term (a battery's sag, other
#   propellers) is a fraction of that either side of 1.
# A square law read against nearly linear rotors is the reverse (0.5). Physical: 0.5-2, the
# two extremes; the fit goes to 0.25-3 so that a value beyond is seen and called implausible.
GAMMA_PHYSICAL = (0.5, 2.0)
GAMMA_FIT = (0.25, 3.0)

REFERENCE: tuple[Candidate, ...] = (
    Candidate("ground_effect", ("rho",), ("1",), (0.01,), (RHO_MAX,), (1.0,), ("ground_effect",)),
    Candidate("ceiling_effect", ("rho",), ("1",), (0.01,), (RHO_MAX,), (1.0,), ("ceiling_effect",)),
    Candidate("wall_effect", ("gain",), ("1",), (-10.0,), (10.0,), (0.5,), ("wall_effect",)),
    Candidate(
        "rotor_drag", ("kxy", "kz"), ("N/((rad/s)(m/s))",) * 2, (0.0,) * 2, (1e-3,) * 2,
        (2.2e-5, 1.0e-5), ("rotor_drag",),
    ),
    Candidate("body_drag", ("drag_coefficient",), ("1",), (0.0,), (5.0,), (1.0,), ("body_drag",)),
    Candidate(
        "wind", ("wx", "wy"), ("m/s",) * 2, (-WIND_MAX_M_S,) * 2, (WIND_MAX_M_S,) * 2,
        (0.5,) * 2, ("wind",),
    ),
    Candidate("motor_lag", ("tau",), ("s",), (0.002,), (0.3,), (0.02,), ("motor_lag",)),
    Candidate("spin_down", ("tau",), ("s",), (0.01,), (5.0,), (0.3,), ("spin_down",)),
    Candidate(
        "thrust_mass", ("c",), ("1",), (-0.5,), (1.0,), (0.05,),
        ("thrust_coefficient", "mass_error"),
    ),
    Candidate(
        "thrust_tilt", ("ax", "ay"), ("deg",) * 2, (-TILT_MAX_DEG,) * 2, (TILT_MAX_DEG,) * 2,
        (0.5,) * 2, ("thrust_tilt",),
    ),
    # typical: 0.1 from the null 1 (a linear model read against e 0.2 at hover 0.4: 1.09)
    Candidate(
        "thrust_curve", ("gamma",), ("1",), (GAMMA_FIT[0],), (GAMMA_FIT[1],), (0.1,),
        ("thrust_curve",), null=(1.0,),
    ),
    Candidate(
        "sensor_bias", ("bx", "by", "bz"), ("m/s^2",) * 3, (-BIAS_MAX_M_S2,) * 3,
        (BIAS_MAX_M_S2,) * 3, (0.1,) * 3, ("sensor_bias",),
    ),
    Candidate(
        "sensor_latency", ("imu_delay",), ("s",), (0.0,), (0.1,), (0.008,), ("sensor_latency",)
    ),
)  # fmt: skip
# What real vehicles show, for the reference vehicle (scaled as the bounds are), with what a
# value beyond it would mean. The fit's bounds are wider, so that a fit outside this range is
# seen and reported as implausible instead of silently held at a bound.
PHYSICAL: dict[str, tuple[tuple[float, ...], tuple[float, ...], str]] = {
    # real multirotors show 6-17% more thrust at 2-3 rotor radii (rho up to 21); a single
    # rotor's Cheeseman-Bennett law is rho 1
    "ground_effect": (
        (0.01,),
        (RHO_MAX,),
        "more thrust near the ground than any measured "
        "multirotor shows (17% at three rotor radii is rho 21)",
    ),
    "ceiling_effect": (
        (0.01,),
        (RHO_MAX,),
        "more thrust under a ceiling than measured rotors show",
    ),
    "wall_effect": (
        (-3.0,),
        (3.0,),
        "a sideways force near a wall of more than 3 times the catalogue's model",
    ),
    # 10% of the weight per m/s at hover: ten times a quadrotor's measured rotor drag; one
    # horizontal coefficient: a symmetric rotor's blade flapping drags alike along x and y
    # (with two, a wind's component along a coefficient near zero is left free)
    "rotor_drag": (
        (0.0,) * 2,
        (1.8e-4,) * 2,
        "a drag of more than 10% of the weight per m/s of air speed",
    ),
    "body_drag": ((0.0,), (2.5,), "a drag coefficient above a flat plate's (about 2)"),
    # horizontal only: a mean vertical wind over a flight is not a site's air (a thermal, a
    # slope) and, through the rotor drag along z, it is a thrust scale by another name
    "wind": ((-WIND_MAX_M_S,) * 2, (WIND_MAX_M_S,) * 2, "air the vehicle could not fly in"),
    # brushed nano motors 20-60 ms (the neural-swarm authors model 57 ms), 12-inch props up
    # to about 0.1 s
    "motor_lag": ((0.002,), (0.15,), "motors slower than any multirotor's (0.15 s to 63%)"),
    # an unbraked rotor halves its speed from hover in I / (k_q n_h): a Crazyflie's 0.3 s, a
    # 12-inch propeller's about 0.8 s (simbridge/effects/actuators.py SpinDownParams)
    "spin_down": (
        (0.02,),
        (2.0,),
        "rotors coasting down slower than any propeller's drag allows (2 s to halve the "
        "speed): a command logged ahead of the motors rather than a rotor",
    ),
    "thrust_mass": (
        (-0.3,),
        (0.3,),
        "a thrust or mass 30% off: the wrong vehicle, or thrust "
        "in the wrong units, rather than an effect",
    ),
    # a frame bent or motors mounted askew, or an IMU mounted off the body's axes: a few
    # degrees is what goes unnoticed on a flying vehicle (a multirotor's motor mounts are
    # level within 1-2 deg; an IMU board's mounting within about 2 deg)
    "thrust_tilt": (
        (-3.0,) * 2,
        (3.0,) * 2,
        "a thrust axis leaning more than 3 deg from the body's z: a frame bent or an IMU "
        "mounted that far askew is seen on the bench; rather a force in the world (wind)",
    ),
    # a thrust curve converted with the wrong law: from a square law read against nearly
    # linear rotors (0.5) to a linear one read against a pure square (2); sources above
    "thrust_curve": (
        (GAMMA_PHYSICAL[0],),
        (GAMMA_PHYSICAL[1],),
        "a thrust curve steeper than a pure square law of the command or flatter than its "
        "square root: thrust in the wrong units or the wrong vehicle rather than an ESC's "
        "curve",
    ),
    # a calibrated MEMS IMU: offsets of 20-70 mg (BMI088 20 mg, MPU-6050 60 mg) before the
    # estimator removes them; 0.1 g is beyond a working accelerometer's
    "sensor_bias": (
        (-1.0,) * 3,
        (1.0,) * 3,
        "an accelerometer offset beyond 0.1 g: a "
        "miscalibrated or misaligned IMU, or a force in the world (wind) read as "
        "a bias",
    ),
    # sensor filters and logging add a few ms; 30 ms is a slow estimator's output
    "sensor_latency": (
        (0.0,),
        (0.03,),
        "an accelerometer more than 30 ms late: a log whose "
        "streams are misaligned in time, or a lag of the motors read as a "
        "sensor delay",
    ),
}
# the fit's search range where it is wider than the catalogue's bounds above: an implausible
# value must be found to be reported
FIT_RANGE: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "ground_effect": ((0.01,), (50.0,)),
    "ceiling_effect": ((0.01,), (50.0,)),
}
REFERENCE = tuple(
    replace(
        c,
        lo=FIT_RANGE.get(c.name, (c.lo, c.hi))[0],
        hi=FIT_RANGE.get(c.name, (c.lo, c.hi))[1],
        plausible_lo=PHYSICAL[c.name][0],
        plausible_hi=PHYSICAL[c.name][1],
        needs_accelerometer=c.name in ("sensor_bias", "sensor_latency"),
    )
    for c in REFERENCE
)


def implausible_parameters(name: str, value: np.ndarray, cat: dict[str, Candidate]) -> list[dict]:
    """The parameters outside the physical range, with what such a value would mean."""
    c = cat[name]
    out = []
    for i, p in enumerate(c.params):
        v = float(value[i])
        if not c.plausible_lo[i] <= v <= c.plausible_hi[i]:
            out.append(
                {"parameter": p, "value": v, "range": [c.plausible_lo[i], c.plausible_hi[i]],
                 "meaning": PHYSICAL[name][2]}
            )  # fmt: skip
    return out


# Names, parameters, units and groups (the same for every vehicle); bounds and magnitudes of
# the reference vehicle: use `catalogue(vehicle)` for those.
CANDIDATES: dict[str, Candidate] = {c.name: c for c in REFERENCE}


def scale_factors(vehicle: Vehicle) -> dict[str, float]:
    """How the catalogue's dimensional magnitudes grow from the reference vehicle to
    `vehicle`, so that the same relative effect sits at the same place in its range: rotor
    drag with weight over hover rotor speed (the same share of the weight per m/s at hover),
    wind with sqrt(weight / frontal area) (the air speed at which body drag is a given share
    of the weight). The rest needs none: rho and the wall gain are relative to the thrust
    with distances in rotor radii, C_d applies to the vehicle's own areas, the thrust-mass
    error is a ratio, a bias is an acceleration (relative to g), lag and latency are times."""
    nano = nano_vehicle()
    area, ref_area = _frontal_area_m2(vehicle.body_size_m), _frontal_area_m2(nano.body_size_m)
    return {
        "rotor_drag": rotor_drag_scale(vehicle),  # as the simulator's default rotor drag
        "wind": math.sqrt((vehicle.weight_n / area) / (nano.weight_n / ref_area)),
    }


def _frontal_area_m2(body_size_m: tuple[float, float, float]) -> float:
    ax, ay, _ = body_areas_m2(body_size_m)
    return 0.5 * (ax + ay)


@functools.lru_cache(maxsize=16)
def catalogue(vehicle: Vehicle) -> dict[str, Candidate]:
    """The candidates with bounds and typical magnitudes for `vehicle` (`scale_factors`);
    the reference vehicle's are the reference values themselves."""
    factors = scale_factors(vehicle)
    out = {}
    for c in REFERENCE:
        f = factors.get(c.name, 1.0)
        if f != 1.0:
            c = replace(
                c,
                lo=tuple(x * f for x in c.lo),
                hi=tuple(x * f for x in c.hi),
                typical=tuple(x * f for x in c.typical),
                plausible_lo=tuple(x * f for x in c.plausible_lo),
                plausible_hi=tuple(x * f for x in c.plausible_hi),
            )
        if c.name == "wind":
            c = replace(
                c,
                lo=tuple(max(x, -SIM_WIND_MAX_M_S) for x in c.lo),
                hi=tuple(min(x, SIM_WIND_MAX_M_S) for x in c.hi),
                plausible_lo=tuple(max(x, -SIM_WIND_MAX_M_S) for x in c.plausible_lo),
                plausible_hi=tuple(min(x, SIM_WIND_MAX_M_S) for x in c.plausible_hi),
            )
        out[c.name] = c
    return out


def nominal_values(effects: EffectSet, vehicle: Vehicle | None = None) -> Values:
    """The nominal world's effects as candidate values (absent effects are left out). With
    `vehicle`, a body drag's C_d is restated on the vehicle's own areas (the candidate's).
    Drag values the world leaves out are the vehicle's defaults (the nano's without one)."""
    effects = effects.for_vehicle(vehicle if vehicle is not None else nano_vehicle())
    out: Values = {}
    if effects.ground_effect:
        out["ground_effect"] = np.array([effects.ground_effect.rho])
    if effects.ceiling_effect:
        out["ceiling_effect"] = np.array([effects.ceiling_effect.rho])
    if effects.wall_effect:
        out["wall_effect"] = np.array([effects.wall_effect.gain])
    if effects.rotor_drag:
        kx, ky, kz = effects.rotor_drag.coefficient_n_s_m
        out["rotor_drag"] = np.array([0.5 * (kx + ky), kz])  # the candidate's symmetric form
    if effects.body_drag:
        cd = effects.body_drag.drag_coefficient
        if vehicle is not None:
            cd *= sum(effects.body_drag.area_m2) / sum(body_areas_m2(vehicle.body_size_m))
        out["body_drag"] = np.array([cd])
    if effects.wind:
        out["wind"] = np.array(effects.wind.mean_m_s[:2])  # the candidate is horizontal
    if effects.motor_lag:
        out["motor_lag"] = np.array([effects.motor_lag.time_constant_s])
    if effects.spin_down:
        out["spin_down"] = np.array([effects.spin_down.time_constant_s])
    if effects.thrust_tilt:
        out["thrust_tilt"] = np.array(effects.thrust_tilt.lean_deg)
    if effects.thrust_curve:
        out["thrust_curve"] = np.array([effects.thrust_curve.gamma])
    s = effects.thrust_coefficient.scale if effects.thrust_coefficient else 1.0
    k = effects.mass_error.scale if effects.mass_error else 1.0
    if s != 1.0 or k != 1.0:
        out["thrust_mass"] = np.array([s / k - 1.0])
    if effects.sensor_bias:
        out["sensor_bias"] = np.array(effects.sensor_bias.accel_bias_m_s2)
    if effects.sensor_latency:
        out["sensor_latency"] = np.array([effects.sensor_latency.imu_delay_s])
    return out


def world_force(values: Values, d: FlightData, vehicle: Vehicle) -> np.ndarray:
    """(N, 3) world-frame force besides gravity that makes m a of the log (see module doc)."""
    f = rotor_forces_n(values, d, vehicle)
    radius = vehicle.rotor_radius_m
    if "ceiling_effect" in values:
        p = CeilingEffectParams(rho=float(values["ceiling_effect"][0]))
        f = f * (1.0 + thrust_gain_array(d.rotor_ceilings_m, p.rho, radius, p.cutoff_for(radius)))
    thrust = f.sum(axis=1)
    force = _thrust_axis(values, d) * thrust[:, None]
    if "ground_effect" in values:
        p = GroundEffectParams(rho=float(values["ground_effect"][0]))
        gain = thrust_gain_array(d.rotor_heights_m, p.rho, radius, p.cutoff_for(radius))
        force[:, 2] += (f * gain).sum(axis=1)
    if "wall_effect" in values:
        wall = WallEffectParams(gain=float(values["wall_effect"][0]))
        force += wall_force_array(wall, thrust, radius, d.wall_distances_m)
    force += _drag(values, d, vehicle)
    if "sensor_latency" in values:
        # the accelerometer reports the body-frame specific force of `delay` ago; the log
        # turns it into the world frame with the current attitude
        delay = float(values["sensor_latency"][0])
        body = np.einsum("nji,nj->ni", d.rotation, force)
        t = d.time_s
        late = np.column_stack([np.interp(t - delay, t, body[:, i]) for i in range(3)])
        force = np.einsum("nij,nj->ni", d.rotation, late)
    if "sensor_bias" in values:
        force += vehicle.mass_kg * np.einsum("nij,j->ni", d.rotation, values["sensor_bias"])
    if not d.measured_acceleration:  # filtered as the log's acceleration was
        force = as_differentiated(force, d)
    return force


def _thrust_axis(values: Values, d: FlightData) -> np.ndarray:
    """(N, 3) the thrust's direction in the world: body z, or the leaning axis."""
    if "thrust_tilt" not in values:
        return d.rotation[:, :, 2]
    ax, ay, az = thrust_axis_body(*(float(a) for a in values["thrust_tilt"]))
    return np.einsum("nij,j->ni", d.rotation, np.array([ax, ay, az]))


def _drag(values: Values, d: FlightData, vehicle: Vehicle) -> np.ndarray:
    if "rotor_drag" not in values and "body_drag" not in values:
        return np.zeros((len(d.time_s), 3))
    wind = np.append(values.get("wind", np.zeros(2))[:2], 0.0)
    v_air = np.einsum("nji,nj->ni", d.rotation, d.velocity_m_s - wind)  # body frame
    comps = (v_air[:, 0], v_air[:, 1], v_air[:, 2])
    body = np.zeros_like(v_air)
    if "rotor_drag" in values:
        k = values["rotor_drag"]
        params = RotorDragParams(coefficient_n_s_m=(float(k[0]), float(k[0]), float(k[1])))
        body += np.column_stack(rotor_drag_n(params, d.commands_rad_s.sum(axis=1), comps))
    if "body_drag" in values:
        params = BodyDragParams(
            drag_coefficient=float(values["body_drag"][0]),
            area_m2=body_areas_m2(vehicle.body_size_m),
        )
        body += np.column_stack(body_drag_n(params, comps))
    return np.einsum("nij,nj->ni", d.rotation, body)


def to_world_effects(values: Values, vehicle: Vehicle | None = None) -> list[dict]:
    """Candidate values as world-YAML effect entries (thrust_mass as a C_T scale: the same
    translational dynamics; body drag with `vehicle`'s areas, which the fit used)."""
    out: list[dict] = []
    for name, v in values.items():
        x = [float(a) for a in v]
        if name in ("ground_effect", "ceiling_effect"):
            out.append({"name": name, "rho": x[0]})
        elif name == "wall_effect":
            out.append({"name": name, "gain": x[0]})
        elif name == "rotor_drag":
            out.append({"name": name, "coefficient_n_s_m": [x[0], x[0], x[1]]})
        elif name == "body_drag":
            entry: dict = {"name": name, "drag_coefficient": x[0]}
            if vehicle is not None:
                entry["area_m2"] = list(body_areas_m2(vehicle.body_size_m))
            out.append(entry)
        elif name == "wind":
            out.append({"name": name, "mean_m_s": [*x[:2], 0.0]})
        elif name in ("motor_lag", "spin_down"):
            out.append({"name": name, "time_constant_s": x[0]})
        elif name == "thrust_mass":
            out.append({"name": "thrust_coefficient", "scale": 1.0 + x[0]})
        elif name == "thrust_tilt":
            out.append({"name": name, "lean_deg": x[:2]})
        elif name == "thrust_curve":
            out.append({"name": name, "gamma": x[0]})
        elif name == "sensor_bias":
            out.append({"name": name, "accel_bias_m_s2": x})
        elif name == "sensor_latency":
            out.append({"name": name, "imu_delay_s": x[0]})
    return out
