"""The flight loop's side of online learning: parameters in, samples to the learner, the
current snapshot into the neural model.

The GFX_OL_* parameters choose the method (autopilot/params.py) and its hyperparameters
(learner/online/settings.py) and may change in flight; GFX_OL_PAUSE pauses, GFX_OL_RESET = 1
resets to the offline weights (and reads 0 again). Learning needs the neural model: with
another one it stays idle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from autopilot.commander.commander import Phase
from autopilot.control.ground_models import GroundEffectModel, default_network
from autopilot.online.alternation import Alternation
from autopilot.params import ParamStore
from learner.dataset import COLUMNS, FEATURES, TARGETS
from learner.online.memory import Memory, load_memory, memory_path_for, offline_path_for
from learner.online.names import NEEDS_BASIS, NEEDS_MEMORY
from simbridge.config import ConfigError
from simbridge.frames import Vec3

# torch, and the learner with it, load only when learning is on: a flight without learning
# connects to the simulator without waiting for them
SAMPLE_HZ = 100.0  # thesis: samples at 100 Hz, an update per 64 (about 1.6 per second)
# (sim time, loss, version, the update's verdict, the ground in use): as online_learner.Report
Report = Callable[[float, float | None, int, str, str | None], None]

_NAMES = list(COLUMNS)
FEATURE_COLUMNS = np.array([_NAMES.index(f) for f in FEATURES])
TARGET_COLUMNS = np.array([_NAMES.index(t) for t in TARGETS])
VELOCITY_COLUMNS = np.array([_NAMES.index(v) for v in ("vx", "vy", "vz")])


@dataclass(frozen=True)
class OnlineOptions:
    deterministic: bool = True  # updates inside the control step: same sim times every run
    save_path: Path | None = None  # the adapted model at the end of the flight
    on_report: Report | None = None  # per update: the recorder
    alternate_s: float | None = None  # the learner works and rests in turns this long


def find_memory(network: str | Path | None, rho: float) -> Memory | None:
    """The stored offline samples beside the model file, if there are any."""
    from learner.model import resolve_model_path

    path = memory_path_for(resolve_model_path(network or default_network(rho)))
    return load_memory(path) if path.exists() else None


def find_offline(network: str | Path | None, rho: float, net: Any) -> Any:
    """The offline weights an adapted model came from (NAME.offline.npz beside it), or None
    for a model trained offline (it is its own anchor)."""
    from learner.model import load_model, resolve_model_path

    if "online" not in net.header:
        return None
    path = offline_path_for(resolve_model_path(network or default_network(rho)))
    if not path.exists():
        raise ConfigError(
            f"{path.name} is missing: an adapted model needs the offline weights it came from "
            "beside it (written by --save-model)"
        )
    return load_model(path)


HOLDING_M_S = 1e-3  # a setpoint moving slower than this holds still


def vertical_tracking_error(state: Any, setpoint: Any) -> float:
    """The position loop's vertical composite error s = (v_z - v_dz) + Lambda (z - z_d) [m/s]
    (Neural-Fly's s, Lambda 1/s), for `composite`'s tracking term; 0 without a setpoint or
    while it moves: a slow position loop lags a moving setpoint by centimetres, which is the
    loop's doing, not the model's (only a held setpoint's error is a model error)."""
    if setpoint is None or max(abs(v) for v in setpoint.velocity_m_s) > HOLDING_M_S:
        return 0.0
    from learner.online.composite_session import LAMBDA_PER_S

    dz = state.position_m[2] - setpoint.position_m[2]
    return (state.velocity_m_s[2] - setpoint.velocity_m_s[2]) + LAMBDA_PER_S * dz


def at_setpoint_velocity(hold_velocity: bool, phase: Phase) -> bool:
    """Whether the model is given (and, with `composite`, learns at) the setpoint's velocity
    this step rather than the estimate's (the thesis's state): while holding, when
    `hold_velocity`.

    The true effect depends on height and thrust (equation 3.4), but a basis trained on
    flights near the ground can still move with vertical velocity there, where its data barely
    move (a few cm/s in a 3 cm hold). `composite` adapts only the last layer, so that slope
    stays; fed the estimate, it acts on the vertical loop as a derivative gain beside the
    controller's, in proportion to the effect, and the learner judges the model at velocities
    the hold's noise and settling make. Given the setpoint's velocity while holding, the model
    is served and learnt as the controller uses it; elsewhere (take-off, descents) the
    velocity tells the network the flight's phase, and the estimate stays.
    """
    return hold_velocity and phase == Phase.HOLDING


class OnlineControl:
    def __init__(
        self, options: OnlineOptions, params: ParamStore, network: str | Path | None
    ) -> None:
        self.options = options
        self.params = params
        self.network = network
        self.learner: Any = None  # autopilot.online.online_learner.OnlineLearner, once learning
        self.active = False
        self.errors: list[str] = []
        self.hold_velocity = False  # composite's GFX_OL_HOLD_V, while it learns
        self.velocity_m_s: Vec3 | None = None  # the setpoint's, when the model was last given it
        self.resting = False  # the learner's turn to rest (`alternate_s`): no samples taken
        self.alternation = (
            Alternation(options.alternate_s) if options.alternate_s is not None else None
        )
        settings = params.online_settings()
        needs_memory = settings is not None and settings.method in NEEDS_MEMORY
        # refuse at the start, not in flight: the memory must exist
        if needs_memory and find_memory(network, params.model()[1]) is None:
            assert settings is not None
            raise ConfigError(
                f"--online {settings.method}: needs stored offline samples beside the "
                "network (NAME.memory.npz; make one with groundfx learn memory)"
            )
        if settings is not None and params.model()[0] == "neural":
            from learner.model import load_model

            rho = params.model()[1]
            net = load_model(network or default_network(rho))
            find_offline(network, rho, net)
            if settings.method in NEEDS_BASIS and not net.header.get("basis"):
                raise ConfigError(
                    f"--online {settings.method}: needs a model trained over several grounds "
                    "(--network grounds; make one with groundfx learn basis)"
                )

    @property
    def sample_hz(self) -> float:
        return SAMPLE_HZ if self.active and not self.resting else 0.0

    def refresh(self, model: GroundEffectModel, t_s: float) -> None:
        """After a parameter change: start, reconfigure, pause or reset the learner."""
        settings = self.params.online_settings()
        self.active = settings is not None and model.name == "neural"
        self.hold_velocity = False
        if settings is None or not self.active:
            return
        self.hold_velocity = settings.method in NEEDS_BASIS and bool(
            settings.composite_hold_velocity
        )
        p = self.params.online()
        try:
            if self.learner is None:
                from autopilot.online.online_learner import OnlineLearner

                rho = self.params.model()[1]
                net = model.net  # type: ignore[attr-defined]
                self.learner = OnlineLearner(
                    net,
                    settings,
                    find_memory(self.network, rho),
                    self.options.deterministic,
                    self.options.on_report,
                    offline=find_offline(self.network, rho, net),
                )
            elif settings != self.learner.settings:
                self.learner.configure(settings)
        except ConfigError as err:  # e.g. ewc asked for in flight without a memory
            self.errors.append(str(err))
            self.active = self.hold_velocity = False
            return
        self.learner.pause(bool(p.pause))
        if p.reset:
            self.learner.reset(t_s)
            self.params.set("GFX_OL_RESET", 0.0)

    def wait_ready(self) -> None:
        """Before the flight (never in it): until the learner process is up, so that a fast
        lockstep flight does not pass while it starts."""
        if self.learner is not None and not self.learner.wait_ready():
            self.errors.append("the learner process was not up within a minute of the start")

    def model_velocity(self, phase: Phase, estimated_m_s: Vec3, planned_m_s: Vec3) -> Vec3:
        """The velocity the model is given this step (`at_setpoint_velocity`); samples carry
        it."""
        at_setpoint = at_setpoint_velocity(self.hold_velocity, phase)
        self.velocity_m_s = planned_m_s if at_setpoint else None
        return planned_m_s if at_setpoint else estimated_m_s

    def submit(self, row: tuple[float, ...], tracking_m_s: float = 0.0) -> None:
        """A learning sample, with the position loop's vertical composite error [m/s]; at the
        setpoint's velocity when the model was given it."""
        if self.active and self.learner is not None:
            r = np.asarray(row)
            if self.velocity_m_s is not None:
                r[VELOCITY_COLUMNS] = self.velocity_m_s
            self.learner.submit(r[FEATURE_COLUMNS], r[TARGET_COLUMNS], float(r[0]), tracking_m_s)

    def apply(self, model: GroundEffectModel, t_s: float) -> Any:
        """The current snapshot into the neural model: one reference read per step. Returns
        the network it replaced when the snapshot changed (else None). With `alternate_s`,
        the learner's turn at `t_s` too."""
        if self.alternation is not None:
            self.resting = not self.alternation.step(t_s)
        if self.active and self.learner is not None:
            net = self.learner.snapshot.net
            old = model.net  # type: ignore[attr-defined]
            if net is not old:
                model.net = net  # type: ignore[attr-defined]
                return old
        return None

    def close(self, controller_s: list[float]) -> dict[str, Any]:
        """Stop the learner, save the adapted model if asked; the summary's online part
        (`controller_s`: the control steps' times, split by the learner's turns)."""
        if self.learner is None:
            return {"online_method": "off", "online_errors": self.errors} if self.errors else {}
        self.learner.close()
        out = self.learner.summary()
        if self.alternation is not None:
            out["online_alternation"] = self.alternation.summary(controller_s)
        out["online_errors"] = self.errors + out["online_errors"]
        if self.options.save_path is not None:
            out["saved_model"] = str(self.learner.save(self.options.save_path))
        return out
