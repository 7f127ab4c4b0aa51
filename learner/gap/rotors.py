"""The torque residual per body axis, and per rotor: which rotor delivers less (or more)
thrust than its command says.

Under closed-loop control a weak rotor hardly shows in the motion: the attitude loop spins it
faster until the moments balance. What it leaves is a commanded-speed asymmetry, and so a
torque residual tau = I w' + w x I w - M(modelled rotor forces), exactly the moment the weak
rotor's missing thrust would have given at its command. With the body-z force residual
(the thrust the commands do not explain) that is four equations in the four rotor thrust
errors delta_f_i = f_i(real) - f_i(model): the mixer (thesis equation 3.6,
`simbridge.rotors.thrust_and_moments`) inverted, per sample. Each rotor's error is then the
sum of its delta_f over the sum of its modelled thrust (-0.15: 15% less than modelled), with
a bootstrap interval over flights or blocks of flight (learner/gap/floor.py), a Holm test
over the four rotors and the noise floor.

A centre-of-mass offset gives the same moments as a front/back or left/right pair of rotors
off by opposite amounts, a thrust-coefficient or mass error (or an outside force along the
body z) all four off alike, tilted motors or unlike propellers the yaw pair: the errors are
split into these four patterns (PATTERNS), and the rule names the pattern when one explains
them alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from learner.gap.candidates import Values
from learner.gap.flightdata import FlightData
from learner.gap.floor import (
    K_SE,
    RESAMPLES,
    bootstrap_units,
    ci95,
    noise_level,
    noise_se,
    se_of,
    unit_sums,
)
from learner.gap.rotor_forces import rotor_forces_n
from learner.gap.stats import bootstrap_mean, bootstrap_p, holm
from learner.gap.torque import torque_residual_n_m
from simbridge.rotors import thrust_and_moments
from simbridge.vehicle import Vehicle

ALPHA = 0.05
MIN_ROTOR_ERROR = 0.01  # absolute floor: a rotor 1% off its model is not worth naming
ROTOR_NAMES = ("front-left", "back-left", "back-right", "front-right")  # simbridge/rotors.py
AXES = ("x", "y", "z")
# The rotors' errors split exactly into four patterns, one per row of the mixer: all alike
# (thrust), left against right (M_x), back against front (M_y), the yaw pair 1, 3 against
# 0, 2 (M_z). One rotor off by e puts e / 4 into each; a centre-of-mass offset, tilted motors
# or unlike propellers put nearly everything into one.
PATTERNS = np.array(
    [[1.0, 1.0, 1.0, 1.0], [1.0, 1.0, -1.0, -1.0], [-1.0, 1.0, 1.0, -1.0], [-1.0, 1.0, -1.0, 1.0]]
).T  # (rotor, pattern)
PATTERN_NAMES = ("collective", "roll", "pitch", "yaw")
PATTERN_WORDS = {
    "collective": "all four rotors alike: a thrust-coefficient or mass error, or an outside "
    "force along the body z (a tilt turns a horizontal force into one)",
    "roll": "left against right rotors: a centre-of-mass offset sideways, or a roll trim",
    "pitch": "front against back rotors: a centre-of-mass offset fore or aft, or a pitch trim",
    "yaw": "rotors 0 and 2 against 1 and 3: a yaw moment the rotors' drag-torque model lacks "
    "(tilted motors, unlike propellers, the yaw moment coefficient)",
}
DOMINANT = 2.0  # a pattern this many times any other's size explains the errors alone


def mixer(vehicle: Vehicle) -> np.ndarray:
    """(4, 4) matrix from rotor forces to (thrust, M_x, M_y, M_z): equation 3.6's columns."""
    eye = np.eye(4)
    return np.column_stack(
        [
            thrust_and_moments(tuple(eye[i]), vehicle.arm_m, vehicle.yaw_moment_coefficient_m)
            for i in range(4)
        ]
    )


def reference_moments_n_m(vehicle: Vehicle) -> np.ndarray:
    """What one rotor's hover thrust gives about each body axis: a torque residual's scale
    (a share of 0.15 about x and y is about one rotor 15% off)."""
    quarter = vehicle.weight_n / 4.0
    arm, k_z = vehicle.arm_m, vehicle.yaw_moment_coefficient_m
    return np.array([arm * quarter, arm * quarter, k_z * quarter])


def thrust_errors_n(
    d: FlightData, values: Values, vehicle: Vehicle, force_residual: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample: the rotor thrust errors delta_f (N, 4) that explain the body-z force
    residual and the torque residual, the modelled rotor forces (N, 4), and the torque
    residual (N, 3), all against `values` (the nominal world's)."""
    torque = torque_residual_n_m(d, values, vehicle)
    body_z = np.einsum("nj,nj->n", d.rotation[:, :, 2], force_residual)  # (R^T r)_z
    wrench = np.column_stack([body_z, torque])
    delta = np.linalg.solve(mixer(vehicle), wrench.T).T
    return delta, rotor_forces_n(values, d, vehicle), torque


def axis_summary(
    flights: list[FlightData], torques: list[np.ndarray], vehicle: Vehicle, rng: np.random.Generator
) -> list[dict[str, Any]]:
    """Per body axis: the mean torque residual (N m), its 95% interval, its share of one
    rotor's hover moment, and whether it clears the test and the noise floor."""
    units = bootstrap_units(flights)
    sums, counts = unit_sums(torques, units)
    rows = counts.sum()
    sd, ess = noise_level(torques, flights)
    ref = reference_moments_n_m(vehicle)
    out = []
    for j, axis in enumerate(AXES):
        draws = bootstrap_mean(sums[:, :, j], counts, RESAMPLES, rng)[:, 0]
        mean = float(sums[:, 0, j].sum() / rows)
        p = float(bootstrap_p(draws[:, None])[0])
        floor = max(K_SE * se_of(draws), K_SE * float(noise_se(sd[j], rows, ess)))
        lo, hi = ci95(draws)
        out.append({
            "axis": axis, "mean_n_m": mean, "ci95_n_m": [lo, hi], "share": float(mean / ref[j]),
            "p": p, "significant": bool(p < ALPHA and abs(mean) >= floor and not lo <= 0 <= hi),
        })  # fmt: skip
    return out


def rotor_attribution(
    flights: list[FlightData],
    values: Values,
    vehicle: Vehicle,
    force_residuals: list[np.ndarray],
    seed: int = 0,
) -> dict[str, Any]:
    """Each rotor's thrust error as a share of its modelled thrust, with a 95% interval and a
    significance flag (`rotors`), the per-axis torque summary (`axes`) and a rule."""
    rng = np.random.default_rng(seed)
    parts = [
        thrust_errors_n(d, values, vehicle, r)
        for d, r in zip(flights, force_residuals, strict=True)
    ]
    deltas = [p[0] for p in parts]
    forces = [p[1] for p in parts]
    units = bootstrap_units(flights)
    sum_delta, counts = unit_sums(deltas, units)
    sum_force, _ = unit_sums(forces, units)
    rows = counts.sum()
    sd, ess = noise_level(deltas, flights)
    mean_force = sum_force[:, 0, :].sum(axis=0) / rows
    draws = np.column_stack(
        [
            bootstrap_mean(sum_delta[:, :, i], sum_force[:, :, i], RESAMPLES, rng)[:, 0]
            for i in range(4)
        ]
    )
    p = holm(bootstrap_p(draws))
    errors = sum_delta[:, 0, :].sum(axis=0) / sum_force[:, 0, :].sum(axis=0)
    se_noise = noise_se(sd, rows, ess) / np.maximum(mean_force, 1e-12)
    rotors = []
    for i in range(4):
        lo, hi = ci95(draws[:, i])
        floor = max(K_SE * se_of(draws[:, i]), K_SE * float(se_noise[i]), MIN_ROTOR_ERROR)
        rotors.append({
            "rotor": i, "position": ROTOR_NAMES[i], "thrust_error": float(errors[i]),
            "ci95": [lo, hi], "p_holm": float(p[i]),
            "significant": bool(p[i] < ALPHA and abs(errors[i]) >= floor and not lo <= 0 <= hi),
        })  # fmt: skip
    coefs = errors @ PATTERNS / 4.0
    coef_draws = draws @ PATTERNS / 4.0
    patterns = {}
    for k, name in enumerate(PATTERN_NAMES):
        lo, hi = ci95(coef_draws[:, k])
        patterns[name] = {
            "share": float(coefs[k]),
            "ci95": [lo, hi],
            "significant": not lo <= 0 <= hi,
        }
    out: dict[str, Any] = {
        "rotors": rotors,
        "patterns": patterns,
        "axes": axis_summary(flights, [q[2] for q in parts], vehicle, rng),
        "per_rotor_logged": per_rotor_logged(flights),
    }
    if not out["per_rotor_logged"]:
        # one collective command: the moments the rotors gave are not in the log, so the
        # torque residual is the whole I w' and only the collective pattern means anything
        out["why"] = NO_PER_ROTOR
        for r in rotors:
            r["significant"] = False
        for name in PATTERN_NAMES[1:]:
            patterns[name]["significant"] = False
        c = patterns["collective"]
        lo, hi = c["ci95"]
        out["rule"] = (
            f"all four rotors alike: {c['share'] * 100:+.1f}% thrust against the model (95% CI "
            f"{lo * 100:+.1f} to {hi * 100:+.1f}%; {PATTERN_WORDS['collective']}); {NO_PER_ROTOR}"
            if c["significant"] and abs(c["share"]) >= MIN_ROTOR_ERROR
            else None
        )
    else:
        out["rule"] = rotor_rule(rotors, patterns)
    return out


NO_PER_ROTOR = "the logs carry one collective rotor command, so no single rotor can be told"


def per_rotor_logged(flights: list[FlightData]) -> bool:
    """Whether any log's rotor commands differ between rotors (Neural-Fly's carry only the
    collective thrust, spread evenly)."""
    for d in flights:
        n = d.commands_rad_s
        spread = np.max(np.abs(n - n.mean(axis=1, keepdims=True)))
        if spread > 1e-6 * max(float(np.max(np.abs(n))), 1e-12):
            return True
    return False


def _pct(x: float) -> str:
    return f"{abs(x) * 100:.0f}% {'less' if x < 0 else 'more'}"


def rotor_rule(
    rotors: list[dict[str, Any]], patterns: dict[str, dict[str, Any]] | None = None
) -> str | None:
    """'rotor 2 (back-right) delivers 15% less thrust than modelled (95% CI ...); the others
    within +-2%', or what one pattern of the errors says when it explains them alone, or
    None when no rotor clears its floor."""
    sig = [r for r in rotors if r["significant"]]
    if not sig:
        return None
    e = np.array([r["thrust_error"] for r in rotors])
    if patterns:
        sizes = {k: abs(v["share"]) for k, v in patterns.items()}
        top = max(sizes, key=sizes.__getitem__)
        rest = max(v for k, v in sizes.items() if k != top)
        if patterns[top]["significant"] and sizes[top] >= DOMINANT * rest:
            lo, hi = patterns[top]["ci95"]
            return (
                f"the rotors' thrust errors ({', '.join(f'{x * 100:+.0f}%' for x in e)}) follow "
                f"one pattern, {PATTERN_WORDS[top]}: {patterns[top]['share'] * 100:+.1f}% "
                f"(95% CI {lo * 100:+.1f} to {hi * 100:+.1f}%), rather than one rotor"
            )
    parts = []
    for r in sorted(sig, key=lambda r: -abs(r["thrust_error"])):
        lo, hi = r["ci95"]
        parts.append(
            f"rotor {r['rotor']} ({r['position']}) delivers {_pct(r['thrust_error'])} thrust "
            f"than modelled (95% CI {lo * 100:+.0f} to {hi * 100:+.0f}%)"
        )
    text = "; ".join(parts)
    others = [r["thrust_error"] for r in rotors if not r["significant"]]
    if others:
        text += f"; the others within +-{max(abs(x) for x in others) * 100:.0f}%"
    return text
