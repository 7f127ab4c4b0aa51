"""A sensor is declared once: a simulator declaration (rate, noise, sampler and packer) and an
autopilot declaration (reader, fusion, parameters, sensor set), naming each other by the
sensor's name. A toy sensor added through its two declarations alone is sampled and sent at
its rate, read and fused by the estimator, and its parameters join the parameter table."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from tests.helpers import REPO

TOY_SIM = '''
"""A toy velocity sensor: the world-frame velocity, as VISION_SPEED_ESTIMATE (NED)."""

from dataclasses import dataclass

from simbridge.config import param
from simbridge.frames import enu_to_ned
from simbridge.sensors import SimSensor, mavlink, register


@dataclass(frozen=True)
class ToyNoise:
    toy_velocity_m_s: float = param(0.01, unit="m/s", lo=0.0, hi=1.0, doc="per axis")


class ToyVelocity:
    history_steps = 0

    def __init__(self, ctx):
        self.ctx = ctx
        self._pack = ctx.packer(mavlink.MAVLink_vision_speed_estimate_message)

    def __call__(self, time_us):
        s = self.ctx.delayed(self.ctx.state_delay)
        errors = self.ctx.errors
        v = enu_to_ned(errors.vector(s.velocity_m_s, errors.noise.toy_velocity_m_s))
        return [(self._pack, (time_us, v[0], v[1], v[2], [0.0] * 9, 0))]


register(SimSensor(
    name="toy_velocity",
    rate_key="toy_velocity_hz",
    rate_hz=20.0,
    doc="VISION_SPEED_ESTIMATE, a toy velocity sensor",
    sampler=ToyVelocity,
    noise=ToyNoise,
))
'''

TOY_AUTOPILOT = '''
"""The toy velocity sensor's fusion: a world-frame velocity."""

from dataclasses import dataclass

import numpy as np

from autopilot.estimation import estimator as ekf
from autopilot.estimation.sources import Source, register
from simbridge.config import param
from simbridge.frames import ned_to_enu


@dataclass(frozen=True)
class ToyParams:
    ctrl: int = param(1, lo=0, hi=1, doc="toy velocity: 1 fused")
    noise_m_s: float = param(0.05, unit="m/s", lo=0.001, hi=10.0, doc="velocity sd")


def fuse(nav, step, imu, s, t):
    if not s.ctrl or "VISION_SPEED_ESTIMATE" not in step.new:
        return
    m = step.latest["VISION_SPEED_ESTIMATE"]
    nav.seen("toy velocity", t)
    v = np.array(ned_to_enu((m["x"], m["y"], m["z"])))
    nav.fuse("toy velocity", ekf.fuse_velocity(nav.estimate, v, s.noise_m_s, nav.params.gate_sd))


register(Source(
    name="toy",
    label="toy velocity",
    sensor="toy_velocity",
    settings=ToyParams,
    names={"GFX_TOY_CTRL": "ctrl", "GFX_TOY_NOISE": "noise_m_s"},
    fuse=fuse,
    switch="GFX_TOY_CTRL",
    sets={"toy": {"GFX_TOY_CTRL": 1, "EKF2_EV_CTRL": 11, "EKF2_HGT_REF": 3}},
))
'''


def test_a_toy_sensor_declared_twice_is_sampled_at_its_rate_fused_and_tuned(tmp_path):
    (tmp_path / "toy_sim.py").write_text(textwrap.dedent(TOY_SIM))
    (tmp_path / "toy_autopilot.py").write_text(textwrap.dedent(TOY_AUTOPILOT))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), env.get("PYTHONPATH")]))
    env["GROUNDFX_SIM_SENSORS"] = "toy_sim"
    env["GROUNDFX_AUTOPILOT_SENSORS"] = "toy_autopilot"
    # the world file sets the toy's rate and noise by the names its declaration gives them
    world = (REPO / "simbridge" / "worlds" / "default.yaml").read_text()
    world += "sensors: {toy_velocity_hz: 25.0}\nsensor_noise: {toy_velocity_m_s: 0.02}\n"
    (tmp_path / "toy_world.yaml").write_text(world)
    flight = subprocess.run(
        [
            sys.executable, "-m", "mission.cli", "fly", "mission/examples/low_hover.yaml",
            "--world", str(tmp_path / "toy_world.yaml"),
            "--sensors", "toy",  # the command line offers the toy's sensor set
            "--param", "GFX_TOY_NOISE=0.1",  # refused unless in the parameter table
            "--no-record", "--json",
        ],
        capture_output=True, text=True, timeout=300, cwd=REPO, env=env,
    )  # fmt: skip
    assert flight.returncode == 0, flight.stderr
    summary = json.loads(flight.stdout)
    assert summary["landed"], summary.get("ended")
    fused = summary["estimator_fused"].get("toy velocity", 0)
    rejected = summary["estimator_rejected"].get("toy velocity", 0)
    # sent at the world's 25 Hz (the flight aligns on its first step), read and fused
    expected = 25.0 * summary["sim_s"]
    assert 0.9 * expected <= fused + rejected <= expected + 2
    assert fused >= 0.9 * (fused + rejected)
    assert summary["estimator_fused"]["motion capture"] > 0  # the rest of the set flies on


def test_the_packaged_sensor_sets_and_declarations_name_each_other():
    from autopilot.estimation.sources import SOURCES, sensor_sets
    from autopilot.params import SPECS
    from simbridge.sensors import SENSORS

    assert sensor_sets() == {
        "mocap": {"EKF2_EV_CTRL": 11, "EKF2_GPS_CTRL": 0, "EKF2_OF_CTRL": 1, "EKF2_HGT_REF": 3},
        "gps": {"EKF2_EV_CTRL": 0, "EKF2_GPS_CTRL": 7, "EKF2_OF_CTRL": 0, "EKF2_HGT_REF": 0},
        "flow": {"EKF2_EV_CTRL": 0, "EKF2_GPS_CTRL": 0, "EKF2_OF_CTRL": 1, "EKF2_HGT_REF": 2},
    }
    for source in SOURCES.values():
        assert source.sensor == "imu" or source.sensor in SENSORS, source.name
        assert set(source.names) <= set(SPECS), source.name
