"""The simulator's sensors besides the IMU, each declared once: its name, its rate, its noise
and the sampler that measures the vehicle and packs the HIL message(s) it sends.

A declaration names the sensor; the autopilot's declaration of the same name
(`autopilot.estimation.sources`) reads and fuses what it sends. The world's `sensors:` section
takes each declared rate by its `rate_key`, its `sensor_noise:` section each declared noise
field (`simbridge.sensor_noise`); the HIL encoder samples each sensor at its rate, in
the order of `SENSORS` (the order the sensor errors are drawn in: a seed gives one flight).
Sensors outside this package are declared by modules named in GROUNDFX_SIM_SENSORS
(comma-separated), imported here; each calls `register`.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: F401 (the sensors pack with it)

if TYPE_CHECKING:
    from simbridge.sim_state import VehicleState
    from simbridge.vehicle import Vehicle
    from simbridge.wire import WirePacker

Frame = tuple["WirePacker", tuple]  # a message's packer and its fields, packed later
PLUGINS_ENV = "GROUNDFX_SIM_SENSORS"


class SensorContext(Protocol):
    """What the HIL encoder offers a sampler: the flight's world, vehicle and errors, the
    delayed states, and the frames' units."""

    world: Any  # simbridge.world.World (which reads the declarations: no import back)
    vehicle: Vehicle
    errors: Any  # simbridge.sensor_noise.SensorErrors (the same)
    state_delay: int  # the state's latency, in control steps
    period_us: int

    @property
    def steps(self) -> int: ...  # control steps encoded before this one

    def packer(self, message_class: Any) -> WirePacker: ...

    def delayed(self, steps: int) -> VehicleState: ...  # the state `steps` steps ago

    def position(self, s: VehicleState) -> tuple[float, float, float]: ...  # biased

    def geodetic(self, position_m: tuple[float, float, float]) -> tuple[int, int, int]: ...


class Sampler(Protocol):
    """One flight's sensor: `history_steps` states back it may ask for; called at each step
    its rate is due, returns its messages."""

    history_steps: int

    def __call__(self, time_us: int) -> list[Frame]: ...


@dataclass(frozen=True)
class SimSensor:
    name: str  # the autopilot's declaration of the same name fuses it
    rate_key: str  # its rate's field in the world file's `sensors:` section
    rate_hz: float  # the rate when the world file gives none; 0: off
    doc: str  # what it sends, for the world file's reference
    sampler: Callable[[SensorContext], Sampler]  # made once per flight
    # a frozen dataclass of its error figures (`param()` fields, names unique across the
    # sensors), read by the sampler from `SensorErrors.noise`; None: it does not err
    noise: type | None = None


SENSORS: dict[str, SimSensor] = {}


def register(sensor: SimSensor) -> SimSensor:
    """Adds `sensor`, sampled after those registered before it."""
    if sensor.name in SENSORS:
        raise ValueError(f"sensor {sensor.name!r} is declared twice")
    SENSORS[sensor.name] = sensor
    return sensor


def int16(v: float) -> int:
    r = round(v)  # a comparison instead of min and max: a few a step
    return r if -32767 <= r <= 32767 else (32767 if r > 0 else -32767)


def _load() -> None:
    # the packaged sensors first, in the order their errors are drawn
    for name in ("odometry", "distance", "esc", "gps"):
        importlib.import_module(f"simbridge.sensors.{name}")
    for module in filter(None, os.environ.get(PLUGINS_ENV, "").split(",")):
        importlib.import_module(module.strip())


_load()
