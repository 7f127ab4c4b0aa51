"""What `groundfx autopilot` (and so `groundfx sitl`) prints when it ends: one aligned row
per flight, saying how each ended, not the summary's raw mapping (`--json` prints that)."""

from __future__ import annotations

from typing import Any

COLUMNS = (
    ("flight", 6),
    ("ended", 22),
    ("landing error", 13),
    ("touchdown", 10),
    ("hold z RMS", 10),
    ("simulated", 9),
)


def _mm(value: Any) -> str:
    return "-" if value is None else f"{value * 1000:.1f} mm"


def _row(number: int, flight: dict[str, Any], ended: str) -> str:
    speed = flight.get("touchdown_speed_m_s")
    sim_s = flight.get("sim_s")
    cells = (
        str(number),
        ended,
        _mm(flight.get("landing_error_m")),
        "-" if speed is None else f"{speed:.2f} m/s",
        _mm(flight.get("hold_z_rms_error_m")),
        "-" if sim_s is None else f"{sim_s:.1f} s",
    )
    return "  " + "  ".join(c.ljust(w) for c, (_, w) in zip(cells, COLUMNS, strict=True)).rstrip()


def exit_summary(summary: dict[str, Any]) -> str:
    """The run's end in a few lines: why it ended, then its flights."""
    flights = [(f, f.get("ended", "landed")) for f in summary.get("flights", [])]
    if summary.get("controller_us_p50") is not None:  # the rotors ran since the last one
        ended = str(summary["ended"])
        if ended != "landed" and summary.get("touchdown_time_s") is not None:
            ended = f"landed, then {ended}"
        flights.append((summary, ended))
    landed = sum(1 for _, ended in flights if ended.startswith("landed"))
    head = f"groundfx autopilot: {summary['ended']}; "
    head += f"{len(flights)} flight{'s' if len(flights) != 1 else ''}, {landed} landed"
    if summary.get("recording"):
        head += f"; recording {summary['recording']}"
    if not flights:
        return head
    header = "  " + "  ".join(name.ljust(w) for name, w in COLUMNS).rstrip()
    return "\n".join([head, header, *(_row(n, f, e) for n, (f, e) in enumerate(flights, 1))])
