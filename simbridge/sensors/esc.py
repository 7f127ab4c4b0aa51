"""ESC_TELEMETRY_1_TO_4: the rotors' actual speeds (so motor lag is observable)."""

from __future__ import annotations

import math

from simbridge.sensors import Frame, SensorContext, SimSensor, mavlink, register

RAD_S_TO_RPM = 60.0 / (2.0 * math.pi)


class Esc:
    history_steps = 0

    def __init__(self, ctx: SensorContext) -> None:
        self.ctx = ctx
        self._pack = ctx.packer(mavlink.MAVLink_esc_telemetry_1_to_4_message)

    def __call__(self, time_us: int) -> list[Frame]:
        s = self.ctx.delayed(0)  # the rotors now: no delay line
        rpm = [min(65535, round(n * RAD_S_TO_RPM)) for n in s.rotor_speeds_rad_s]
        count = self.ctx.steps & 0xFFFF
        return [(self._pack, ([0] * 4, [0] * 4, [0] * 4, [0] * 4, rpm, [count] * 4))]


register(SimSensor(
    name="esc",
    rate_key="esc_hz",
    rate_hz=125.0,
    doc="ESC_TELEMETRY_1_TO_4",
    sampler=Esc,
))  # fmt: skip
