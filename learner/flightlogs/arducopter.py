"""ArduCopter's motor outputs in its logs: which outputs are the four motors, the frame, and
the thrust curve that turns a motor's PWM into its share of thrust, for ArduCopter 3.4 on
and for the ArduCopter 3.3 logs still found in public datasets.

ArduCopter 3.4 on (AP_MotorsMulticopter): a = (pwm - MOT_PWM_MIN) / (MOT_PWM_MAX -
MOT_PWM_MIN), r = (a - MOT_SPIN_MIN) / (MOT_SPIN_MAX - MOT_SPIN_MIN) clipped to 0..1, thrust
fraction = (1 - MOT_THST_EXPO) r + MOT_THST_EXPO r^2 (the inverse of its linearisation; the
battery voltage scaling is left out, lift_max = 1), per rotor thrust = weight/4 x fraction /
MOT_THST_HOVER (the learnt hover thrust, in the same units).

ArduCopter 3.3 has no MOT_PWM_*, MOT_SPIN_* or MOT_THST_HOVER: its throttle (0..1000) maps
linearly onto the throttle channel's RC3_MIN..RC3_MAX, and the thrust curve runs from
out_min = RC3_MIN + THR_MIN/1000 (RC3_MAX - RC3_MIN) to RC3_MAX with the curve's top at
MOT_THST_MAX of that span (apply_thrust_curve_and_volt_scaling). That is the curve above with
MOT_SPIN_MIN = s = THR_MIN/1000, MOT_SPIN_MAX = s + MOT_THST_MAX (1 - s), and a hover thrust
of (THR_MID/1000 - s) / (1 - s) (THR_MID: the throttle at hover). ArduCopter 3.4's own
upgrade carries THR_MIN, THR_MID and MOT_THST_MAX over the same way, without the offsets.
ArduCopter 3.2 and before had neither MOT_THST_EXPO nor MOT_THST_MAX: the output linear in
the throttle (expo 0, max 1; its optional piecewise MOT_TCRV_* curve is not modelled).
"""

from __future__ import annotations

import numpy as np

from learner.flightlogs.actuators import ActuatorModel
from learner.flightlogs.resample import AutopilotLog, Stream
from simbridge.config import ConfigError

# ArduCopter's defaults, used where the log has no PARM for them (and said so in the meta)
AC_DEFAULTS = {"MOT_PWM_MIN": 1000.0, "MOT_PWM_MAX": 2000.0, "MOT_SPIN_MIN": 0.15,
               "MOT_SPIN_MAX": 0.95, "MOT_THST_EXPO": 0.65, "MOT_THST_HOVER": 0.35}  # fmt: skip
# ArduCopter 3.3's names for the same facts, and its defaults
AC33_DEFAULTS = {"THR_MIN": 130.0, "THR_MID": 500.0, "MOT_THST_MAX": 0.95, "RC3_MIN": 1100.0,
                 "RC3_MAX": 1900.0, "MOT_THST_EXPO": 0.65}  # fmt: skip
AP_MOTOR_FUNCTION = 33  # SERVOn_FUNCTION: 33 = Motor 1, 34 = Motor 2, ...
AP_FRAME_CLASSES = {2: "hexarotor", 3: "octorotor", 4: "octaquad", 5: "Y6", 6: "helicopter",
                    7: "tricopter", 8: "single copter", 9: "coax copter"}  # fmt: skip
# ArduCopter before 4.0 was built per frame and says which in its start-up text: "Frame: QUAD"
# (3.3), "Frame: QUAD/X" (3.5 on)
AP_FRAME_WORDS = {"HEXA": "hexarotor", "OCTA": "octorotor", "OCTA_QUAD": "octaquad",
                  "Y6": "Y6", "HELI": "helicopter", "TRI": "tricopter", "SINGLE": "single copter",
                  "COAX": "coax copter", "HELI_DUAL": "helicopter"}  # fmt: skip


def is_arducopter_33(params: dict[str, float]) -> bool:
    """A log of ArduCopter 3.3 or earlier: its motor parameters carry the old names."""
    return (
        "MOT_THST_HOVER" not in params
        and "MOT_SPIN_MIN" not in params
        and ("THR_MID" in params or "MOT_THST_MAX" in params)
    )


def curve_parameters(log: AutopilotLog, params: dict[str, float]) -> dict[str, float]:
    """The thrust curve's parameters under ArduCopter 3.4's names, from the log's PARMs
    (ArduCopter 3.3's converted, see the module's text); defaults assumed are noted."""
    if is_arducopter_33(params):
        return _old_curve_parameters(log, params)
    p = {k: params.get(k, d) for k, d in AC_DEFAULTS.items()}
    if p["MOT_PWM_MAX"] <= p["MOT_PWM_MIN"]:  # 0, 0: ArduCopter takes the throttle channel's
        p["MOT_PWM_MIN"] = params.get("RC3_MIN", 1000.0)
        p["MOT_PWM_MAX"] = params.get("RC3_MAX", 2000.0)
    assumed = sorted(k for k in AC_DEFAULTS if k not in params)
    if assumed:
        log.notes.append(f"warning: not in the log, ArduCopter's defaults assumed: {assumed}")
    return p


def _old_curve_parameters(log: AutopilotLog, params: dict[str, float]) -> dict[str, float]:
    """ArduCopter 3.3's parameters, or 3.2's and before (no MOT_THST_EXPO: no thrust curve,
    the output linear in the throttle; their piecewise MOT_TCRV_* curve is not modelled)."""
    old = {k: params.get(k, d) for k, d in AC33_DEFAULTS.items()}
    assumed = sorted(k for k in AC33_DEFAULTS if k not in params)
    version = "3.3"
    if "MOT_THST_EXPO" not in params:
        version = "3.2 or older"
        old["MOT_THST_EXPO"], old["MOT_THST_MAX"] = 0.0, 1.0
        assumed = [k for k in assumed if k not in ("MOT_THST_EXPO", "MOT_THST_MAX")]
        if params.get("MOT_TCRV_ENABLE", 0):
            log.notes.append(
                "warning: ArduCopter 3.2's piecewise throttle curve (MOT_TCRV_*) is enabled in "
                "this log and not modelled: thrust read linear in the PWM above THR_MIN"
            )
    s = old["THR_MIN"] / 1000.0
    p = {
        "MOT_PWM_MIN": old["RC3_MIN"],
        "MOT_PWM_MAX": old["RC3_MAX"],
        "MOT_SPIN_MIN": s,
        "MOT_SPIN_MAX": s + old["MOT_THST_MAX"] * (1.0 - s),
        "MOT_THST_EXPO": old["MOT_THST_EXPO"],
        "MOT_THST_HOVER": (old["THR_MID"] / 1000.0 - s) / (1.0 - s),
    }
    log.notes.append(
        f"ArduCopter {version}'s motor parameters: THR_MIN {old['THR_MIN']:g}, THR_MID "
        f"{old['THR_MID']:g}, MOT_THST_MAX {old['MOT_THST_MAX']:g}, MOT_THST_EXPO "
        f"{old['MOT_THST_EXPO']:g}, RC3 {old['RC3_MIN']:g}..{old['RC3_MAX']:g} read as its output "
        f"stage uses them"
    )
    if assumed:
        log.notes.append(f"warning: not in the log, ArduCopter's defaults assumed: {assumed}")
    if not 0.0 < p["MOT_THST_HOVER"] < 1.0:
        raise ConfigError(
            f"{log.path}: THR_MID {old['THR_MID']:g} at or below THR_MIN {old['THR_MIN']:g}: "
            f"no hover throttle to scale the thrust by (THR_MID must lie in "
            f"{old['THR_MIN']:g}..1000)"
        )
    return p


def arducopter_thrust(
    log: AutopilotLog, pwm: Stream | None, params: dict[str, float]
) -> tuple[Stream | None, ActuatorModel, str]:
    """Each motor's thrust as a fraction of its maximum, from its PWM."""
    p = curve_parameters(log, params)
    expo, hover = p["MOT_THST_EXPO"], p["MOT_THST_HOVER"]
    note = (
        f"RCOU/SERVO_OUTPUT_RAW PWM through ArduCopter's thrust curve: a = (pwm - "
        f"{p['MOT_PWM_MIN']:g}) / ({p['MOT_PWM_MAX']:g} - {p['MOT_PWM_MIN']:g}), r = (a - "
        f"{p['MOT_SPIN_MIN']:g}) / ({p['MOT_SPIN_MAX']:g} - {p['MOT_SPIN_MIN']:g}) in 0..1, "
        f"fraction = {1 - expo:g} r + {expo:g} r^2 (MOT_THST_EXPO; no voltage scaling), per "
        f"rotor weight/4 x fraction / MOT_THST_HOVER {hover:g}"
    )
    model = ActuatorModel("throttle", hover_throttle=hover)
    if pwm is None:
        return None, model, note
    a = (pwm.values - p["MOT_PWM_MIN"]) / (p["MOT_PWM_MAX"] - p["MOT_PWM_MIN"])
    r = np.clip((a - p["MOT_SPIN_MIN"]) / (p["MOT_SPIN_MAX"] - p["MOT_SPIN_MIN"]), 0.0, 1.0)
    return Stream(pwm.t_s, (1.0 - expo) * r + expo * r * r, pwm.source), model, note


def motor_outputs(log: AutopilotLog, params: dict[str, float]) -> list[int]:
    """The outputs of motors 1..4 by SERVOn_FUNCTION 33..36; ArduCopter's default 1..4 for a
    copter whose log has none; a plane without them has no four motors."""
    funcs = {
        int(v): int(k[5:-9]) - 1
        for k, v in params.items()
        if k.startswith("SERVO") and k.endswith("_FUNCTION") and k[5:-9].isdigit()
    }
    motors = [funcs.get(AP_MOTOR_FUNCTION + i) for i in range(4)]
    if None not in motors:
        return [int(c) for c in motors if c is not None]
    if "warning_vehicle" in log.meta:
        found = ", ".join(f"motor {f - 32} on SERVO{c + 1}" for f, c in sorted(funcs.items())
                          if 33 <= f <= 40)  # fmt: skip
        raise ConfigError(
            f"{log.path}: a {log.meta['warning_vehicle']} log without four motor outputs "
            f"(SERVOn_FUNCTION 33..36 for motors 1..4; found: {found or 'none'}): not converted"
        )
    return [0, 1, 2, 3]


def frame_class(log: AutopilotLog, params: dict[str, float], texts: list[str] = ()) -> None:
    """Refuses a vehicle that is not a quadrotor: by FRAME_CLASS (ArduCopter 3.5 on), or by
    the frame its start-up text names (firmware built per frame)."""
    for key in ("FRAME_CLASS", "Q_FRAME_CLASS"):  # a copter's, a quadplane's lift motors
        value = int(params.get(key, 1))
        if value in AP_FRAME_CLASSES:
            raise ConfigError(
                f"{log.path}: a {AP_FRAME_CLASSES[value]} ({key} {value}); the diagnosis "
                f"models a quadrotor's four rotors: not converted"
            )
    for text in texts:
        if text.startswith("Frame: "):
            word = text[len("Frame: ") :].split("/")[0].strip().upper()
            if word in AP_FRAME_WORDS:
                raise ConfigError(
                    f"{log.path}: a {AP_FRAME_WORDS[word]} (its start-up text: '{text}'); the "
                    f"diagnosis models a quadrotor's four rotors: not converted"
                )


def ardupilot_type(log: AutopilotLog, params: dict[str, float], texts: list[str]) -> None:
    frame_class(log, params, texts)
    text = " ".join(texts)
    if "ArduPlane" in text or "Q_ENABLE" in params:
        kind = "VTOL (quadplane)" if params.get("Q_ENABLE", 0) else "fixed-wing"
        log.meta["warning_vehicle"] = kind
        log.notes.append(winged_warning(kind, "ArduPlane"))
        return
    # FRAME_TYPE (3.5 on) and FRAME (before) number the orientations alike: 0 plus, 1 X
    key = "FRAME_TYPE" if "FRAME_TYPE" in params else "FRAME"
    if int(params.get(key, 1)) != 1:
        log.notes.append(f"warning: {key} {int(params[key])} is not X: motors read in X order")


def winged_warning(kind: str, autopilot: str) -> str:
    return (
        f"warning: a {kind} {autopilot} log, not a quadrotor's: its four motors are read as a "
        f"quad X's rotors; wing and control-surface forces are not modelled"
    )
