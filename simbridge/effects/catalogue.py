"""The declared effects, in the order the world loader lists them and the diagnosis tries
their candidates: each effect once, with its parameters, its candidate's bounds (for the
reference vehicle, the thesis's nano: `Candidate.scale` restates them for another vehicle),
what real vehicles show and how a world's effect and a fit's values convert.

The forces of the effects below are computed by the physics step (simbridge/physics.py,
simbridge/rotor_dynamics.py) and the diagnosis's world model (learner/gap/candidates.py),
which share rays, rotor heights and rotor dynamics between them; a new effect declares its
force here instead (`Effect.force`, `Candidate.log_force`): see
docs/where-a-change-goes.md.
"""

from __future__ import annotations

import math
from typing import Any

from simbridge.effects.actuators import (
    MassErrorParams,
    MotorLagParams,
    SpinDownParams,
    ThrustCoefficientParams,
    ThrustCurveParams,
    ThrustTiltParams,
)
from simbridge.effects.drag import BodyDragParams, RotorDragParams, WindParams, body_areas_m2
from simbridge.effects.drag import rotor_drag_scale as _rotor_drag_scale
from simbridge.effects.ground import CeilingEffectParams, GroundEffectParams
from simbridge.effects.learned import LearnedResidualParams
from simbridge.effects.proximity import WallEffectParams
from simbridge.effects.registry import Candidate, Effect, register
from simbridge.effects.sensor_errors import SensorBiasParams, SensorLatencyParams
from simbridge.effects.uncatalogued import (
    GroundEffectExponentialParams,
    GroundOutwashParams,
    RotorAsymmetryParams,
    ThrustDecayParams,
)
from simbridge.vehicle import nano_vehicle

# A fitted rho of 21 gives 17% more thrust at three rotor radii, the most real Crazyflies
# show (6-17% at 2-3 radii); 25 leaves room above it without reaching the simulator's 50.
RHO_MAX = 25.0
# The fit's range of rho, wider than the physical one: an implausible value must be found to
# be reported
RHO_FIT_MAX = 50.0
# Half of g: a larger bias is gravity left in the accelerometer, which the residual's
# plausibility check (learner/gap/plausibility.py) stops before any fit.
BIAS_MAX_M_S2 = 5.0
# Wind the reference vehicle could still be flown in (a nano quadrotor's drag at 20 m/s is
# about its weight); the Neural-Fly tunnel blew 12 m/s. Scaled with the vehicle, and never
# past the simulator's own range (simbridge/effects/drag.py: +-30 m/s).
WIND_MAX_M_S = 20.0
SIM_WIND_MAX_M_S = 30.0
# The fit's range of a thrust axis's lean, well past the physical 3 deg, so that a steady
# force read as a lean is seen at its value and called implausible
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


def _frontal_area_m2(body_size_m: tuple[float, float, float]) -> float:
    ax, ay, _ = body_areas_m2(body_size_m)
    return 0.5 * (ax + ay)


def _wind_scale(vehicle: Any) -> float:
    """The air speed at which body drag is a given share of the weight: sqrt(weight /
    frontal area), relative to the reference vehicle's."""
    nano = nano_vehicle()
    area, ref_area = _frontal_area_m2(vehicle.body_size_m), _frontal_area_m2(nano.body_size_m)
    return math.sqrt((vehicle.weight_n / area) / (nano.weight_n / ref_area))


def _one(name: str, field: str) -> Any:
    """A world's effect as the candidate's one parameter, its `field`."""

    def nominal(fx: Any, _vehicle: Any) -> list[float] | None:
        p = getattr(fx, name)
        return None if p is None else [getattr(p, field)]

    return nominal


def _body_drag_nominal(fx: Any, vehicle: Any) -> list[float] | None:
    """C_d restated on the vehicle's own areas (the candidate's), with a vehicle."""
    if fx.body_drag is None:
        return None
    cd = fx.body_drag.drag_coefficient
    if vehicle is not None:
        cd *= sum(fx.body_drag.area_m2) / sum(body_areas_m2(vehicle.body_size_m))
    return [cd]


def _body_drag_world(x: list[float], vehicle: Any) -> list[dict]:
    entry: dict = {"name": "body_drag", "drag_coefficient": x[0]}
    if vehicle is not None:  # the areas the fit used
        entry["area_m2"] = list(body_areas_m2(vehicle.body_size_m))
    return [entry]


def _thrust_mass_nominal(fx: Any, _vehicle: Any) -> list[float] | None:
    s = fx.thrust_coefficient.scale if fx.thrust_coefficient else 1.0
    k = fx.mass_error.scale if fx.mass_error else 1.0
    return [s / k - 1.0] if s != 1.0 or k != 1.0 else None


GROUND_EFFECT = Effect(
    "ground_effect",
    GroundEffectParams,
    "thesis equation 3.4 at each rotor, over the surface below it",
    candidate=Candidate(
        "ground_effect", ("rho",), ("1",), (0.01,), (RHO_FIT_MAX,), (1.0,), ("ground_effect",),
        # real multirotors show 6-17% more thrust at 2-3 rotor radii (rho up to 21); a
        # single rotor's Cheeseman-Bennett law is rho 1
        (0.01,), (RHO_MAX,),
        "more thrust near the ground than any measured multirotor shows (17% at three rotor "
        "radii is rho 21)",
        # the cut-off height steps with rho (thesis section 3.3.1: 2 to 3 cm at rho 2.9 on
        # the nano), a wall a fit started below it does not cross
        multi_start=(1.0, 4.0, 12.0), walled=True,
        nominal=_one("ground_effect", "rho"),
        to_world=lambda x, _v: [{"name": "ground_effect", "rho": x[0]}],
    ),
)  # fmt: skip
CEILING_EFFECT = Effect(
    "ceiling_effect",
    CeilingEffectParams,
    "the ground effect's law with the distance to a ceiling, a thrust gain",
    candidate=Candidate(
        "ceiling_effect", ("rho",), ("1",), (0.01,), (RHO_FIT_MAX,), (1.0,), ("ceiling_effect",),
        (0.01,), (RHO_MAX,), "more thrust under a ceiling than measured rotors show",
        multi_start=(1.0, 4.0, 12.0), walled=True,
        nominal=_one("ceiling_effect", "rho"),
        to_world=lambda x, _v: [{"name": "ceiling_effect", "rho": x[0]}],
    ),
)  # fmt: skip
WALL_EFFECT = Effect(
    "wall_effect",
    WallEffectParams,
    "a lateral force decaying with the distance to a wall",
    candidate=Candidate(
        "wall_effect", ("gain",), ("1",), (-10.0,), (10.0,), (0.5,), ("wall_effect",),
        (-3.0,), (3.0,), "a sideways force near a wall of more than 3 times the catalogue's model",
        start=(0.0,),
        nominal=_one("wall_effect", "gain"),
        to_world=lambda x, _v: [{"name": "wall_effect", "gain": x[0]}],
    ),
)  # fmt: skip
ROTOR_DRAG = Effect(
    "rotor_drag",
    RotorDragParams,
    "f = -k_d (sum of rotor speeds) v_air, per body axis",
    candidate=Candidate(
        "rotor_drag", ("kxy", "kz"), ("N/((rad/s)(m/s))",) * 2, (0.0,) * 2, (1e-3,) * 2,
        (2.2e-5, 1.0e-5), ("rotor_drag",),
        # 10% of the weight per m/s at hover: ten times a quadrotor's measured rotor drag;
        # one horizontal coefficient: a symmetric rotor's blade flapping drags alike along x
        # and y (with two, a wind's component along a coefficient near zero is left free)
        (0.0,) * 2, (1.8e-4,) * 2, "a drag of more than 10% of the weight per m/s of air speed",
        # as the simulator's default rotor drag: the same share of the weight per m/s at hover
        scale=_rotor_drag_scale,
        nominal=lambda fx, _v: None if fx.rotor_drag is None else [
            0.5 * (fx.rotor_drag.coefficient_n_s_m[0] + fx.rotor_drag.coefficient_n_s_m[1]),
            fx.rotor_drag.coefficient_n_s_m[2],
        ],
        to_world=lambda x, _v: [{"name": "rotor_drag", "coefficient_n_s_m": [x[0], x[0], x[1]]}],
    ),
)  # fmt: skip
BODY_DRAG = Effect(
    "body_drag",
    BodyDragParams,
    "f = -0.5 rho_air C_d A |v_air| v_air",
    candidate=Candidate(
        "body_drag", ("drag_coefficient",), ("1",), (0.0,), (5.0,), (1.0,), ("body_drag",),
        (0.0,), (2.5,), "a drag coefficient above a flat plate's (about 2)",
        nominal=_body_drag_nominal, to_world=_body_drag_world,
    ),
)  # fmt: skip
WIND = Effect(
    "wind",
    WindParams,
    "a constant or gusting wind field; drag acts on the air-relative velocity",
    candidate=Candidate(
        "wind", ("wx", "wy"), ("m/s",) * 2, (-WIND_MAX_M_S,) * 2, (WIND_MAX_M_S,) * 2,
        (0.5,) * 2, ("wind",),
        # horizontal only: a mean vertical wind over a flight is not a site's air (a
        # thermal, a slope) and, through the rotor drag along z, it is a thrust scale by
        # another name
        (-WIND_MAX_M_S,) * 2, (WIND_MAX_M_S,) * 2, "air the vehicle could not fly in",
        start=(0.0, 0.0), scale=_wind_scale,
        nominal=lambda fx, _v: None if fx.wind is None else list(fx.wind.mean_m_s[:2]),
        to_world=lambda x, _v: [{"name": "wind", "mean_m_s": [*x[:2], 0.0]}],
    ),
)  # fmt: skip
MOTOR_LAG = Effect(
    "motor_lag",
    MotorLagParams,
    "n' = (n_cmd - n) / tau",
    candidate=Candidate(
        "motor_lag", ("tau",), ("s",), (0.002,), (0.3,), (0.02,), ("motor_lag",),
        # brushed nano motors 20-60 ms (the neural-swarm authors model 57 ms), 12-inch props
        # up to about 0.1 s
        (0.002,), (0.15,), "motors slower than any multirotor's (0.15 s to 63%)",
        # a lag's residual has local minima a period apart
        multi_start=(0.02, 0.08), history=True,
        nominal=_one("motor_lag", "time_constant_s"),
        to_world=lambda x, _v: [{"name": "motor_lag", "time_constant_s": x[0]}],
    ),
)  # fmt: skip
SPIN_DOWN = Effect(
    "spin_down",
    SpinDownParams,
    "unbraked rotors coasting down on their drag",
    candidate=Candidate(
        "spin_down", ("tau",), ("s",), (0.01,), (5.0,), (0.3,), ("spin_down",),
        # an unbraked rotor halves its speed from hover in I / (k_q n_h): a Crazyflie's
        # 0.3 s, a 12-inch propeller's about 0.8 s (SpinDownParams)
        (0.02,), (2.0,),
        "rotors coasting down slower than any propeller's drag allows (2 s to halve the "
        "speed): a command logged ahead of the motors rather than a rotor",
        history=True,
        nominal=_one("spin_down", "time_constant_s"),
        to_world=lambda x, _v: [{"name": "spin_down", "time_constant_s": x[0]}],
    ),
)  # fmt: skip
# Mass and thrust-coefficient errors scale the residual identically (m a = s T + ... and
# k m a = T + ...), so they are one candidate, `thrust_mass`, with c = s / k - 1, written
# back as a C_T scale (the same translational dynamics).
THRUST_COEFFICIENT = Effect(
    "thrust_coefficient",
    ThrustCoefficientParams,
    "C_T scaled by a factor (battery sag, wrong propeller)",
    candidate=Candidate(
        "thrust_mass", ("c",), ("1",), (-0.5,), (1.0,), (0.05,),
        ("thrust_coefficient", "mass_error"),
        (-0.3,), (0.3,),
        "a thrust or mass 30% off: the wrong vehicle, or thrust in the wrong units, rather "
        "than an effect",
        start=(0.0,), nominal=_thrust_mass_nominal,
        to_world=lambda x, _v: [{"name": "thrust_coefficient", "scale": 1.0 + x[0]}],
    ),
)  # fmt: skip
MASS_ERROR = Effect(
    "mass_error", MassErrorParams, "the true mass differs from the vehicle file's (thrust_mass)"
)
THRUST_TILT = Effect(
    "thrust_tilt",
    ThrustTiltParams,
    "the rotors' thrust axis leaning from body z",
    candidate=Candidate(
        "thrust_tilt", ("ax", "ay"), ("deg",) * 2, (-TILT_MAX_DEG,) * 2, (TILT_MAX_DEG,) * 2,
        (0.5,) * 2, ("thrust_tilt",),
        # a frame bent or motors mounted askew, or an IMU mounted off the body's axes: a few
        # degrees is what goes unnoticed on a flying vehicle (a multirotor's motor mounts are
        # level within 1-2 deg; an IMU board's mounting within about 2 deg)
        (-3.0,) * 2, (3.0,) * 2,
        "a thrust axis leaning more than 3 deg from the body's z: a frame bent or an IMU "
        "mounted that far askew is seen on the bench; rather a force in the world (wind)",
        start=(0.0, 0.0),
        nominal=lambda fx, _v: None if fx.thrust_tilt is None else list(fx.thrust_tilt.lean_deg),
        to_world=lambda x, _v: [{"name": "thrust_tilt", "lean_deg": x[:2]}],
    ),
)  # fmt: skip
THRUST_CURVE = Effect(
    "thrust_curve",
    ThrustCurveParams,
    "the rotors' thrust as a power law about hover",
    candidate=Candidate(
        # typical: 0.1 from the null 1 (a linear model read against e 0.2 at hover 0.4: 1.09)
        "thrust_curve", ("gamma",), ("1",), (GAMMA_FIT[0],), (GAMMA_FIT[1],), (0.1,),
        ("thrust_curve",),
        # a thrust curve converted with the wrong law: from a square law read against nearly
        # linear rotors (0.5) to a linear one read against a pure square (2); sources above
        (GAMMA_PHYSICAL[0],), (GAMMA_PHYSICAL[1],),
        "a thrust curve steeper than a pure square law of the command or flatter than its "
        "square root: thrust in the wrong units or the wrong vehicle rather than an ESC's "
        "curve",
        null=(1.0,),
        nominal=_one("thrust_curve", "gamma"),
        to_world=lambda x, _v: [{"name": "thrust_curve", "gamma": x[0]}],
    ),
)  # fmt: skip
SENSOR_BIAS = Effect(
    "sensor_bias",
    SensorBiasParams,
    "biased accelerometer, gyro and position",
    candidate=Candidate(
        "sensor_bias", ("bx", "by", "bz"), ("m/s^2",) * 3, (-BIAS_MAX_M_S2,) * 3,
        (BIAS_MAX_M_S2,) * 3, (0.1,) * 3, ("sensor_bias",),
        # a calibrated MEMS IMU: offsets of 20-70 mg (BMI088 20 mg, MPU-6050 60 mg) before
        # the estimator removes them; 0.1 g is beyond a working accelerometer's
        (-1.0,) * 3, (1.0,) * 3,
        "an accelerometer offset beyond 0.1 g: a miscalibrated or misaligned IMU, or a force "
        "in the world (wind) read as a bias",
        needs_accelerometer=True, start=(0.0, 0.0, 0.0),
        nominal=lambda fx, _v: (
            None if fx.sensor_bias is None else list(fx.sensor_bias.accel_bias_m_s2)
        ),
        to_world=lambda x, _v: [{"name": "sensor_bias", "accel_bias_m_s2": x}],
    ),
)  # fmt: skip
SENSOR_LATENCY = Effect(
    "sensor_latency",
    SensorLatencyParams,
    "a delayed IMU and state",
    candidate=Candidate(
        "sensor_latency", ("imu_delay",), ("s",), (0.0,), (0.1,), (0.008,), ("sensor_latency",),
        # sensor filters and logging add a few ms; 30 ms is a slow estimator's output
        (0.0,), (0.03,),
        "an accelerometer more than 30 ms late: a log whose streams are misaligned in time, "
        "or a lag of the motors read as a sensor delay",
        # a delay's residual has local minima a period apart
        needs_accelerometer=True, start=(0.004,), multi_start=(0.004, 0.02), history=True,
        nominal=_one("sensor_latency", "imu_delay_s"),
        to_world=lambda x, _v: [{"name": "sensor_latency", "imu_delay_s": x[0]}],
    ),
)  # fmt: skip
LEARNED_RESIDUAL = Effect(
    "learned_residual", LearnedResidualParams, "the residual force a gap diagnosis learnt"
)
# outside the diagnosis's catalogue: the gap bench's tests of what the diagnosis cannot name
# (simbridge/effects/uncatalogued.py)
UNCATALOGUED_EFFECTS = (
    Effect("ground_effect_exponential", GroundEffectExponentialParams, catalogued=False),
    Effect("thrust_decay", ThrustDecayParams, catalogued=False),
    Effect("rotor_asymmetry", RotorAsymmetryParams, catalogued=False),
    Effect("ground_outwash", GroundOutwashParams, catalogued=False),
)

# The world loader's order; the diagnosis tries the candidates in this order too, except
# that the accelerometer's bias comes before its latency.
for _effect in (
    GROUND_EFFECT, CEILING_EFFECT, WALL_EFFECT, ROTOR_DRAG, BODY_DRAG, WIND, MOTOR_LAG,
    SPIN_DOWN, THRUST_COEFFICIENT, MASS_ERROR, THRUST_TILT, THRUST_CURVE, SENSOR_LATENCY,
):  # fmt: skip
    register(_effect)
register(SENSOR_BIAS, candidate_after="thrust_curve")
register(LEARNED_RESIDUAL)
for _effect in UNCATALOGUED_EFFECTS:
    register(_effect)

# Effects declared in modules of their own register themselves when imported: one import
# each below (docs/where-a-change-goes.md).
