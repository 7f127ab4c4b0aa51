"""What goes into the corrected world, as a rule on the verdicts: only effects named present,
a group (effects the data cannot tell apart) through the one member that carries its fitted
value, and never a sensor effect: an accelerometer's bias or delay changes what the logs
measure, not how the vehicle moves, so it is removed from the logs' residual and stays out
of the world the simulator flies."""

from __future__ import annotations

from typing import Any

from learner.gap.candidates import CANDIDATES, Values
from simbridge.vehicle import Vehicle


def is_sensor(candidate: str) -> bool:
    """Whether a candidate models the logs' sensors (what is measured) rather than a force."""
    return CANDIDATES[candidate].needs_accelerometer


def _entry(effects: dict[str, dict[str, Any]], candidate: str) -> dict[str, Any]:
    return effects.get(CANDIDATES[candidate].effects[0], {})


def _others(entry: dict[str, Any], candidate: str) -> list[str]:
    own = set(CANDIDATES[candidate].effects)
    return [g for g in entry.get("group", []) if g not in own]


def corrected_members(
    effects: dict[str, dict[str, Any]], chosen: Values, vehicle: Vehicle | None = None
) -> dict[str, Any]:
    """The chosen candidates split into those written into the corrected world (`written`:
    candidate, the world-file entries, why) and those kept out (`kept_out`: candidate, why),
    by the rule of the module's doc. `effects` are the verdicts (`verdicts.effect_report`),
    `chosen` the fitted values of the search's set."""
    written, kept_out = [], []
    for name, value in chosen.items():
        cand = CANDIDATES[name]
        entry = _entry(effects, name)
        status = entry.get("status", "absent")
        group = entry.get("group") or []
        others = _others(entry, name)
        if is_sensor(name):
            why = (
                f"{name} is a property of the logs' sensors (it changes what the accelerometer "
                "measures, not how the vehicle moves): taken out of the logs' residual, never "
                "written as a force"
            )
            if others:
                why += (
                    f"; the data cannot tell it from {', '.join(others)}, and the fit puts "
                    f"the group's value on {name}, so the group is not written"
                )
            kept_out.append({"candidate": name, "effects": list(cand.effects), "why": why})
            continue
        if status not in ("present", "not identifiable") or cand.to_world is None:
            kept_out.append(
                {"candidate": name, "effects": list(cand.effects),
                 "why": f"{name} is {status}: only effects named present are written"}
            )  # fmt: skip
            continue
        entries = cand.to_world([float(v) for v in value], vehicle)
        member = ", ".join(e["name"] for e in entries)
        if status == "present":
            why = f"{member}: named present"
        else:
            why = f"the group {', '.join(group)} goes in as {member} " + _why_member(name, others)
        written.append(
            {"candidate": name, "as": member, "group": list(group), "entries": entries, "why": why}
        )
    return {"written": written, "kept_out": kept_out}


def _why_member(name: str, others: list[str]) -> str:
    """Why one member stands for its group."""
    if name == "thrust_mass":
        reason = "(a C_T scale and a mass error give the same translational dynamics"
    else:
        reason = (
            "(it carries the fitted value: the search chose it, the data fit the others no better"
        )
    sensors = [o for o in others if o in CANDIDATES and is_sensor(o)]
    if sensors:
        reason += f", and {', '.join(sensors)} would be the sensors', never a force"
    return reason + ")"


def world_entries(members: dict[str, Any]) -> list[dict]:
    """The world-file effect entries the corrected world gains (`corrected_members`)."""
    return [e for m in members.get("written", []) for e in m["entries"]]


def world_column(effects: dict[str, dict[str, Any]], members: dict[str, Any]) -> dict[str, str]:
    """Per catalogue effect, the status table's word on the corrected world: written, in
    through another member of its group, or kept out (and why, briefly)."""
    out: dict[str, str] = {}
    for m in members.get("written", []):
        names = [e["name"] for e in m["entries"]]
        for effect in m["group"] or CANDIDATES[m["candidate"]].effects:
            out[effect] = "written" if effect in names else f"in as {m['as']}"
        for effect in names:
            out[effect] = "written"
    for m in members.get("kept_out", []):
        label = "no: the logs' sensors'" if is_sensor(m["candidate"]) else "no"
        group = _entry(effects, m["candidate"]).get("group") or m["effects"]
        for effect in group:
            out.setdefault(
                effect, label if effect in m["effects"] else f"no: {m['candidate']} carries it"
            )
    return out
