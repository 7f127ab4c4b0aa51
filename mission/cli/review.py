"""`groundfx review RECORDING [--web | --report]`: open a flight recording in the rerun viewer,
or write its one-page report (`mission/flight_report.py`).

Native: the `rerun` viewer of the installed rerun-sdk opens the file (it needs a display);
it replaces this process. `--web`: the same viewer serves itself over HTTP instead
(`rerun --serve-web`), for a headless machine, and this process serves the recording beside
it, over HTTP on the data port, for the viewer in the browser to load; open the printed
address (through an SSH tunnel of both ports if the machine is remote). Ctrl-C ends both.
Given the file to serve itself, rerun's server keeps a core busy for as long as it runs (a
polling loop in its gRPC server, rerun-io/rerun#10944); empty, it idles.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import shutil
import signal
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import quote

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


def review(path: Path, web: bool = False, web_port: int = 9090, data_port: int = 9876) -> int:
    print(f"groundfx review: {check_recording(path)}", flush=True)
    if web:
        return serve_web(path, web_port, data_port)
    if sys.platform.startswith("linux"):
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ConfigError("no display for the native viewer; use --web to serve the web viewer")
    binary = rerun_binary()
    # the viewer takes over this process, and with it Ctrl-C and the exit code
    os.execv(binary, [binary, str(path)])
    return 0  # not reached


def serve_web(path: Path, web_port: int, data_port: int) -> int:
    """The web viewer's server, and the recording over HTTP beside it; until Ctrl-C."""
    files = _file_server(path, data_port)
    threading.Thread(target=files.serve_forever, daemon=True).start()
    # --serve-web hosts the viewer without trying to open a browser (--web-viewer would); its
    # gRPC server, which nothing here uses, on a port of the system's choosing
    viewer = subprocess.Popen(
        [rerun_binary(), "--serve-web", "--web-viewer-port", str(web_port), "--port", "0"],
        process_group=0,  # a terminal's Ctrl-C reaches this process, which passes it on
        preexec_fn=_killed_with_parent,
    )
    data = quote(f"http://127.0.0.1:{data_port}/{path.name}", safe="")
    print(
        f"groundfx review: web viewer at http://127.0.0.1:{web_port}/?url={data} (Ctrl-C ends it)",
        flush=True,
    )
    try:
        return viewer.wait()
    except KeyboardInterrupt:
        viewer.send_signal(signal.SIGINT)  # the viewer's server ignores SIGTERM
        return viewer.wait()
    finally:
        files.shutdown()
        if viewer.poll() is None:
            viewer.kill()
            viewer.wait()


def _file_server(path: Path, port: int) -> ThreadingHTTPServer:
    """An HTTP server of the one file, to any origin (the viewer's page is on another port)."""
    name = f"/{path.name}"

    class File(BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # the name http.server calls
            if self.path.split("?", 1)[0] != name:
                self.send_error(404)
                return
            data = path.read_bytes()
            self.send_response(200)
            self.send_header("Content-Type", "application/octet-stream")
            self.send_header("Content-Length", str(len(data)))
            self.send_header("Access-Control-Allow-Origin", "*")
            self.end_headers()
            self.wfile.write(data)

        def log_message(self, *args: Any) -> None:  # the viewer's own log is enough
            pass

    try:
        return ThreadingHTTPServer(("127.0.0.1", port), File)  # a tunnel reaches it
    except OSError as err:
        raise ConfigError(f"--data-port {port}: {err.strerror}") from None


def _killed_with_parent() -> None:
    """The viewer's server ends with this process, however it ends (Linux)."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG


def add_review_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("review", help="open a flight recording in the rerun viewer")
    p.add_argument("recording", type=Path, help="a recording (.rrd) of a flight")
    p.add_argument(
        "--web", action="store_true", help="serve the web viewer instead (headless machines)"
    )
    p.add_argument("--web-port", type=int, default=9090, help="HTTP port of --web (default: 9090)")
    p.add_argument(
        "--data-port",
        "--grpc-port",
        dest="data_port",
        type=int,
        default=9876,
        help="the port --web serves the recording on, for the viewer to load (default: 9876)",
    )
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
    return review(args.recording, args.web, args.web_port, args.data_port)
