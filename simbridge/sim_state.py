"""What the simulator reports of one vehicle after a step: its true state and the true forces
of the world's effects (`simbridge.physics` fills them; the HIL encoder sends them)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from simbridge.frames import Mat3, Quat, Vec3, quat_to_matrix
from simbridge.rotors import Quad

T = TypeVar("T")


class _ComputedOnce(Generic[T]):
    """A value computed at its first reading and kept in the instance: functools'
    cached_property without the lock it takes at every first reading (Python 3.11), half
    its cost, for a state made at every step and read by one thread."""

    def __init__(self, compute: Callable[[Any], T]) -> None:
        self._compute, self._name = compute, compute.__name__
        self.__doc__ = compute.__doc__

    def __get__(self, obj: Any, owner: type | None = None) -> T:
        if obj is None:
            return self  # type: ignore[return-value]  # the descriptor, read on the class
        value = obj.__dict__[self._name] = self._compute(obj)
        return value


@dataclass(frozen=True)
class VehicleState:
    """The true state after a control step (world x east, y north, z up; body FLU)."""

    time_s: float
    position_m: Vec3
    quaternion: Quat  # (w, x, y, z), body to world
    velocity_m_s: Vec3  # world frame
    angular_velocity_body_rad_s: Vec3  # body frame
    acceleration_m_s2: Vec3  # world frame, mean over the last control period
    rotor_speeds_rad_s: Quad  # actual (after motor lag)
    range_m: float  # downward range sensor: distance along body -z to a surface, inf if none

    @_ComputedOnce
    def rotation(self) -> Mat3:
        """The quaternion as a rotation matrix (row-major, body to world), computed once: the
        HIL encoder turns several of a step's vectors by it."""
        return quat_to_matrix(self.quaternion)


@dataclass(frozen=True)
class EffectForces:
    """The true effect forces of the last physics step, world frame unless stated."""

    rotor_heights_m: Quad  # height of each rotor above the surface below it (inf: none)
    ground_effect_rotor_n: Quad  # equation 3.4 per rotor, vertical
    ground_effect_n: Vec3
    ceiling_effect_n: Vec3
    wall_effect_n: Vec3
    drag_n: Vec3  # rotor drag + body drag
    wind_m_s: Vec3
    learned_n: Vec3 = (0.0, 0.0, 0.0)  # a gap diagnosis's learnt residual
    # outside the catalogue (simbridge/effects/uncatalogued.py)
    ground_effect_exponential_n: Vec3 = (0.0, 0.0, 0.0)
    outwash_n: Vec3 = (0.0, 0.0, 0.0)
    thrust_scale: float = 1.0  # thrust_decay's C_T scale
    declared_n: tuple[tuple[str, Vec3], ...] = ()  # each effect declared with its own force
