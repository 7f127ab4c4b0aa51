"""`groundfx review RECORDING [--web | --report]`: open a flight recording in the rerun viewer,
or write its one-page report (`mission/flight_report.py`).

Native: the `rerun` viewer of the installed rerun-sdk opens the file (it needs a display).
`--web`: the same viewer serves itself over HTTP instead (`rerun --serve-web`), for a headless
machine; open the printed address in a browser (through an SSH tunnel of both ports if the
machine is remote). The viewer replaces this process: Ctrl-C ends it.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

from simbridge.config import ConfigError


def rerun_binary() -> str:
    """The viewer binary of the installed rerun-sdk (`rerun_cli/rerun`), not the `rerun` script
    in front of it: the script runs the binary as a child, which a signal to the script would
    leave running."""
    if os.environ.get("RERUN_CLI_PATH"):
        return os.environ["RERUN_CLI_PATH"]
    try:
        import rerun_cli

        binary = Path(rerun_cli.__file__).parent / ("rerun.exe" if os.name == "nt" else "rerun")
        if binary.is_file():
            return str(binary)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if found is None:
        raise ConfigError("no rerun viewer found: install rerun-sdk")
    return found


def check_recording(path: Path) -> str:
    """Refuse what is not a readable recording; a one-line description of what is."""
    from learner.flightlogs.recording import RecordingError, read_recording  # pyarrow: lazily

    try:
        recording = read_recording(path)
    except RecordingError as err:
        raise ConfigError(str(err)) from None
    if not recording.entities:
        raise ConfigError(f"{path}: a rerun file without flight data")
    t = recording.times("plots/position") if "plots/position" in recording.entities else []
    span = f"{t[-1] - t[0]:.1f} s of flight" if len(t) else "no flight data"
    state = "" if recording.complete else " (cut short: no footer, e.g. the autopilot was killed)"
    return f"{path}: {span}{state}"


def viewer_args(path: Path, web: bool, web_port: int, grpc_port: int) -> list[str]:
    if web:
        # --serve-web hosts the viewer without trying to open a browser (--web-viewer would)
        return [
            str(path),
            "--serve-web",
            "--web-viewer-port",
            str(web_port),
            "--port",
            str(grpc_port),
        ]
    return [str(path)]


def review(path: Path, web: bool = False, web_port: int = 9090, grpc_port: int = 9876) -> int:
    print(f"groundfx review: {check_recording(path)}", flush=True)
    if not web and sys.platform.startswith("linux"):
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ConfigError("no display for the native viewer; use --web to serve the web viewer")
    if web:
        print(
            f"groundfx review: web viewer at http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F"
            f"%2F127.0.0.1%3A{grpc_port}%2Fproxy (Ctrl-C ends it)",
            flush=True,
        )
    binary = rerun_binary()
    # the viewer takes over this process, and with it Ctrl-C and the exit code
    os.execv(binary, [binary, *viewer_args(path, web, web_port, grpc_port)])
    return 0  # not reached


def add_review_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("review", help="open a flight recording in the rerun viewer")
    p.add_argument("recording", type=Path, help="a recording (.rrd) of a flight")
    p.add_argument(
        "--web", action="store_true", help="serve the web viewer instead (headless machines)"
    )
    p.add_argument("--web-port", type=int, default=9090, help="HTTP port of --web (default: 9090)")
    p.add_argument("--grpc-port", type=int, default=9876, help="data port of --web (default: 9876)")
    p.add_argument(
        "--report",
        action="store_true",
        help="write the flight's one-page report (REC.report.png, answers in REC.report.json) "
        "instead of opening a viewer",
    )
    p.set_defaults(func=cmd_review)


def write_flight_report(path: Path) -> tuple[Path, Path]:
    """The one-page report of a readable recording, or a message saying why not."""
    from mission.flight_report_page import write_report

    check_recording(path)
    try:
        return write_report(path)
    except (KeyError, ValueError) as err:  # a recording of another program, or cut too short
        raise ConfigError(f"{path}: no flight report: {err}") from None


def cmd_review(args: argparse.Namespace) -> int:
    if args.report:
        png, answers = write_flight_report(args.recording)
        print(f"groundfx review: report {png} (answers: {answers})")
        return 0
    return review(args.recording, args.web, args.web_port, args.grpc_port)
