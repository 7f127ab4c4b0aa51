"""The gap bench's verdict on an effect outside the catalogue: the diagnosis cannot
name it, so it is scored on what it says about it instead:

- located: the unexplained residual is placed in the expected regime (an entry of
  `unexplained.where` with the expected variable and component, its bin starting below a
  bound; for the time since take-off, also a significant falling trend in the whole-flight
  summaries), or, for a weak rotor, a significant negative thrust error on that rotor (a
  positive one for a rotor stronger than modelled), or, for a torque, a significant pattern
  of the rotors' errors (the yaw pair against the other);
- no catalogue effect declared present with confidence (`confident`, true when absent);
- the unexplained share reported (a number);
- the learnt residual shrinks the held-out force gap by at least LEARNED_SHRINK_MIN (a
  torque-only effect, located by its pattern of rotor errors, leaves no force to learn).

The diagnosis result is read defensively: a field it does not (yet) carry reads "missing"
(None), and a case with a missing figure does not pass.
"""

from __future__ import annotations

import math
from typing import Any

LEARNED_SHRINK_MIN = 0.6


def _rotors(result: dict[str, Any]) -> list[dict[str, Any]] | None:
    """The per-rotor attribution, at the top level or under the whole-flight summaries."""
    rotors = result.get("rotors")
    if isinstance(rotors, dict):
        rotors = rotors.get("rotors")
    if rotors is None:
        rotors = ((result.get("summaries") or {}).get("rotors") or {}).get("rotors")
    return rotors if isinstance(rotors, list) else None


def _falling(result: dict[str, Any]) -> bool:
    """The diagnosis's trend summary: the vertical residual falls significantly over time."""
    trend = (result.get("summaries") or {}).get("trend") or {}
    return bool(trend.get("significant")) and trend.get("slope_share_per_min", 0.0) < 0


def located(expected: tuple[Any, ...], result: dict[str, Any]) -> bool | None:
    """Whether the diagnosis places the residual where the effect acts; None: not reported."""
    if not expected:
        return None
    if expected[0] == "pattern":  # a pattern of the rotors' errors: a torque, named
        patterns = ((result.get("summaries") or {}).get("rotors") or {}).get("patterns")
        if not isinstance(patterns, dict) and isinstance(result.get("rotors"), dict):
            patterns = result["rotors"].get("patterns")
        if not isinstance(patterns, dict):
            return None
        pattern = patterns.get(expected[1]) or {}
        return bool(pattern.get("significant"))
    if expected[0] == "rotor":
        rotors = _rotors(result)
        if rotors is None:
            return None
        sign = expected[2] if len(expected) > 2 else -1  # a weak rotor, unless said strong
        return any(
            r.get("rotor") == expected[1]
            and r.get("significant")
            and r.get("thrust_error", 0) * sign > 0
            for r in rotors
        )
    variable, component, upper = expected
    where = (result.get("unexplained") or {}).get("where")
    if variable == "time_since_takeoff_s" and component == "vertical" and _falling(result):
        return True  # the whole-flight trend since take-off is that regime, read as a slope
    if where is None:
        return None
    return any(
        w.get("variable") == variable
        and w.get("component") == component
        and (upper is None or w.get("low", math.inf) < upper)
        for w in where
    )


def verdict(expected: tuple[Any, ...], result: dict[str, Any]) -> dict[str, Any]:
    """The out-of-catalogue targets of one case; None marks a figure the result lacks."""
    effects = result.get("effects") or {}
    confident = sorted(
        e for e, r in effects.items() if r.get("status") == "present" and r.get("confident", True)
    )
    unexplained = result.get("unexplained")
    share = unexplained.get("share") if isinstance(unexplained, dict) else None
    learned = (result.get("gap") or {}).get("force_rms_n_learned")
    shrink = learned.get("shrink") if isinstance(learned, dict) else None
    where = located(expected, result)
    share_ok = isinstance(share, int | float) and math.isfinite(share)
    shrink_ok = None if shrink is None else bool(shrink >= LEARNED_SHRINK_MIN)
    if expected and expected[0] == "pattern":
        # a torque: no force for a residual to learn, so no shrink to ask of it
        shrink_ok = True
    return {
        "expected_regime": list(expected),
        "located": where,
        "confident_catalogue": confident,
        "unexplained_share": float(share) if share_ok else None,
        "learned_shrink": shrink,
        "learned_shrink_ok": shrink_ok,
        "passed": bool(where and not confident and share_ok and shrink_ok),
    }


def _yes(value: bool | None) -> str:
    return "missing" if value is None else "yes" if value else "no"


def verdict_text(v: dict[str, Any]) -> str:
    """One table cell: located, confident catalogue effects, share, learnt shrink."""
    share = v["unexplained_share"]
    shrink = v["learned_shrink"]
    return (
        f"{'PASS' if v['passed'] else 'fail'}: located {_yes(v['located'])}, "
        f"confident {','.join(v['confident_catalogue']) or '-'}, "
        f"share {'missing' if share is None else f'{share * 100:.0f}%'}, "
        f"learnt {'missing' if shrink is None else f'{shrink * 100:.0f}%'}"
    )


def summary(verdicts: list[dict[str, Any]]) -> dict[str, Any]:
    """Rates over the out-of-catalogue cases (a missing figure counts as a miss)."""
    n = len(verdicts)

    def rate(key: str, good: Any) -> float:
        return sum(1 for v in verdicts if good(v[key])) / n if n else float("nan")

    return {
        "cases": n,
        "located": rate("located", bool),
        "no_confident_catalogue": rate("confident_catalogue", lambda c: not c),
        "share_reported": rate("unexplained_share", lambda s: s is not None),
        "learned_shrink_ok": rate("learned_shrink_ok", bool),
        "passed": rate("passed", bool),
    }
