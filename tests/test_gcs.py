"""The ground-station endpoint with a real pymavlink ground station over UDP: parameters,
missions up and down, refusals, hostile input, the link-loss failsafe, the geofence, signing."""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav

from autopilot.commander.mission_items import NAV_WAYPOINT, Home, item_at
from autopilot.gcs.mission_protocol import item_from_message, item_message
from mission.fly import gcs_autopilot_command
from mission.gcs_client import GroundStation, GroundStationError
from mission.plans.formats import load_mission_file
from simbridge.launch import finish, start_sim
from simbridge.world import load_world
from tests.helpers import REPO, cpu_bound
from tests.hostile_frames import flood

SQUARE = REPO / "mission" / "examples" / "square.plan"
WORLD_ORIGIN = load_world("default").origin
ORIGIN = Home(WORLD_ORIGIN.lat_deg, WORLD_ORIGIN.lon_deg, WORLD_ORIGIN.alt_m)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def vehicle(
    *options: str, speedup: str = "max", key: bytes | None = None
) -> Iterator[tuple[GroundStation, subprocess.Popen[str], int]]:
    """A simulator and an autopilot sending to a pymavlink ground station; also listening on
    a udpin port (the third value) for other senders. It records only where `--record PATH`
    is among the options."""
    station = GroundStation("udpin:127.0.0.1:0", signing_key=key)
    listen_port = free_udp_port()
    sim, port = start_sim("default", speedup=speedup)
    cmd = gcs_autopilot_command(
        port,
        station.conn.port.getsockname()[1],
        "--out",
        f"udpin:127.0.0.1:{listen_port}",
        "--json",
        *(() if "--record" in options else ("--no-record",)),
        *options,
    )
    autopilot = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        station.connect(timeout_s=20.0)
        yield station, autopilot, listen_port
    finally:
        if autopilot.poll() is None:
            autopilot.terminate()
        autopilot.communicate(timeout=30)
        finish(sim)
        station.close()


def on_the_wire(items: tuple) -> tuple:
    """The items as MISSION_ITEM_INT carries them (parameters as float32)."""
    packer = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    return tuple(
        item_from_message(packer.decode(bytearray(item_message(it, k, False, (1, 1)).pack(packer))))
        for k, it in enumerate(items)
    )


def summary_of(autopilot: subprocess.Popen[str]) -> dict:
    out, err = autopilot.communicate(timeout=60)
    assert out.strip(), err
    return json.loads(out.strip().splitlines()[-1])


def test_parameters_set_read_refuse_and_persist(tmp_path):
    params = tmp_path / "params.yaml"
    with vehicle("--params-file", str(params), speedup="1") as (gs, _, _):
        assert gs.set_param("MIS_TAKEOFF_ALT", 1.5) == 1.5
        assert gs.set_param("MPC_XY_CRUISE", 1000.0) == 0.5  # out of range: the old value back
        assert any("outside the allowed range" in t for t in gs.progress.texts)
        value = gs.get_param("MIS_TAKEOFF_ALT")
        assert value.param_value == 1.5 and value.param_type == mav.MAV_PARAM_TYPE_REAL32
        count = value.param_count
        gs.conn.mav.param_request_list_send(1, 1)
        names = set()
        gs.wait_for(
            "the whole parameter list",
            lambda m: m.get_type() == "PARAM_VALUE" and names.add(m.param_id) is None
            and len(names) == count,
        timeout_s=30.0,  # a bound, not a wait: the list streams in a second when quiet
        )  # fmt: skip
        assert {"MIS_TAKEOFF_ALT", "NAV_DLL_ACT", "GF_MAX_VER_DIST", "GFX_GE_MODEL"} <= names
        # MAVLink-FTP is answered with a NAK, so MAVProxy falls back to the list at once
        gs.conn.mav.file_transfer_protocol_send(0, 1, 1, [0] * 251)
        nak = gs.wait_for("FTP NAK", lambda m: m.get_type() == "FILE_TRANSFER_PROTOCOL", 3.0)
        assert nak.payload[3] == 129
    with vehicle("--params-file", str(params), speedup="1") as (gs, autopilot, _):
        assert gs.get_param("MIS_TAKEOFF_ALT").param_value == 1.5  # persisted across restarts
        autopilot.terminate()
        _, err = autopilot.communicate(timeout=30)
    # and said so, never silently: the file, the names, how to start from the defaults
    assert f"1 parameter from {params} (set over MAVLink in an earlier run: MIS_TAKEOFF_ALT)" in err
    assert "--params-file none" in err


def test_a_mission_downloads_identical_and_a_bad_one_leaves_it_in_place():
    doc = load_mission_file(SQUARE)
    with vehicle("--param", "GF_MAX_HOR_DIST=10", speedup="1") as (gs, _, _):
        gs.upload(doc.items)
        back = gs.download()
        sent = on_the_wire(doc.items)
        assert len(back) == len(sent)
        assert all(a.same_as(b) for a, b in zip(back, sent, strict=True))
        outside = item_at(NAV_WAYPOINT, ORIGIN, (50.0, 0.0, 1.0))  # beyond GF_MAX_HOR_DIST 10 m
        bad = (*doc.items[:2], outside, *doc.items[2:])
        with pytest.raises(GroundStationError, match=r"item 2 .*geofence"):
            gs.upload(bad)
        assert all(a.same_as(b) for a, b in zip(gs.download(), sent, strict=True))
        nan_item = item_at(NAV_WAYPOINT, ORIGIN, (0.5, 0.0, float("nan")))
        with pytest.raises(GroundStationError, match="INVALID_PARAM7"):
            gs.upload((doc.items[0], nan_item))
        assert len(gs.download()) == len(doc.items)


def test_the_square_mission_flies_to_the_end_through_10000_hostile_frames():
    doc = load_mission_file(SQUARE)
    with vehicle() as (gs, autopilot, listen_port):
        sent = [0]
        stop = threading.Event()
        sender = threading.Thread(target=flood, args=(listen_port, sent, stop), daemon=True)
        gs.upload(doc.items)
        gs.wait_armable()
        gs.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming")
        gs.require(mav.MAV_CMD_MISSION_START, 0, 0, what="mission start")
        sender.start()
        gs.wait_for(
            "disarm after landing", lambda m: gs.progress.was_armed and not gs.progress.armed, 120.0
        )
        stop.set()
        sender.join(timeout=10)
        summary = summary_of(autopilot)
    assert sent[0] >= 10_000
    assert sorted(gs.progress.reached) == list(range(len(doc.items)))
    assert summary["landed"] and summary["landing_error_m"] < 0.02
    counters = summary["gcs"]
    assert counters["dropped"] + counters["invalid"] >= 5_000, counters
    assert counters["malformed"] > 0 and counters["unknown"] > 0 and counters["wrong_target"] > 0


def test_heartbeats_go_on_through_a_flood_beside_two_cpu_bound_processes():
    """A hover through 5,000 hostile frames on a busy machine: the ground station hears a
    heartbeat at least every 1.5 s of wall time (MAVSDK and QGroundControl call a link lost
    after about 3 s), and the vehicle lands."""
    with vehicle("--param", "MIS_TAKEOFF_ALT=1", speedup="2") as (gs, autopilot, listen_port):
        gs.wait_armable()
        gs.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming")
        gs.require(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, float("nan"), 0, 0, 1.0, what="take-off")
        gs.wait_for(
            "the hover at 1 m",
            lambda m: m.get_type() == "GLOBAL_POSITION_INT" and m.relative_alt > 950,
            30.0,
        )
        heard: list[float] = []
        with cpu_bound(2):
            sender = subprocess.Popen(
                [sys.executable, "-m", "tests.hostile_frames", str(listen_port), "5000", "1.5"],
                stdout=subprocess.PIPE,
                text=True,
                cwd=REPO,
            )
            try:
                while sender.poll() is None or len(heard) < 3:
                    m = gs.receive(0.2)
                    if m is not None and m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1:
                        heard.append(time.monotonic())
            finally:
                sender.kill()
                out, _ = sender.communicate()
        gs.require(mav.MAV_CMD_NAV_LAND, what="landing")
        gs.wait_for("disarm after landing", lambda m: not gs.progress.armed, 60.0)
        summary = summary_of(autopilot)
    assert int(out) == 5000
    gaps = [b - a for a, b in itertools.pairwise(heard)]
    assert max(gaps) <= 1.5, f"heartbeat gaps {[round(g, 2) for g in gaps]} s"
    print(f"heartbeat gaps at most {max(gaps):.2f} s; {summary['gcs']}")
    assert summary["landed"], summary
    assert summary["gcs"]["dropped"] + summary["gcs"]["invalid"] >= 2_500, summary["gcs"]


def test_losing_the_ground_station_in_flight_lands():
    doc = load_mission_file(SQUARE)
    # the station beats at 1 Hz: a loss timeout of 1 s would trip on ordinary jitter
    options = ("--param", "COM_DL_LOSS_T=3", "--param", "NAV_DLL_ACT=5")
    with vehicle(*options, speedup="2") as (gs, autopilot, _):
        gs.upload(doc.items)
        gs.wait_armable()
        gs.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming")
        gs.require(mav.MAV_CMD_MISSION_START, 0, 0, what="mission start")
        gs.wait_for(
            "climbing past 0.5 m",
            lambda m: m.get_type() == "GLOBAL_POSITION_INT" and m.relative_alt > 500,
            30.0,
        )
        # silence: keep listening, stop the heartbeats
        texts = []
        deadline = time.monotonic() + 60.0
        armed = True
        while armed and time.monotonic() < deadline:
            m = gs.conn.recv_match(blocking=True, timeout=0.2)
            if m is not None and m.get_type() == "STATUSTEXT":
                texts.append(m.text)
            if m is not None and m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1:
                armed = bool(m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
        summary = summary_of(autopilot)
    assert any("failsafe: ground station lost: land" in t for t in texts), texts
    assert not armed and summary["landed"]
    assert summary["sim_s"] < 40.0  # landed where it was, not after the whole square


def test_signing_refuses_unsigned_and_survives_a_forged_future_timestamp(tmp_path):
    key_file = tmp_path / "key"
    key_file.write_text("correct horse battery staple\n")
    key = __import__("hashlib").sha256(b"correct horse battery staple").digest()
    with vehicle("--signing-key-file", str(key_file), speedup="1", key=key) as (gs, ap, port):
        beat = gs.wait_for("a heartbeat", lambda m: m.get_type() == "HEARTBEAT", 5.0)
        assert beat._signed  # everything the vehicle sends is signed
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
            arm = mav.MAVLink_command_long_message(1, 1, 400, 0, 1, 21196, 0, 0, 0, 0, 0)
            sock.sendto(arm.pack(unsigned), ("127.0.0.1", port))
            # a forger with the ground station's ids, the wrong key, a far-future timestamp
            forger = mav.MAVLink(None, srcSystem=255, srcComponent=190)
            forger.signing.secret_key = bytes(32)
            forger.signing.sign_outgoing = True
            forger.signing.link_id = 0
            forger.signing.timestamp = gs.conn.mav.signing.timestamp + 10**12
            ping = mav.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)
            sock.sendto(ping.pack(forger), ("127.0.0.1", port))
        with pytest.raises(GroundStationError):  # no answer at all to the unsigned arm
            gs.wait_for("COMMAND_ACK", lambda m: m.get_type() == "COMMAND_ACK", 1.0)
        assert not gs.progress.armed
        gs.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="signed arming")  # not locked out
        gs.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, what="signed disarm")
        ap.terminate()
        summary = summary_of(ap)
    assert summary["gcs"]["rejected"] >= 2
    saved = Path(str(key_file) + ".timestamp")
    assert int(saved.read_text()) > 0  # the timestamp persists beside the key


def test_sitl_takes_off_flies_offboard_and_a_fence_breach_returns_home():
    station = GroundStation("udpin:127.0.0.1:0")
    port = station.conn.port.getsockname()[1]
    sitl = subprocess.Popen(
        [
            *(sys.executable, "-m", "mission.cli", "sitl", "--speedup", "4"),
            *("--params-file", "none", "--out", f"udpout:127.0.0.1:{port}"),
            *("--param", "MIS_TAKEOFF_ALT=1"),  # PX4's default: 2.5 m
            *("--param", "GF_ACTION=3"),  # return (PX4's default: hold)
            *("-L", "47.3977419,8.5455938,488,90"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        start_new_session=True,  # its simulator and autopilot with it, should it hang
    )
    gs = station
    try:
        gs.connect(timeout_s=20.0)
        home = gs.wait_for("HOME_POSITION", lambda m: m.get_type() == "HOME_POSITION", 10.0)
        assert abs(home.latitude - 473977419) <= 1 and abs(home.altitude - 488_000) < 50  # -L
        gs.wait_armable()
        gs.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming")
        gs.require(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, float("nan"), 0, 0, 5.0, what="take-off")
        gs.wait_for(
            "the take-off altitude (MIS_TAKEOFF_ALT, 1 m, not param 7 under PX4)",
            lambda m: m.get_type() == "GLOBAL_POSITION_INT" and 950 < m.relative_alt < 1100,
            30.0,
        )
        # a second take-off in the air is denied, saying why (not left hanging in a mode)
        again = gs.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, float("nan"), 0, 0, 5.0)
        assert again == mav.MAV_RESULT_DENIED
        if not any("already flying" in text for text in gs.progress.texts):
            gs.wait_for(
                "the reason", lambda m: m.get_type() == "STATUSTEXT" and "already" in m.text, 5.0
            )
        # offboard: a stream of setpoints first, then the mode (PX4's rule)
        target_ned = (0.0, 0.6, -1.0)  # 0.6 m east
        for _ in range(5):
            send_target(gs, target_ned)
            gs.receive(0.05)
        gs.require(mav.MAV_CMD_DO_SET_MODE, 1, 6, 0, what="offboard mode")
        deadline = time.monotonic() + 30.0
        east = 0.0
        while time.monotonic() < deadline and abs(east - 0.6) > 0.05:
            send_target(gs, target_ned)
            m = gs.receive(0.05)
            if m is not None and m.get_type() == "LOCAL_POSITION_NED":
                east = m.y
        assert abs(east - 0.6) <= 0.05, east
        # a setpoint it cannot fly is refused, saying why (a frame it does not know)
        gs.conn.mav.set_position_target_local_ned_send(
            0, 1, 1, 12, 0b110111111000, 0, 0, -1, 0, 0, 0, 0, 0, 0, 0, 0
        )
        gs.wait_for(
            "the refusal", lambda m: m.get_type() == "STATUSTEXT" and "frame 12" in m.text, 5.0
        )
        assert gs.set_param("GF_MAX_HOR_DIST", 0.3) == pytest.approx(0.3)  # now outside
        gs.wait_for(
            "return mode after the breach",
            lambda m: m.get_type() == "HEARTBEAT" and m.custom_mode == 0x05040000,
            10.0,
        )
        gs.wait_for("disarm at home", lambda m: gs.progress.was_armed and not gs.progress.armed, 60)
        position = gs.wait_for("position", lambda m: m.get_type() == "LOCAL_POSITION_NED", 5.0)
        assert abs(position.x) < 0.03 and abs(position.y) < 0.03  # landed at home
        assert any("failsafe: geofence" in t for t in gs.progress.texts), gs.progress.texts
        # resting on the ground for 2 s of the vehicle's time is still the one flight
        rested_ms = position.time_boot_ms + 2000
        gs.wait_for(
            "2 s at rest",
            lambda m: m.get_type() == "LOCAL_POSITION_NED" and m.time_boot_ms >= rested_ms,
            30.0,
        )
    finally:
        sitl.send_signal(signal.SIGINT)
        try:
            out, err = sitl.communicate(timeout=30)
        except subprocess.TimeoutExpired:  # never leave it running for the next tests
            os.killpg(sitl.pid, signal.SIGKILL)  # its children end with it (PDEATHSIG)
            out, err = sitl.communicate()
        station.close()
    assert sitl.returncode == 0, err
    assert f"udp 127.0.0.1:{port}" in out and "Ctrl-C" in out
    # one line once arming would be accepted: where ground stations connect, what it claims
    ready = [line for line in out.splitlines() if line.startswith("groundfx sitl: ready:")]
    assert len(ready) == 1, out
    assert f"udpout:127.0.0.1:{port}; px4 identity; signing off" in ready[0], ready
    assert out.strip().splitlines()[-1] == "groundfx sitl: stopped by SIGINT"
    # the autopilot's last words: a table of its flights, each saying how it ended
    assert "groundfx autopilot: stopped; 1 flight, 1 landed" in out, out
    row = next(line for line in out.splitlines() if line.startswith("  1 "))
    assert row.split()[1].startswith("landed"), row  # "landed", or "landed, then stopped"


def send_target(gs: GroundStation, ned: tuple[float, float, float]) -> None:
    ignore_velocity_acceleration_yaw_rate = 0b101111111000
    gs.conn.mav.set_position_target_local_ned_send(
        0, 1, 1, mav.MAV_FRAME_LOCAL_NED, ignore_velocity_acceleration_yaw_rate,
        *ned, 0, 0, 0, 0, 0, 0, float("nan"), 0,
    )  # fmt: skip


def test_a_ground_station_port_in_use_is_refused_naming_what_holds_it():
    """A second vehicle on a port another holds (a second sitl beside a first) must not start
    silently and take its ground-station traffic."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        r = subprocess.run(
            [sys.executable, "-m", "mission.cli", "autopilot", "--sim", "tcp:127.0.0.1:9",
             "--no-record", "--out", f"udpin:127.0.0.1:{port}"],
            capture_output=True, text=True, timeout=120, cwd=REPO,
        )  # fmt: skip
    assert r.returncode == 2, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith(
        f"groundfx autopilot: error: udpin:127.0.0.1:{port}: cannot open port {port}: "
        f"Address already in use (held by pid {os.getpid()}: "
    ), last
