"""What the estimator's predictions alone moved and turned, step by step: a measurement
captured in the past (motion capture 12 ms late, a GPS fix) is compared with the filter as
it was at its capture time, and its correction applied to the present state (PX4's EKF2
fuses delayed measurements against its buffered states the same way)."""

from __future__ import annotations

from collections import deque

from autopilot.estimation import estimator as ekf
from autopilot.estimation.attitude import rotation_vector_floats
from simbridge.frames import Quat, Vec3, quat_conjugate, quat_multiply, quat_normalize


class PredictionHistory:
    """(time, displacement sum, rotation product) of the last `steps` predictions, in Python
    floats: they change every control step, and small arrays cost more than their sums."""

    def __init__(self, steps: int) -> None:
        self._entries: deque[tuple[int, Vec3, Quat]] = deque(maxlen=steps)
        self._moved: Vec3 = (0.0, 0.0, 0.0)
        self._turned: Quat = (1.0, 0.0, 0.0, 0.0)

    def record(self, time_us: int) -> None:
        self._entries.append((time_us, self._moved, self._turned))

    def advance(
        self, before: ekf.Estimate, predicted: ekf.Estimate, dt: float, time_us: int
    ) -> None:
        """Add what one prediction (from `before` to `predicted`, over `dt`) moved and turned,
        and record it at `time_us`, the IMU sample's time."""
        mx, my, mz = self._moved
        px, py, pz = predicted.position_m.tolist()
        bx, by, bz = before.position_m.tolist()
        self._moved = (mx + (px - bx), my + (py - by), mz + (pz - bz))
        wx, wy, wz = predicted.angular_velocity_body_rad_s.tolist()
        turn = rotation_vector_floats(wx * dt, wy * dt, wz * dt)
        self._turned = quat_normalize(quat_multiply(self._turned, turn))
        self.record(time_us)

    def at_capture(self, estimate: ekf.Estimate, capture_us: int) -> tuple[Vec3, Quat]:
        """The filter's position and attitude at `capture_us`, in floats: `estimate` less
        what the predictions moved and turned since (the oldest recorded, if it is older
        still)."""
        then = self._entries[0]
        for entry in reversed(self._entries):
            if entry[0] <= capture_us:
                then = entry
                break
        now = self._entries[-1]
        px, py, pz = estimate.position_m.tolist()
        (nx, ny, nz), (tx, ty, tz) = now[1], then[1]
        position = (px - (nx - tx), py - (ny - ty), pz - (nz - tz))
        back = quat_multiply(quat_conjugate(now[2]), then[2])
        return position, quat_multiply(tuple(estimate.quaternion.tolist()), back)
