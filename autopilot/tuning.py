"""The settings the flight loop derives from the parameters, rebuilt only when one changes."""

from __future__ import annotations

from pathlib import Path

from autopilot.control.ground_models import GroundEffectModel, make_model
from autopilot.params import ParamStore
from simbridge.vehicle import Vehicle


class Tuning:
    """The controller's, commander's and land detector's parameters, the speed limits' leads
    and the ground-effect model, as of the parameters' `version`."""

    def __init__(self, params: ParamStore, vehicle: Vehicle, network: str | Path | None) -> None:
        self.params = params
        self.vehicle = vehicle
        self.network = network  # the neural model's weights (None: by rho)
        self.version = -1  # the parameters' version these settings were built from
        self.model_key: tuple[str, float] | None = None
        self.model: GroundEffectModel | None = None
        self.refresh()

    def refresh(self) -> bool:
        """Rebuild what a parameter change touched; True if anything changed."""
        store = self.params
        if store.version == self.version:
            return False
        self.version = store.version
        self.controller = store.controller()
        self.commander = store.commander()
        self.land_detector = store.land_detector()
        gains = self.controller
        # the speed limits' lead: steady speed = error * a0 / a1 (commander.limited_setpoint)
        self.lead_s = gains.position_d / gains.position_p if gains.position_p > 0 else 2.0
        self.vertical_lead_s = gains.vertical_d / gains.vertical_p if gains.vertical_p > 0 else 2.0
        key = store.model()
        if key != self.model_key:
            self.model_key = key
            self.model = make_model(key[0], self.vehicle, key[1], self.network)
        return True
