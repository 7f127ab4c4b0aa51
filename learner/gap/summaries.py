"""The diagnosis's whole-flight summaries in one call, their rules, and their report.md
section: the constant world-frame force and the trend since take-off (learner/gap/overall.py),
the torque residual per body axis and the thrust error per rotor (learner/gap/rotors.py)."""

from __future__ import annotations

from typing import Any

import numpy as np

from learner.gap.candidates import Values
from learner.gap.flightdata import FlightData
from learner.gap.overall import trend_summary, world_frame_summary
from learner.gap.rotors import rotor_attribution
from simbridge.vehicle import Vehicle


def summaries(
    flights: list[FlightData],
    residuals: list[np.ndarray],
    nominal: Values,
    vehicle: Vehicle,
    seed: int = 0,
) -> dict[str, Any]:
    """JSON-able: `world_frame`, `trend`, `rotors` (with `axes`); each carries its `rule`
    (None below its floor). `residuals` are the force residuals against `nominal`."""
    return {
        "world_frame": world_frame_summary(flights, residuals, vehicle, seed),
        "trend": trend_summary(flights, residuals, vehicle, seed),
        "rotors": rotor_attribution(flights, nominal, vehicle, residuals, seed),
    }


def explain_trend(s: dict[str, Any], left: dict[str, Any]) -> None:
    """Say in the trend's rule when the named effects explain it: what they leave (`left`, a
    trend_summary of the corrected residual) trends by under a tenth as much, or not
    significantly. A flight that ends low over the ground gains its ground effect over time,
    and the two read alike against the nominal world."""
    trend = s["trend"]
    slope, after = trend["slope_share_per_min"], left["slope_share_per_min"]
    trend["after_catalogue_share_per_min"] = after
    if trend.get("rule") and (not left["significant"] or abs(after) <= 0.1 * abs(slope)):
        trend["rule"] += (
            f"; what the effects named leave trends by {after * 100:+.2f}% of the weight per "
            f"minute: they explain {(1.0 - abs(after) / abs(slope)) * 100:.0f}% of it"
        )


def extra_rules(s: dict[str, Any]) -> list[str]:
    """The summaries' rule sentences, those that cleared their floor."""
    return [
        part["rule"]
        for key in ("world_frame", "trend", "rotors")
        if (part := s.get(key)) and part.get("rule")
    ]


def markdown_section(s: dict[str, Any] | None, with_rules: bool = False) -> list[str]:
    """report.md lines: '## Everywhere, over time, per rotor' with a table of each part, and
    the rule sentences first `with_rules` (leave them out when the diagnosis's rules, listed
    under '## Where', already hold extra_rules)."""
    if not s:
        return []
    lines = ["", "## Everywhere, over time, per rotor"]
    if with_rules:
        lines += [""] + ([f"- {r}" for r in extra_rules(s)] or ["- none above its floor"])
    if s["rotors"].get("why"):
        lines += ["", f"- per rotor: {s['rotors']['why']}"]
    w = s["world_frame"]
    lines += [
        "",
        "| flight | constant horizontal force (N) | share of the weight | towards (deg) |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {f['flight']} | {f['size_n']:.3g} | {f['share'] * 100:.1f}% | "
        f"{f['direction_deg']:.0f} |"
        for f in w["flights"]
    ]
    t = s["trend"]
    lo, hi = t["ci95_share_per_min"]
    lines += [
        "",
        f"- vertical residual against time since take-off: {t['slope_share_per_min'] * 100:+.2f}% "
        f"of the weight per minute (95% CI {lo * 100:+.2f} to {hi * 100:+.2f}%; floor "
        f"{t['floor_share_per_min'] * 100:.2f}%)",
    ]
    r = s["rotors"]
    lines += ["", "| rotor | thrust error | 95% CI | significant |", "|---|---|---|---|"]
    lines += [
        f"| {x['rotor']} ({x['position']}) | {x['thrust_error'] * 100:+.1f}% | "
        f"{x['ci95'][0] * 100:+.1f} to {x['ci95'][1] * 100:+.1f}% | "
        f"{'yes' if x['significant'] else 'no'} |"
        for x in r["rotors"]
    ]
    lines += ["", "| body axis | torque residual (N m) | of one rotor's moment | significant |"]
    lines += ["|---|---|---|---|"]
    lines += [
        f"| {a['axis']} | {a['mean_n_m']:.3g} ({a['ci95_n_m'][0]:.3g} to "
        f"{a['ci95_n_m'][1]:.3g}) | {a['share'] * 100:+.1f}% | "
        f"{'yes' if a['significant'] else 'no'} |"
        for a in r["axes"]
    ]
    return lines
