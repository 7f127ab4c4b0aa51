"""A flight request: what `groundfx fly`, `groundfx sitl` and the command line ask of the
autopilot process, declared once.

Each field carries its option's name, default and help. The `groundfx autopilot` parser is
built from them, and the request crosses into the autopilot process as the command line it
writes itself (`argv`) and reads back (`parse`), so that a flight started by our own code
and one started by hand take the same path.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

from autopilot.control.ground_models import MODEL_NAMES
from autopilot.identity import IDENTITIES
from autopilot.simlink import DEFAULT_LINK_TIMEOUT_S
from learner.online.names import METHODS
from learner.online.settings import tuned_in_flight
from simbridge.config import ConfigError

DEFAULT_MAX_FLIGHT_S = 900.0  # a flight ends (exit code 3) after this many simulated seconds
DEFAULT_SIM_URL = "tcp:127.0.0.1:4560"  # the PX4 simulator protocol's port
DEFAULT_GCS_URLS = ("udpout:127.0.0.1:14550", "udpin:0.0.0.0:14540")  # QGroundControl; MAVSDK
DEFAULT_PARAMS_FILE = Path("logs") / "params.yaml"
NO_PARAMS_FILE = "none"  # --params-file none: nothing persists


def seconds_within(low: float, high: float, text: str) -> float:
    """Seconds in [low, high], or an argparse error naming the range."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not low <= value <= high:
        raise argparse.ArgumentTypeError(f"expected seconds in [{low:g}, {high:g}], got {text!r}")
    return value


def flight_seconds(text: str) -> float:
    """A flight's limit (its length, a silence) in seconds, in [1, 86400]."""
    return seconds_within(1.0, 86400.0, text)


def alternation_seconds(text: str) -> float:
    """A learner's turn in seconds, in [0.1, 600]."""
    return seconds_within(0.1, 600.0, text)


def option(
    default: Any,
    help: str,
    *,
    type: Any = None,
    choices: Sequence[str] | None = None,
    metavar: str | None = None,
    section: str | None = None,
    exclusive: str | None = None,
    negative: str | None = None,
) -> Any:
    """A field that is also a command-line option `--name-with-dashes`. A bool is a switch;
    a tuple a repeatable option; `negative`: the switch that sets a tri-state bool False
    (with its help after a `|` in `help`). `section`: the help's section; `exclusive`: the
    name of the options it excludes (set one of them)."""
    spec = {"help": help, "type": type, "choices": choices, "metavar": metavar}
    spec |= {"section": section, "exclusive": exclusive, "negative": negative}
    return field(default=default, metadata=spec)


@dataclass(frozen=True)
class FlightRequest:
    sim: str = option(
        DEFAULT_SIM_URL,
        f"simulator URL, tcp:HOST:PORT or unix:PATH (default: {DEFAULT_SIM_URL})",
    )
    mission: Path | None = option(None, "a mission file to load before any upload", type=Path)
    auto_start: bool = option(
        False, "arm and fly --mission at once, without a ground station (reproducible runs)"
    )
    exit_after_landing: bool = option(
        False, "end (printing the summary) once a flight has landed and disarmed"
    )
    model: str | None = option(
        None,
        "ground-effect model of the controller (default: parameter GFX_GE_MODEL, analytic)",
        choices=MODEL_NAMES,
    )
    rho: float | None = option(
        None, "rho of the analytic model (fly's default: the world's rho_sim)", type=float
    )
    network: str | None = option(
        None,
        "model file or packaged name for --model neural "
        "(default: the packaged network trained nearest --rho)",
    )
    out: tuple[str, ...] = option(
        (),
        "ground-station endpoint, repeatable: udpout:HOST:PORT, udpin:HOST:PORT, "
        f"tcpin:HOST:PORT (default: {' and '.join(DEFAULT_GCS_URLS)})",
        metavar="URL",
    )
    no_gcs: bool = option(False, "no ground-station endpoint at all")
    identity: str = option(
        "px4",
        "autopilot type and mode numbering in HEARTBEAT (default: px4)",
        choices=tuple(IDENTITIES),
    )
    params_file: Path = option(
        DEFAULT_PARAMS_FILE,
        f"YAML file parameters set over MAVLink persist in (default: {DEFAULT_PARAMS_FILE}; "
        f"{NO_PARAMS_FILE}: nothing persists)",
        type=Path,
    )
    param: tuple[str, ...] = option(
        (),
        "a parameter for this run only, repeatable (e.g. --param MIS_TAKEOFF_ALT=2)",
        metavar="NAME=VALUE",
    )
    signing_key_file: Path | None = option(
        None,
        "sign MAVLink 2 to ground stations and accept only signed packets; the file "
        "holds 64 hex digits or a passphrase",
        type=Path,
    )
    vehicle: str = option("nano", "vehicle YAML or packaged name")
    origin: str | None = option(None, "geodetic origin of the local frame", metavar="LAT,LON,ALT")
    json: bool = option(False, "print the summary as one JSON object")
    trajectory: Path | None = option(None, "save the flown trajectory (.npz)", type=Path)
    flight_log: Path | None = option(None, "save airborne steps as a gap-diagnosis log", type=Path)
    max_flight_s: float = option(
        DEFAULT_MAX_FLIGHT_S,
        "end the flight after this many simulated seconds (without --exit-after-landing: "
        "from each arming); the autopilot then exits with "
        f"code 3 (default {DEFAULT_MAX_FLIGHT_S:g})",
        type=flight_seconds,
    )
    link_timeout_s: float = option(
        DEFAULT_LINK_TIMEOUT_S,
        "end the flight after this many seconds without a word from the simulator; a slow "
        "simulator is waited for, one that closed its connection ends the flight at once "
        f"(default {DEFAULT_LINK_TIMEOUT_S:g})",
        type=flight_seconds,
    )
    online: str | None = option(
        None,
        f"adapt the neural model in flight: {', '.join(METHODS)} (parameter GFX_OL_METHOD; "
        f"hyperparameters {', '.join(tuned_in_flight())} via --param)",
        choices=METHODS,
        metavar="METHOD",
        section="online learning",
    )
    online_deterministic: bool | None = option(
        None,
        "update inside the control step when a batch completes: the same simulated "
        "times on every run (default with --auto-start / --no-gcs)"
        "|update in the learner thread; the control loop never waits "
        "(default with a ground station)",
        section="online learning",
        negative="--online-async",
    )
    save_model: Path | None = option(
        None, "save the adapted network here at the end", type=Path, section="online learning"
    )
    online_alternate: float | None = option(
        None,
        "the learner works S simulated seconds, then rests S (no samples taken), in turn; the "
        "summary keeps each control step's time with its turn (groundfx bench online)",
        type=alternation_seconds,
        metavar="S",
        section="online learning",
    )
    record: Path | None = option(
        None,
        "write the flight's rerun recording here (default: logs/<time>-<mission>-<model>.rrd)",
        type=Path,
        metavar="PATH",
        exclusive="recording",
    )
    no_record: bool = option(False, "do not record the flight", exclusive="recording")
    record_world: str | None = option(
        None,
        "world YAML or packaged name drawn in the recording (ground and obstacles); "
        "default: flat ground",
        metavar="WORLD",
    )
    record_mission: str | None = option(
        None,
        "the mission file a ground station uploads, named in the recording's meta",
        metavar="FILE",
    )

    def argv(self) -> list[str]:
        """The command line that `parse` reads back into this request (its options that
        differ from their defaults)."""
        out: list[str] = []
        for f in dataclasses.fields(self):
            value, flag = getattr(self, f.name), _flag(f.name)
            if value == f.default:
                continue
            if isinstance(value, bool):
                out.append(flag if value else f.metadata["negative"])
            elif isinstance(value, tuple):
                out += [f"{flag}={v}" for v in value]
            else:  # one word: a value with a leading minus would read as an option
                out.append(f"{flag}={value}")
        return out

    @classmethod
    def parse(cls, argv: Sequence[str]) -> FlightRequest:
        """The request a command line asks for; a ConfigError with argparse's message if it
        asks for something the autopilot does not take."""
        parser = _RaisingParser(prog="groundfx autopilot")
        add_options(parser)
        return cls.from_args(parser.parse_args(list(argv)))

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> FlightRequest:
        """The request from parsed options (those `add_options` added; others at defaults)."""
        values = {}
        for f in dataclasses.fields(cls):
            if hasattr(args, f.name):
                value = getattr(args, f.name)
                values[f.name] = tuple(value) if isinstance(f.default, tuple) else value
        return cls(**values)

    def with_options(self, argv: Sequence[str]) -> FlightRequest:
        """This request with the options in `argv` set over it (a repeatable option's
        values after this request's, as on one command line)."""
        given = FlightRequest.parse(argv)
        changed = {}
        for f in dataclasses.fields(self):
            value = getattr(given, f.name)
            if value != f.default:
                mine = getattr(self, f.name)
                changed[f.name] = mine + value if isinstance(value, tuple) else value
        return dataclasses.replace(self, **changed)


class _RaisingParser(argparse.ArgumentParser):
    """A parser for our own code's command lines: an error is raised, not printed and
    exited on."""

    def error(self, message: str) -> NoReturn:
        raise ConfigError(f"{self.prog}: {message}")


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def add_options(
    parser: argparse.ArgumentParser,
    names: Iterable[str] | None = None,
    defaults: dict[str, Any] | None = None,
    helps: dict[str, str] | None = None,
) -> None:
    """The request's options on `parser`: all of them, or those `names`; `defaults` and
    `helps` replace a field's where another command defaults otherwise."""
    fields = {f.name: f for f in dataclasses.fields(FlightRequest)}
    defaults, helps = defaults or {}, helps or {}
    sections: dict[str, Any] = {}
    exclusive: dict[str, Any] = {}
    for name in list(fields) if names is None else names:
        f, spec = fields[name], fields[name].metadata
        default = defaults.get(name, f.default)
        help_text = helps.get(name, spec["help"])
        where: Any = parser
        if spec["section"] is not None:
            if spec["section"] not in sections:
                sections[spec["section"]] = parser.add_argument_group(spec["section"])
            where = sections[spec["section"]]
        if spec["exclusive"] is not None:
            if spec["exclusive"] not in exclusive:
                exclusive[spec["exclusive"]] = where.add_mutually_exclusive_group()
            where = exclusive[spec["exclusive"]]
        _add_option(where, name, f, spec, default, help_text)


def _add_option(
    where: Any, name: str, f: dataclasses.Field, spec: Any, default: Any, help_text: str
) -> None:
    if spec["negative"] is not None:
        yes, no = help_text.split("|")
        pair = where.add_mutually_exclusive_group()
        pair.add_argument(_flag(name), dest=name, action="store_true", default=default, help=yes)
        pair.add_argument(spec["negative"], dest=name, action="store_false", help=no)
    elif isinstance(f.default, bool):
        where.add_argument(_flag(name), action="store_true", help=help_text)
    elif isinstance(f.default, tuple):
        where.add_argument(
            _flag(name), action="append", default=list(default), metavar=spec["metavar"],
            help=help_text,
        )  # fmt: skip
    else:
        where.add_argument(
            _flag(name), default=default, type=spec["type"], choices=spec["choices"],
            metavar=spec["metavar"], help=help_text,
        )  # fmt: skip
