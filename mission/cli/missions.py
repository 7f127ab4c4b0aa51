"""`groundfx mission convert IN OUT` and `groundfx mission check FILE`: mission files between
YAML (local metres), QGroundControl `.plan` and `QGC WPL 110`, validated as the vehicle would."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot.commander.mission_items import Home, MissionItem
    from mission.plans.doc import MissionDoc

# The model and the formats are imported when a mission command runs: they bring pymavlink
# and the simulator's modules, which `groundfx --help` and the other commands need not wait for.


def _home(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected LAT,LON,ALT in degrees and metres, got {text!r}"
        ) from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and -500 <= alt <= 9000):
        raise argparse.ArgumentTypeError(
            f"lat in [-90, 90], lon in [-180, 180], alt in [-500, 9000] m; got {text!r}"
        )
    return (lat, lon, alt)


def _limit_m(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected metres >= 0 (0: no limit), got {text!r}")
    return value


def add_mission_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add `mission convert` and `mission check` to the `groundfx` command line."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--home",
        type=_home,
        metavar="LAT,LON,ALT",
        help="home of a YAML mission that names none (default: the default world's origin); "
        ".plan and .waypoints files carry their own",
    )
    common.add_argument(
        "--max-altitude", type=_limit_m, default=0.0, metavar="M",
        help="geofence: highest point, metres above home (default: 0, no limit)",
    )  # fmt: skip
    common.add_argument(
        "--max-radius", type=_limit_m, default=0.0, metavar="M",
        help="geofence: farthest point, horizontal metres from home (default: 0, no limit)",
    )  # fmt: skip
    p = subparsers.add_parser(
        "mission", help="convert and check mission files (YAML, QGroundControl .plan, QGC WPL)"
    )
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    c = actions.add_parser(
        "convert",
        parents=[common],
        help="convert a mission file; the format follows OUT's suffix",
        description="Formats: .yaml/.yml (local metres), .plan (QGroundControl), "
        ".waypoints/.txt (QGC WPL 110, MAVProxy's wp load).",
    )
    c.add_argument("input", type=Path, metavar="IN", help="mission file to read")
    c.add_argument("output", type=Path, metavar="OUT", help="file to write (.yaml, .plan, ...)")
    k = actions.add_parser(
        "check", parents=[common], help="validate a mission file and print one line per item"
    )
    k.add_argument("file", type=Path, metavar="FILE", help="mission file")
    p.set_defaults(func=cmd_mission)


def describe(item: MissionItem, home: Home) -> str:
    """One item in words, positions in metres from home (x east, y north, z up)."""
    from autopilot.commander.mission_items import (
        DO_CHANGE_SPEED,
        NAV_LAND,
        NAV_RETURN_TO_LAUNCH,
        NAV_TAKEOFF,
        NAV_WAYPOINT,
        NO_POSITION,
        local_offset,
    )
    from mission.plans.doc import flip_yaw_deg

    if item.command == DO_CHANGE_SPEED:
        return f"speed {item.param2:g} m/s" if item.param2 > 0 else "speed unchanged"
    if item.command == NAV_RETURN_TO_LAUNCH:
        return "return home and land"
    east, north, up = (round(v, 3) + 0.0 for v in local_offset(item, home))  # no "-0.000"
    place = f"east {east:.2f} north {north:.2f} m"  # centimetres: the degE7 grid's resolution
    if item.command != NAV_WAYPOINT and (item.x, item.y) == (NO_POSITION, NO_POSITION):
        place = "where it stands"
    if item.command == NAV_TAKEOFF:
        return f"to {up:.3f} m above home, {place}"
    if item.command == NAV_LAND:
        return f"land {place}"
    yaw = "free" if math.isnan(item.param4) else f"{flip_yaw_deg(item.param4):g} deg from east"
    return f"{place} up {up:.3f} m, hold {item.param1:g} s, radius {item.param2:g} m, yaw {yaw}"


def summary(path: Path, doc: MissionDoc) -> list[str]:
    from mission.plans.formats import FORMAT_NAMES, file_format

    home = doc.home
    kind = FORMAT_NAMES[file_format(path, path.read_text())]
    lines = [
        f"{path}: {kind}, {len(doc.items)} items, "
        f"home {home.lat_deg:.7f}, {home.lon_deg:.7f}, {home.alt_m:g} m AMSL"
    ]
    for seq, item in enumerate(doc.items):
        lines.append(f"{seq:4d} {item.name:<21} {describe(item, home)}")
    if doc.waypoint_timeout_s is not None:
        lines.append(f"waypoint timeout {doc.waypoint_timeout_s:g} s")
    return lines


def cmd_mission(args: argparse.Namespace) -> int:
    from autopilot.commander.mission_items import Geofence, Home
    from mission.plans.formats import FORMAT_NAMES, SUFFIXES, load_mission_file, save_mission_file

    fence = Geofence(max_altitude_m=args.max_altitude, max_radius_m=args.max_radius)
    source = args.input if args.action == "convert" else args.file
    origin = None if args.home is None else Home(*args.home)
    doc = load_mission_file(source, origin, fence)
    if origin is not None and doc.home != origin:
        note = f"groundfx mission: note: {source} names its own home; --home unused"
        print(note, file=sys.stderr)
    if args.action == "check":
        print("\n".join(summary(source, doc)))
        print(f"ok: {len(doc.items)} items the vehicle accepts")
        return 0
    save_mission_file(doc, args.output)
    kind = FORMAT_NAMES[SUFFIXES[args.output.suffix.lower()]]
    print(f"groundfx mission: wrote {args.output} ({kind}, {len(doc.items)} items)")
    return 0
