"""`QGC WPL 110` waypoint files (MAVProxy's `wp load` and `wp save`, Mission Planner, QGC).

    QGC WPL 110
    0  1  0  16  0.000000  0.000000  0.000000  0.000000  59.34980000  18.07070000  28.000000  1
    1  0  6  22  0.000000  0.000000  0.000000  nan  0.00000000  0.00000000  1.000000  1

Tab-separated (shown here with spaces): INDEX CURRENT FRAME COMMAND P1 P2 P3 P4 X(latitude)
Y(longitude) Z AUTOCONTINUE.
Row 0 is home (frame 0: its altitude above mean sea level); the items follow from index 1.
Latitude and longitude have 8 decimals (`dege7_to_deg`: MAVProxy truncates); other numbers
are MAVProxy's `%f` when that reads back exactly, else the shortest exact decimal; NaN is
`nan`. Lost: `waypoint_timeout_s`. There is nowhere to put it: QGroundControl reads every
line after the header as a row and refuses comments.
"""

from __future__ import annotations

import math

from autopilot.commander.mission_items import Home, MissionItem
from mission.plans.doc import MissionDoc, ParsedMission, carries_position, check_home, dege7_to_deg
from simbridge.config import ConfigError
from simbridge.hil import mavlink as mav

HEADER = "QGC WPL 110"
COLUMNS = (
    "INDEX", "CURRENT", "FRAME", "COMMAND", "P1", "P2", "P3", "P4", "X", "Y", "Z", "AUTOCONTINUE",
)  # fmt: skip
INTEGER_COLUMNS = ("INDEX", "CURRENT", "FRAME", "COMMAND", "AUTOCONTINUE")
WPL_FIELDS = {
    "frame": ", column 3 (FRAME)",
    "command": ", column 4 (COMMAND)",
    "param1": ", column 5 (P1)",
    "param2": ", column 6 (P2)",
    "param3": ", column 7 (P3)",
    "param4": ", column 8 (P4)",
    "x": ", column 9 (X, latitude)",
    "y": ", column 10 (Y, longitude)",
    "z": ", column 11 (Z, altitude)",
    "autocontinue": ", column 12 (AUTOCONTINUE)",
}


def _number_text(value: float) -> str:
    fixed = f"{value:f}"  # MAVProxy's format, when it loses nothing
    return fixed if math.isnan(value) or float(fixed) == value else repr(value)


def _degrees_text(value_deg: float) -> str:
    fixed = f"{value_deg:.8f}"
    return fixed if float(fixed) == value_deg else repr(value_deg)


def _row(index: int, current: int, item: MissionItem) -> str:
    if carries_position(item.command, item.frame):
        lat, lon = dege7_to_deg(item.x), dege7_to_deg(item.y)
    else:
        lat, lon = float(item.x), float(item.y)  # raw, as MAVProxy reads them
    fields = [str(index), str(current), str(item.frame), str(item.command)]
    fields += [_number_text(p) for p in (item.param1, item.param2, item.param3, item.param4)]
    fields += [f"{lat:.8f}", f"{lon:.8f}", _number_text(item.z), str(item.autocontinue)]
    return "\t".join(fields)


def dump_wpl(doc: MissionDoc) -> str:
    home = doc.home
    home_row = [
        "0", "1", str(mav.MAV_FRAME_GLOBAL), str(mav.MAV_CMD_NAV_WAYPOINT),
        *[_number_text(0.0)] * 4,
        _degrees_text(home.lat_deg), _degrees_text(home.lon_deg), _number_text(home.alt_m), "1",
    ]  # fmt: skip
    rows = [HEADER, "\t".join(home_row)]
    rows += [_row(seq + 1, 0, item) for seq, item in enumerate(doc.items)]
    return "\n".join(rows) + "\n"


def _parse_row(fields: list[str], where: str) -> tuple[list[int], list[float]]:
    """(INDEX, CURRENT, FRAME, COMMAND, AUTOCONTINUE) and (P1-P4, X, Y, Z)."""
    whole, real = [], []
    for column, (name, text) in enumerate(zip(COLUMNS, fields, strict=True), start=1):
        try:
            if name in INTEGER_COLUMNS:
                whole.append(int(text))
            else:
                real.append(float(text))
        except ValueError:
            kind = "an integer" if name in INTEGER_COLUMNS else "a number"
            raise ConfigError(
                f"{where}, column {column} ({name}): expected {kind}, got {text!r}"
            ) from None
    return whole, real


def parse_wpl(text: str, where: str) -> ParsedMission:
    lines = text.lstrip("\ufeff").splitlines()  # a byte-order mark, as Windows tools write
    if not lines or lines[0].strip() != HEADER:
        first = lines[0][:40] if lines else ""
        raise ConfigError(f"{where}: line 1: expected the header {HEADER!r}, got {first!r}")
    rows: list[tuple[str, list[int], list[float]]] = []
    for number, line in enumerate(lines[1:], start=2):
        if line.startswith("#") or not line.strip():
            continue  # as MAVProxy reads them
        fields = line.split()  # tabs when written; MAVProxy splits on any white space
        at = f"{where}: line {number}"
        if len(fields) != len(COLUMNS):
            raise ConfigError(
                f"{at}: expected {len(COLUMNS)} tab-separated fields ({' '.join(COLUMNS)}), "
                f"got {len(fields)}"
            )
        whole, real = _parse_row(fields, at)
        if whole[0] != len(rows):
            raise ConfigError(
                f"{at}, column 1 (INDEX): {whole[0]}: expected {len(rows)} "
                "(rows count from 0, home first)"
            )
        rows.append((f"line {number}", whole, real))
    if not rows:
        raise ConfigError(f"{where}: no rows: row 0, home, must follow the header")
    home_at, home_whole, home_real = rows[0]
    if home_whole[2] != mav.MAV_FRAME_GLOBAL:
        raise ConfigError(
            f"{where}: {home_at}, column 3 (FRAME): home's frame {home_whole[2]}: expected 0 "
            "(its altitude is above mean sea level)"
        )
    home = check_home(Home(home_real[4], home_real[5], home_real[6]), f"{where}: {home_at} (home)")
    items = []
    for at, (_, _, frame, command, auto), (p1, p2, p3, p4, lat, lon, z) in rows[1:]:
        if carries_position(command, frame):
            if not (math.isfinite(lat) and math.isfinite(lon)):
                raise ConfigError(
                    f"{where}: {at}, columns 9-10 (X, Y): {lat}, {lon}: expected finite degrees"
                )
            x, y = round(lat * 1e7), round(lon * 1e7)
        else:
            x, y = (round(v) if math.isfinite(v) else 0 for v in (lat, lon))
        items.append(MissionItem(command, frame, p1, p2, p3, p4, x, y, z, auto))
    doc = MissionDoc(tuple(items), home)
    return ParsedMission(doc, tuple(at for at, _, _ in rows[1:]), WPL_FIELDS)
