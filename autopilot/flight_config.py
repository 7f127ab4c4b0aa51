"""What the flight loop is given (the vehicle, its parameters, the links, the callbacks of
whoever runs it) and what it gives back."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from autopilot.commander.mission_items import MissionItem
from autopilot.gcs.signing import Signing
from autopilot.online.online_control import OnlineOptions
from autopilot.params import ParamStore
from autopilot.recording.record_options import RecordOptions
from autopilot.request import DEFAULT_MAX_FLIGHT_S
from autopilot.simlink import DEFAULT_LINK_TIMEOUT_S
from autopilot.types import FlightState, Step
from simbridge.rotors import Quad
from simbridge.vehicle import Vehicle


@dataclass(frozen=True)
class AutopilotConfig:
    sim_url: str
    vehicle: Vehicle
    params: ParamStore
    origin: tuple[float, float, float]  # lat deg, lon deg, alt m of the local frame's origin
    network: str | Path | None = None  # the neural model's weights (default: by rho)
    mission: tuple[MissionItem, ...] = ()  # loaded before any ground station speaks
    auto_start: bool = False  # arm and start the mission without a ground station
    exit_after_landing: bool = True  # end once a flight has landed and settled
    identity: str = "px4"
    gcs_urls: tuple[str, ...] = ()
    signing: Signing | None = None
    link_timeout_s: float = DEFAULT_LINK_TIMEOUT_S  # silence that ends the flight
    settle_after_landing_s: float = 0.5  # keep logging after disarm, to see any bounce
    max_flight_s: float = DEFAULT_MAX_FLIGHT_S
    should_stop: Callable[[], bool] = lambda: False  # a signal asked the loop to end
    on_event: Callable[[float, str], None] | None = None  # modes, arming, failsafes
    # told once, when arming would first be accepted: the ground-station link's description
    on_ready: Callable[[str], None] | None = None
    record_hz: float = 0.0  # > 0: record learning samples at this rate (thesis: 100 Hz)
    stop_after_samples: int | None = None  # end the flight once this many are recorded
    on_sample: Callable[[int], None] | None = None  # told the count of recorded samples
    # told each airborne step (t, messages, the true state as a lab's motion capture would log
    # it, rotor speeds applied over the last period): the --flight-log of the gap diagnosis
    on_step: Callable[[float, Step, FlightState, Quad], None] | None = None
    online: OnlineOptions = OnlineOptions()  # online learning (GFX_OL_METHOD turns it on)
    record: RecordOptions | None = None  # the flight's rerun recording; None: off


@dataclass
class Flight:
    log: np.ndarray
    summary: dict[str, Any]
    ended: str  # "landed", "enough samples", "mission time limit", or the lost link's reason
    samples: np.ndarray | None = None  # learning samples, columns learner.dataset.COLUMNS
