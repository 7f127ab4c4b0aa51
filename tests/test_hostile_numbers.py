"""Numbers and names from outside, refused with a reason, over loopback with a real pymavlink
ground station: NaN and inf in every mission item form and coordinate, and a flood of
PARAM_SETs naming no parameter (explained once a while, not once per message), go-to
targets with infinity or half a position."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav

from mission.gcs_client import GroundStation
from tests.test_gcs import ORIGIN, vehicle

MISSION = mav.MAV_MISSION_TYPE_MISSION
LAT, LON = ORIGIN.lat_deg, ORIGIN.lon_deg
NAN, INF = math.nan, math.inf


def legacy(seq: int, command: int, *params: float, x: float, y: float, z: float) -> Callable:
    """A MISSION_ITEM (degrees as floats), as old ground stations and scripts send it."""
    return lambda gs: gs.conn.mav.mission_item_send(
        1, 1, seq, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, command, 0, 1, *params, x, y, z, MISSION
    )


def integer(seq: int, command: int, *params: float, x: int, y: int, z: float) -> Callable:
    """A MISSION_ITEM_INT (degE7)."""
    return lambda gs: gs.conn.mav.mission_item_int_send(
        1, 1, seq, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, command, 0, 1, *params, x, y, z, MISSION
    )


def upload(gs: GroundStation, items: list[Callable]) -> Any:
    """Answer the vehicle's requests with `items`; its MISSION_ACK."""
    gs.conn.mav.mission_count_send(1, 1, len(items), MISSION)
    while True:
        m = gs.wait_for(
            "MISSION_REQUEST_INT or MISSION_ACK",
            lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_ACK"),
            timeout_s=10.0,
        )
        if m.get_type() == "MISSION_ACK":
            return m
        items[m.seq](gs)


def said_since(gs: GroundStation, n: int, texts: list[str]) -> None:
    """Until the vehicle's STATUSTEXTs after the first `n` are `texts`."""
    gs.wait_for("the reason", lambda m: gs.progress.texts[n:] == texts, timeout_s=10.0)


WP, TAKEOFF = mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_TAKEOFF
BAD_ITEMS = [
    # (the second item, the MISSION_ACK's result, the reason's words)
    (legacy(1, WP, 0, 0.5, 0, NAN, x=NAN, y=LON, z=1.0), "INVALID_PARAM5_X", "x: nan"),
    (legacy(1, WP, 0, 0.5, 0, NAN, x=LAT, y=NAN, z=1.0), "INVALID_PARAM6_Y", "y: nan"),
    (legacy(1, WP, 0, 0.5, 0, NAN, x=INF, y=LON, z=1.0), "INVALID_PARAM5_X", "x: inf"),
    (legacy(1, WP, 0, 0.5, 0, NAN, x=LAT, y=-INF, z=1.0), "INVALID_PARAM6_Y", "y: -inf"),
    (legacy(1, WP, 0, 0.5, 0, NAN, x=LAT, y=LON, z=INF), "INVALID_PARAM7", "z: inf"),
    (integer(1, WP, 0, 0.5, INF, NAN, x=round(LAT * 1e7), y=round(LON * 1e7), z=1.0),
     "INVALID_PARAM3", "param3: inf"),
    (integer(1, WP, 0, 0.5, 0, -INF, x=round(LAT * 1e7), y=round(LON * 1e7), z=1.0),
     "INVALID_PARAM4", "param4: -inf"),
    (integer(1, WP, 0, 0.5, 0, NAN, x=round(LAT * 1e7), y=round(LON * 1e7), z=NAN),
     "INVALID_PARAM7", "z: nan"),
]  # fmt: skip


def test_nan_and_inf_are_refused_in_every_item_form_and_coordinate():
    takeoff = legacy(0, TAKEOFF, 0, 0, 0, NAN, x=LAT, y=LON, z=1.0)
    with vehicle(speedup="1") as (gs, _, _):
        for bad, result, words in BAD_ITEMS:
            said = len(gs.progress.texts)
            ack = upload(gs, [takeoff, bad])
            assert mav.enums["MAV_MISSION_RESULT"][ack.type].name == f"MAV_MISSION_{result}"
            refused = [f"mission refused: item 1 (NAV_WAYPOINT): {words} is not a finite number"]
            said_since(gs, said, refused)
        assert gs.download() == ()  # nothing of it was taken
        # the same items with numbers in them are flown
        good = legacy(1, WP, 0, 0.5, 0, NAN, x=LAT, y=LON, z=1.0)
        ack = upload(gs, [takeoff, good])
        assert ack.type == mav.MAV_MISSION_ACCEPTED
        assert len(gs.download()) == 2


BAD_GO_TO = [
    # DO_REPOSITION (p5 latitude, p6 longitude, p7 altitude MSL; NaN: here) and the reason
    ((INF, LON, 30.0), "latitude inf"),
    ((LAT, -INF, 30.0), "longitude -inf"),
    ((LAT, LON, INF), "altitude inf"),
    ((NAN, LON, 30.0), "latitude and longitude both, or both NaN"),
]


def test_a_go_to_with_infinity_or_half_a_position_is_refused_saying_why():
    with vehicle(speedup="1") as (gs, _, _):
        for (lat, lon, alt), words in BAD_GO_TO:
            said = len(gs.progress.texts)
            result = gs.command(mav.MAV_CMD_DO_REPOSITION, -1, 1, 0, NAN, lat, lon, alt)
            assert result == mav.MAV_RESULT_DENIED, (lat, lon, alt)
            gs.wait_for("the reason", lambda m, n=said: len(gs.progress.texts) > n, timeout_s=10.0)
            assert words in gs.progress.texts[said], gs.progress.texts[said:]


@pytest.mark.parametrize("flood", [500])
def test_a_flood_of_unknown_parameter_names_is_explained_once_a_while(flood):
    with vehicle(speedup="1") as (gs, _, _):
        started = time.monotonic()
        for k in range(flood):
            gs.conn.mav.param_set_send(
                1, 1, f"NO_SUCH_{k}".encode(), 1.0, mav.MAV_PARAM_TYPE_REAL32
            )
        # answered after every one of them: what they caused has arrived
        assert gs.set_param("MIS_TAKEOFF_ALT", 1.5) == 1.5
        flood_s = time.monotonic() - started
        unknown = [t for t in gs.progress.texts if t.startswith("unknown parameter")]
        # one per 5 s while the flood lasts (however long a busy machine makes it), not 500
        assert 1 <= len(unknown) <= 2 + flood_s // 5.0, (unknown, flood_s)
        assert unknown[0] == "unknown parameter NO_SUCH_0"
        # a refusal of another kind is still explained at once
        assert gs.set_param("MPC_XY_CRUISE", 1000.0) == 0.5
        gs.wait_for(
            "the range refusal",
            lambda m: any("outside the allowed range" in t for t in gs.progress.texts),
            timeout_s=10.0,
        )
