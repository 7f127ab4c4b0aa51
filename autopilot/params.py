"""The parameters a user tunes over MAVLink, with ranges, defaults and a YAML file they persist in.

Each parameter maps to one field of a frozen settings dataclass (controller gains, commander
speeds and altitudes, failsafes, geofence, ground-effect model), whose `param()` metadata
gives its range and meaning: one place for each fact. Names follow PX4 where PX4 has the
setting (MIS_TAKEOFF_ALT, MPC_XY_CRUISE, NAV_DLL_ACT, GF_MAX_VER_DIST...) and GFX_ otherwise.
Values travel as REAL32 and are stored rounded to float32, so the bits sent back are the bits
received.
"""

from __future__ import annotations

import dataclasses
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from autopilot.commander.commander import CommanderParams
from autopilot.commander.failsafes import ACTION_NAMES, FailsafeParams
from autopilot.commander.mission_items import Geofence
from autopilot.control.controller import ControllerParams
from autopilot.control.ground_models import MODEL_NAMES
from autopilot.control.land_detector import LandDetectorParams
from autopilot.estimation.estimator_params import NAMES as ESTIMATOR_NAMES
from autopilot.estimation.estimator_params import EstimatorParams
from autopilot.estimation.sources import SOURCES
from autopilot.estimation.sources import parameter_names as source_parameter_names
from autopilot.identity import identity_defaults
from learner.online.names import METHODS, method_number_doc, method_of_number
from learner.online.settings import OnlineSettings, tuned_in_flight
from simbridge.config import ConfigError, param


@dataclass(frozen=True)
class FenceParams:
    max_altitude_m: float = param(0.0, unit="m", lo=0.0, hi=1000.0, doc="above home (0: off)")
    max_radius_m: float = param(0.0, unit="m", lo=0.0, hi=10000.0, doc="from home (0: off)")


@dataclass(frozen=True)
class ModelParams:
    model: int = param(1, lo=0, hi=2, doc="ground-effect model: 0 none, 1 analytic, 2 neural")
    rho: float = param(1.0, lo=0.01, hi=50.0, doc="rho of the analytic model (equation 3.4)")


@dataclass(frozen=True)
class OnlineSwitches:
    """What a ground station switches on the online learner; the hyperparameters it tunes are
    the GFX_OL_* fields of OnlineSettings (learner/online/settings.py)."""

    method: int = param(0, lo=0, hi=len(METHODS), doc=method_number_doc())
    pause: int = param(0, lo=0, hi=1, doc="1: samples are ignored, the weights stay")
    reset: int = param(0, lo=0, hi=1, doc="1: back to the offline weights (then reads 0 again)")


GROUPS: dict[str, type] = {
    "controller": ControllerParams,
    "commander": CommanderParams,
    "failsafe": FailsafeParams,
    "fence": FenceParams,
    "model": ModelParams,
    "online": OnlineSwitches,
    "online_settings": OnlineSettings,
    "estimator": EstimatorParams,
    **{source.name: source.settings for source in SOURCES.values()},
    "land_detector": LandDetectorParams,
}
# MAVLink name -> (group, field)
NAMES: dict[str, tuple[str, str]] = {
    "GFX_POS_P": ("controller", "position_p"),
    "GFX_POS_D": ("controller", "position_d"),
    "GFX_POS_Z_P": ("controller", "vertical_p"),
    "GFX_POS_Z_D": ("controller", "vertical_d"),
    "GFX_POS_Z_AMAX": ("controller", "vertical_accel_limit_m_s2"),
    "GFX_POS_I": ("controller", "position_i"),
    "GFX_POS_I_MAX": ("controller", "integral_limit_m_s2"),
    "GFX_ATT_P": ("controller", "attitude_p"),
    "GFX_ATT_D": ("controller", "attitude_d"),
    "GFX_YAW_P": ("controller", "yaw_p"),
    "GFX_YAW_D": ("controller", "yaw_d"),
    "MPC_TILTMAX_AIR": ("controller", "max_tilt_deg"),
    "MPC_JERK_MAX": ("controller", "max_jerk_m_s3"),
    "COM_SPOOLUP_TIME": ("commander", "spin_up_s"),
    "MIS_TAKEOFF_ALT": ("commander", "takeoff_altitude_m"),
    "GFX_TKO_ACC_RAD": ("commander", "takeoff_acceptance_m"),
    "NAV_ACC_RAD": ("commander", "acceptance_radius_m"),
    "GFX_WP_TIMEOUT": ("commander", "waypoint_timeout_s"),
    "MPC_XY_CRUISE": ("commander", "cruise_speed_m_s"),
    "MPC_Z_V_AUTO_UP": ("commander", "climb_speed_m_s"),
    "MPC_Z_V_AUTO_DN": ("commander", "descent_speed_m_s"),
    "MPC_LAND_SPEED": ("commander", "land_speed_m_s"),
    "MPC_LAND_ALT1": ("commander", "land_blend_from_m"),
    "MPC_LAND_ALT2": ("commander", "land_slow_below_m"),
    "RTL_RETURN_ALT": ("commander", "return_altitude_m"),
    "GFX_TD_MARGIN": ("commander", "touchdown_margin_m"),
    "GFX_TD_TIME": ("commander", "touchdown_s"),
    "COM_OF_LOSS_T": ("commander", "offboard_timeout_s"),
    "NAV_DLL_ACT": ("failsafe", "gcs_loss_action"),
    "COM_DL_LOSS_T": ("failsafe", "gcs_loss_timeout_s"),
    "GF_ACTION": ("failsafe", "fence_action"),
    "GF_MAX_VER_DIST": ("fence", "max_altitude_m"),
    "GF_MAX_HOR_DIST": ("fence", "max_radius_m"),
    "GFX_GE_MODEL": ("model", "model"),
    "GFX_GE_RHO": ("model", "rho"),
    "GFX_OL_METHOD": ("online", "method"),
    **{name: ("online_settings", field) for name, field in tuned_in_flight().items()},
    "GFX_OL_PAUSE": ("online", "pause"),
    "GFX_OL_RESET": ("online", "reset"),
    **{name: ("estimator", field) for name, field in ESTIMATOR_NAMES.items()},
    **source_parameter_names(),
    "GFX_LND_ALT": ("land_detector", "max_height_m"),
    "LNDMC_Z_VEL_MAX": ("land_detector", "max_climb_rate_m_s"),
    "GFX_LND_LOW_T": ("land_detector", "low_thrust"),
    "GFX_LND_SP_BELOW": ("land_detector", "min_setpoint_below_m"),
    "LNDMC_TRIG_TIME": ("land_detector", "trigger_s"),
    "GFX_LND_SP_FLOOR": ("commander", "landing_floor_m"),
}


@dataclass(frozen=True)
class ParamSpec:
    name: str
    group: str
    field: str
    default: float
    lo: float
    hi: float
    integer: bool
    unit: str
    doc: str


def _specs() -> dict[str, ParamSpec]:
    specs = {}
    for name, (group, field_name) in NAMES.items():
        f = {f.name: f for f in dataclasses.fields(GROUPS[group])}[field_name]
        meta = f.metadata
        specs[name] = ParamSpec(
            name=name,
            group=group,
            field=field_name,
            default=float(f.default),
            lo=float(meta["lo"]),
            hi=float(meta["hi"]),
            integer=isinstance(f.default, int) and not isinstance(f.default, bool),
            unit=meta.get("unit", ""),
            doc=meta.get("doc", ""),
        )
    return specs


SPECS = _specs()
ORDER = tuple(sorted(SPECS))  # param_index order
# Parameters added since recordings carried their flight's parameters, with the value that
# flies as the autopilot did before them (a replay of an older recording sets it): landings
# sank at MPC_LAND_SPEED from any height.
BEFORE_ADDED: dict[str, float] = {"MPC_LAND_ALT1": 100.0, "MPC_LAND_ALT2": 100.0}


def float32(value: float) -> float:
    """`value` as REAL32 carries it."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def check_value(name: str, value: float) -> str | None:
    """Why `value` is refused for parameter `name`, or None."""
    spec = SPECS.get(name)
    if spec is None:
        return f"unknown parameter {name!r}"
    if not math.isfinite(value) or not spec.lo <= value <= spec.hi:
        return f"{name}: {value:g} is outside the allowed range [{spec.lo:g}, {spec.hi:g}]"
    if spec.integer and value != int(value):
        return f"{name}: {value:g} is not a whole number"
    if name in ("NAV_DLL_ACT", "GF_ACTION") and int(value) not in ACTION_NAMES:
        return f"{name}: {value:g} is not one of {sorted(ACTION_NAMES)}"
    return None


class ParamStore:
    """Current values; `path` (YAML, name: value) keeps the ones set across restarts. The
    defaults follow the firmware `identity` claims to be (autopilot/identity.py)."""

    def __init__(
        self,
        path: Path | None,
        overrides: dict[str, float] | None = None,
        identity: str = "px4",
    ) -> None:
        self.path = path
        self.values = {name: float32(spec.default) for name, spec in SPECS.items()}
        self.values.update({k: float32(v) for k, v in identity_defaults(identity).items()})
        self._groups: dict[str, tuple[int, Any]] = {}
        # counts the changes through `set`: the flight loop asks every step whether anything
        # changed, and comparing two dicts of every parameter costs more than the step's maths
        self.version = 0
        self.saved: dict[str, float] = {}
        if path is not None and path.exists():
            self.saved = self._read(path)
            self.values.update(self.saved)
        for name, value in (overrides or {}).items():
            why = check_value(name, value)
            if why is not None:
                raise ConfigError(why)
            self.values[name] = float32(value)

    @staticmethod
    def _read(path: Path) -> dict[str, float]:
        try:
            data = yaml.safe_load(path.read_text()) or {}
        except (OSError, yaml.YAMLError) as e:
            raise ConfigError(f"{path}: cannot read the parameter file: {e}") from None
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: expected a mapping of parameter names to numbers")
        out = {}
        for name, value in data.items():
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"{path}: {name}: expected a number, got {value!r}")
            why = check_value(str(name), float(value))
            if why is not None:
                raise ConfigError(f"{path}: {why}")
            out[str(name)] = float32(float(value))
        return out

    def set(self, name: str, value: float) -> str | None:
        """Set and persist; returns why it was refused, or None."""
        why = check_value(name, value)
        if why is not None:
            return why
        self.values[name] = float32(value)
        self.version += 1
        if self.path is not None:
            self.saved[name] = self.values[name]
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(self.path.suffix + ".tmp")
            tmp.write_text(yaml.safe_dump(dict(sorted(self.saved.items()))))
            tmp.replace(self.path)  # atomic: a crash never leaves half a file
        return None

    def group(self, group: str) -> Any:
        """The settings dataclass of `group` with the current values (built again only when
        a value changed: the flight loop asks for some every step)."""
        cached = self._groups.get(group)
        if cached is not None and cached[0] == self.version:
            return cached[1]
        settings = self._build(group)
        self._groups[group] = (self.version, settings)
        return settings

    def _build(self, group: str) -> Any:
        cls = GROUPS[group]
        values: dict[str, Any] = {}
        for name, (g, field_name) in NAMES.items():
            if g == group:
                value = self.values[name]
                values[field_name] = int(value) if SPECS[name].integer else value
        return cls(**values)

    def controller(self) -> ControllerParams:
        return self.group("controller")

    def commander(self) -> CommanderParams:
        return self.group("commander")

    def failsafe(self) -> FailsafeParams:
        return self.group("failsafe")

    def geofence(self) -> Geofence:
        fence = self.group("fence")
        return Geofence(fence.max_altitude_m, fence.max_radius_m)

    def land_detector(self) -> LandDetectorParams:
        return self.group("land_detector")

    def estimator(self) -> EstimatorParams:
        """The estimator's parameters with each declared source's."""
        sources = {name: self.group(name) for name in SOURCES}
        return dataclasses.replace(self.group("estimator"), sources=sources)

    def online(self) -> OnlineSwitches:
        return self.group("online")

    def online_settings(self) -> OnlineSettings | None:
        """The online method and hyperparameters the parameters ask for; None when off."""
        method = method_of_number(self.online().method)
        if method is None:
            return None
        return dataclasses.replace(self.group("online_settings"), method=method)

    def model(self) -> tuple[str, float]:
        chosen = self.group("model")
        return MODEL_NAMES[chosen.model], chosen.rho
