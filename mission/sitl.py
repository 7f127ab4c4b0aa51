"""`groundfx sitl`: the simulator and the autopilot as two processes, waiting for ground
stations, like `make px4_sitl` or `sim_vehicle.py`. Ends on Ctrl-C (or SIGTERM), or when
either process does."""

from __future__ import annotations

import dataclasses
import signal
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import yaml

from autopilot.request import FlightRequest
from mission.cli.autopilot import READY
from mission.fly import request_command
from simbridge.config import ConfigError
from simbridge.launch import start_sim, supervised_options
from simbridge.world import load_world, resolve_world_path

STOP_WAIT_S = 5.0  # for each process to end on its signal before it is killed


def parse_location(text: str) -> tuple[float, float, float, float]:
    """`-L LAT,LON,ALT,YAW` as sim_vehicle.py takes it (YAW optional, degrees from north)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) == 3:
        values.append(0.0)
    if len(values) != 4:
        raise ConfigError(f"-L {text!r}: expected LAT,LON,ALT[,YAW]")
    lat, lon, alt, yaw = values
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and -500 <= alt <= 9000 and -360 <= yaw <= 360):
        raise ConfigError(
            f"-L {text!r}: lat in [-90, 90], lon in [-180, 180], alt in [-500, 9000] m, "
            "yaw in [-360, 360] deg"
        )
    return lat, lon, alt, yaw


def located_world(world: str, location: tuple[float, float, float, float], folder: Path) -> Path:
    """The world file with its geodetic origin at `location` and the start heading its yaw."""
    data = yaml.safe_load(resolve_world_path(world).read_text()) or {}
    lat, lon, alt, yaw_from_north = location
    origin = dict(data.get("origin") or {})
    origin.update(lat_deg=lat, lon_deg=lon, alt_m=alt)
    data["origin"] = origin
    start = dict(data.get("start") or {})
    start["yaw_deg"] = ((90.0 - yaw_from_north) + 180.0) % 360.0 - 180.0  # from east
    data["start"] = start
    path = folder / "world.yaml"
    path.write_text(yaml.safe_dump(data))
    load_world(path)  # refuse it here, with the message, if it is wrong
    return path


def run_sitl(
    world: str,
    speedup: str,
    request: FlightRequest,
    vehicle: str | None,
    location: tuple[float, float, float, float] | None,
    say: Callable[[str], None] = print,
    sim_options: Sequence[str] = (),
) -> int:
    """The simulator and an autopilot process flying `request` against it, with the world's
    origin and (unless `vehicle` names one) its vehicle."""
    with tempfile.TemporaryDirectory(prefix="groundfx-sitl-") as tmp:
        world_path = (
            located_world(world, location, Path(tmp)) if location else resolve_world_path(world)
        )
        world_obj = load_world(world_path)
        o = world_obj.origin
        sim, port = start_sim(
            world_path, speedup=speedup, extra=["--wait", *sim_options], supervised=True
        )
        request = dataclasses.replace(
            request,
            sim=f"tcp:127.0.0.1:{port}",
            origin=f"{o.lat_deg},{o.lon_deg},{o.alt_m}",
            record_world=str(world_path),  # ignored when not recording
            vehicle=vehicle or world_obj.vehicle,
        )
        autopilot = subprocess.Popen(
            request_command(request),
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
            **supervised_options(),
        )
        say(f"groundfx sitl: simulator on tcp:127.0.0.1:{port} ({world_path}, speed {speedup})")
        say(f"groundfx sitl: vehicle 1 at {o.lat_deg:.7f}, {o.lon_deg:.7f}, {o.alt_m:g} m")
        for url in request.out:
            say(f"groundfx sitl: ground stations: {connect_hint(url)}")
        say("groundfx sitl: starting (Ctrl-C to stop)")
        relay = threading.Thread(target=relay_output, args=(autopilot, say), daemon=True)
        relay.start()
        stop: list[int] = []
        previous = {
            sig: signal.signal(sig, lambda signum, frame: stop.append(signum))
            for sig in (signal.SIGINT, signal.SIGTERM)
        }
        try:
            while not stop and autopilot.poll() is None and sim.poll() is None:
                time.sleep(0.05)
        finally:
            stop_in_order(autopilot, sim)
            relay.join(timeout=STOP_WAIT_S)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        if stop:
            say(f"groundfx sitl: stopped by {signal.Signals(stop[0]).name}")
            return 0
        say(f"groundfx sitl: the autopilot ended (exit code {autopilot.returncode})")
        return 0 if autopilot.returncode == 0 else (autopilot.returncode or 1)


def relay_output(autopilot: subprocess.Popen[str], say: Callable[[str], None]) -> None:
    """The autopilot's output, line by line; its ready line becomes sitl's."""
    assert autopilot.stdout is not None
    for line in autopilot.stdout:
        text = line.rstrip("\n")
        if text.startswith(READY):
            say(f"groundfx sitl: ready: {text[len(READY) :].strip()} (Ctrl-C to stop)")
        else:
            say(text)


def stop_in_order(autopilot: subprocess.Popen, sim: subprocess.Popen[str]) -> None:
    """The autopilot first (it closes its recording and links), then the simulator, which
    waits for the next autopilot until told to stop; each killed after STOP_WAIT_S. The
    autopilot's output is another thread's to read: it is waited for, not communicated."""
    for proc, sig in ((autopilot, signal.SIGINT), (sim, signal.SIGTERM)):
        if proc.poll() is None:
            proc.send_signal(sig)
        finish = proc.wait if proc is autopilot else proc.communicate
        try:
            finish(timeout=STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            finish()


def connect_hint(url: str) -> str:
    """What a ground station does to reach the vehicle on `url`."""
    scheme, host, port = url.split(":")
    if scheme == "udpout":
        return (
            f"the vehicle sends to udp {host}:{port} "
            f"(QGroundControl; mavproxy.py --master udpin:0.0.0.0:{port})"
        )
    if scheme in ("udpin", "udp"):
        peer = "127.0.0.1" if host in ("0.0.0.0", "") else host
        return (
            f"send to udp {peer}:{port} "
            f"(MAVSDK udpout://{peer}:{port}; pymavlink udpout:{peer}:{port})"
        )
    return f"connect to tcp {host}:{port} (mavproxy.py --master tcp:{host}:{port})"
