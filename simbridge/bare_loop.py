"""The physics reference of `groundfx bench sim`: the simulator's body stepped by a bare
quadrotor loop in PyBullet, doing per physics step only what any PyBullet quadrotor does (read
pose and velocity, apply the four rotor thrusts at their hubs and the yaw moment, step), as
gym-pybullet-drones' `_physics` does. The thrusts hold the weight: no effect, no control."""

from __future__ import annotations

from simbridge.physics import Simulation
from simbridge.pybullet_quiet import pybullet as pb
from simbridge.vehicle import Vehicle


class BareQuadrotor:
    """`sim`'s body (released from its stand) under a bare loop; `sim` must stay open."""

    def __init__(self, sim: Simulation, vehicle: Vehicle) -> None:
        sim.release()
        self._cid, self._body = sim._cid, sim._body
        self._thrust = [0.0, 0.0, vehicle.weight_n / 4.0]
        self._hubs = vehicle.rotor_positions_body_m()

    def run(self, steps: int) -> None:
        """`steps` physics steps, the loop inline (its figure is the loop's, not calls')."""
        cid, body, thrust, hubs = self._cid, self._body, self._thrust, self._hubs
        no_moment = [0.0, 0.0, 0.0]
        for _ in range(steps):
            pb.getBasePositionAndOrientation(body, physicsClientId=cid)
            pb.getBaseVelocity(body, physicsClientId=cid)
            for hub in hubs:
                pb.applyExternalForce(body, -1, thrust, hub, pb.LINK_FRAME, physicsClientId=cid)
            pb.applyExternalTorque(body, -1, no_moment, pb.LINK_FRAME, physicsClientId=cid)
            pb.stepSimulation(physicsClientId=cid)
