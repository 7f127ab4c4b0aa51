"""Mission files in three formats, one model: YAML in local metres (`plan_yaml`), QGroundControl
`.plan` JSON (`plan_qgc`) and `QGC WPL 110` text (`plan_wpl`).

`load_mission_file` reads any of them into a `MissionDoc` and validates it with the vehicle's
own rules (`validate_mission`: commands, frames, finite numbers, the geofence); every error is a
ConfigError naming the file, the item, where it sits in the file and the field.
`save_mission_file` writes the format its suffix names.
"""

from __future__ import annotations

from pathlib import Path

from autopilot.commander.mission_items import Geofence, Home, MissionError, validate_mission
from mission.plans.doc import MissionDoc, ParsedMission, check_home, default_home
from mission.plans.qgc import dump_plan, parse_plan
from mission.plans.wpl import HEADER as WPL_HEADER
from mission.plans.wpl import dump_wpl, parse_wpl
from mission.plans.yaml_plan import dump_yaml, parse_yaml
from simbridge.config import ConfigError, load_yaml

SUFFIXES = {".yaml": "yaml", ".yml": "yaml", ".plan": "plan", ".waypoints": "wpl", ".txt": "wpl"}
FORMAT_NAMES = {"yaml": "YAML (local metres)", "plan": "QGroundControl plan", "wpl": WPL_HEADER}
KNOWN = "YAML (.yaml, .yml), QGroundControl plan (.plan) or QGC WPL 110 (.waypoints, .txt)"
WRITERS = {"yaml": dump_yaml, "plan": dump_plan, "wpl": dump_wpl}


def _read_text(path: Path) -> str:
    try:
        return path.read_text()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text file; expected {KNOWN}") from None


def file_format(path: Path, text: str | None = None) -> str:
    """'yaml', 'plan' or 'wpl'. A `QGC WPL 110` first line wins over the suffix (MAVProxy
    users name these files anything); otherwise the suffix, else a JSON object is a plan."""
    if text is not None and text.lstrip("\ufeff").split("\n", 1)[0].strip() == WPL_HEADER:
        return "wpl"
    if path.suffix.lower() in SUFFIXES:
        return SUFFIXES[path.suffix.lower()]
    if text is not None and text.lstrip().startswith("{"):
        return "plan"
    raise ConfigError(f"{path}: unknown mission format; expected {KNOWN}")


def _parse(path: Path, origin: Home | None) -> ParsedMission:
    text = _read_text(path)
    kind = file_format(path, text)
    if kind == "plan":
        return parse_plan(text, str(path))
    if kind == "wpl":
        return parse_wpl(text, str(path))
    home = check_home(origin, "origin") if origin is not None else default_home()
    return parse_yaml(load_yaml(path), str(path), home)


def load_mission_file(
    path: str | Path, origin: Home | None = None, fence: Geofence | None = None
) -> MissionDoc:
    """A validated mission from a YAML, .plan or QGC WPL 110 file. `origin` is home for a
    YAML mission that names none (default: the default world's origin); the other formats
    carry their own. `fence`: none by default."""
    path = Path(path)
    parsed = _parse(path, origin)
    try:
        validate_mission(parsed.doc.items, parsed.doc.home, fence or Geofence())
    except MissionError as err:
        where = parsed.locations[err.seq] + parsed.field_names.get(err.field, "")
        raise ConfigError(f"{path}: {where}: {err}") from None
    return parsed.doc


def save_mission_file(doc: MissionDoc, path: str | Path) -> None:
    """Write `doc` in the format of the file's suffix; refuses a mission the vehicle would
    refuse, and (YAML) one the format cannot hold, naming the item and the field."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ConfigError(f"{path}: unknown mission format {path.suffix!r}; expected {KNOWN}")
    try:
        check_home(doc.home, "home")
        validate_mission(doc.items, doc.home, Geofence())
        text = WRITERS[SUFFIXES[path.suffix.lower()]](doc)
    except (MissionError, ConfigError) as err:
        raise ConfigError(f"{path}: {err}") from None
    try:
        path.write_text(text)
    except OSError as err:
        raise ConfigError(f"{path}: cannot write ({err.strerror})") from None
