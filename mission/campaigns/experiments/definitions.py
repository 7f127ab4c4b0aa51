"""The thesis's experiments (chapter 4) as data: conditions x seeds -> trials of real flights.

A trial is one or more flights flown in order (experiment 4.4 adapts a network in one flight
and flies the adapted network in the next); its result is the last flight's. Trials of one
experiment share their seeds across conditions, so conditions fly the same points.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass

from learner.online.names import METHODS, PROTECTING
from mission.campaigns.experiments.missions import MISSION_KINDS, make_mission

ONLINE_METHODS = METHODS  # the conditions fly every online method there is
BASIS = "grounds"  # composite adapts the basis learnt over several grounds (learner/basis.py)


def network_for(method: str | None, network: str = "rho1") -> str:
    """The network a condition flies: composite the basis model, the others `network`."""
    return BASIS if method == "composite" else network


MULTI_NETWORK = "@multi"  # the network trained on several rho once per campaign (4.2)
MULTI_RHOS = (1.0, 2.0)
MEASURES = {  # the error measures of the report: key in a flight summary -> (label, unit, scale)
    "hold_z_rms_error_m": ("hold z RMS error", "mm", 1000.0),
    "landing_error_m": ("landing position error", "mm", 1000.0),
    "touchdown_speed_m_s": ("touchdown speed", "m/s", 1.0),
    "sim_s": ("flight time", "s", 1.0),
    # predicted minus true vertical ground-effect force over the hold: the model, not the loop
    "ge_z_hold_rms_error_n": ("model error over the hold", "mN", 1000.0),
}
PRIMARY = "hold_z_rms_error_m"


@dataclass(frozen=True)
class Flight:
    """One flight of a trial: world (a packaged name) with rho_sim, mission kind, controller."""

    mission: str = "landing"
    world: str = "default"
    rho_sim: float | None = None  # replaces the world's ground-effect rho
    model: str = "neural"  # none | analytic | neural
    rho_model: float | None = None  # the analytic model's rho (None: rho_sim, the expert)
    network: str | None = None  # packaged name, file, or MULTI_NETWORK
    online: str | None = None  # online method, None: offline
    carry_network: bool = False  # fly the network the previous flight adapted (4.4)

    def __post_init__(self) -> None:
        if self.mission not in MISSION_KINDS:
            raise ValueError(f"mission {self.mission!r}: choose one of {MISSION_KINDS}")
        if self.model not in ("none", "analytic", "neural"):
            raise ValueError(f"model {self.model!r}: choose none, analytic or neural")
        if self.online is not None and self.online not in ONLINE_METHODS:
            raise ValueError(f"online {self.online!r}: choose one of {ONLINE_METHODS}")


@dataclass(frozen=True)
class Condition:
    name: str
    label: str
    flights: tuple[Flight, ...]
    trials: int  # default number of trials
    group: str = ""  # plots draw conditions of one group together (e.g. one rho_sim)


@dataclass(frozen=True)
class Expectation:
    """What the thesis (or its premise) expects: `a` has a lower error than `b` ("lower"), or
    no significant difference between them ("similar"), in `measure` (the hold error, or the
    model's error over the hold: whether the model adapted, whatever the loop made of it)."""

    a: str
    b: str
    relation: str
    claim: str
    measure: str = PRIMARY


MODEL = "ge_z_hold_rms_error_n"


@dataclass(frozen=True)
class Experiment:
    key: str
    title: str
    question: str
    conditions: tuple[Condition, ...]
    expectations: tuple[Expectation, ...] = ()

    @property
    def needs_online(self) -> bool:
        return any(f.online or f.carry_network for c in self.conditions for f in c.flights)

    @property
    def needs_multi(self) -> bool:
        return any(f.network == MULTI_NETWORK for c in self.conditions for f in c.flights)


@dataclass(frozen=True)
class Trial:
    experiment: str
    condition: str
    seed: int
    flights: tuple[Flight, ...]

    @property
    def id(self) -> str:
        """Experiment, condition, seed and a digest of the flights and their missions: a
        changed definition is a new trial, never confused with an old result."""
        return f"{self.experiment}/{self.condition}/{self.flight_key}"

    @property
    def flight_key(self) -> str:
        """Seed and digest alone: trials of different experiments with the same key fly
        the very same seeded flights (e.g. the rho1 network at rho 1 in 4.2, 4.3, 4.4 and
        4.7), so one flight serves them all."""
        missions = [make_mission(f.mission, self.seed) for f in self.flights]
        flights = [dataclasses.asdict(f) for f in self.flights]
        spec = json.dumps([flights, missions], sort_keys=True)
        digest = hashlib.sha256(spec.encode()).hexdigest()[:8]
        return f"{self.seed}/{digest}"

    def to_dict(self) -> dict:
        return {
            "experiment": self.experiment,
            "condition": self.condition,
            "seed": self.seed,
            "flights": [dataclasses.asdict(f) for f in self.flights],
        }

    @staticmethod
    def from_dict(data: dict) -> Trial:
        flights = tuple(Flight(**f) for f in data["flights"])
        return Trial(data["experiment"], data["condition"], int(data["seed"]), flights)


def _c(name: str, label: str, trials: int, *flights: Flight, group: str = "") -> Condition:
    return Condition(name, label, tuple(flights), trials, group)


# `none` flies long (without a model the landing waits ~65 simulated seconds for the sinking
# setpoint to overcome the ground effect) and alike (spread 0.01 mm): few trials measure it.
BASELINE_TRIALS = 2
# Online learning runs an update per 64 samples and 4.4 flies two flights per trial:
# with six methods in 4.4 and 4.5, two trials per method keep `all` within 15 minutes on
# two cores; --trials N asks for more.
ONLINE_TRIALS = 3
METHOD_TRIALS = 2
NEAREST = {0.5: "rho1", 1.0: "rho1", 1.5: "rho1", 2.0: "rho2", 3.0: "rho2", 4.0: "rho2"}


def _offline_vs_baseline() -> Experiment:
    w = Flight(world="rho2")
    return Experiment(
        "4.1",
        "Offline learning against the baseline",
        "Does the offline-trained network (rho2) hold closer to the ground than no model, and "
        "how close does it come to the analytic expert, in the rho_sim = 2 world?",
        (
            _c("none", "no model", BASELINE_TRIALS, dataclasses.replace(w, model="none")),
            _c("analytic", "analytic (true rho)", 4, dataclasses.replace(w, model="analytic")),
            _c("neural", "neural rho2 (offline)", 4, dataclasses.replace(w, network="rho2")),
        ),
        (
            Expectation("neural", "none", "lower", "the offline network beats the baseline"),
            Expectation("analytic", "neural", "lower", "the true model stays the best"),
        ),
    )


def _several_rho() -> Experiment:
    conditions = []
    for rho in (1.0, 1.5, 2.0, 3.0):
        seen = "seen" if rho in MULTI_RHOS else "unseen"
        g = f"rho_sim {rho:g}"
        f = Flight(rho_sim=rho)
        conditions += [
            _c(f"multi@{rho:g}", f"rho 1+2 net at {rho:g} ({seen})", 2,
               dataclasses.replace(f, network=MULTI_NETWORK), group=g),
            _c(f"single@{rho:g}", f"{NEAREST[rho]} net at {rho:g}", 2,
               dataclasses.replace(f, network=NEAREST[rho]), group=g),
        ]  # fmt: skip
    return Experiment(
        "4.2",
        "Offline learning of several rho",
        "One network trained on rho 1 and rho 2 data together, flown at rho_sim 1 and 2 (seen) "
        "and 1.5 and 3 (never seen), against the single-rho network nearest each rho_sim.",
        tuple(conditions),
        (
            Expectation("multi@1", "single@1", "similar", "one net serves several rho (rho 1)"),
            Expectation("multi@2", "single@2", "similar", "one net serves several rho (rho 2)"),
            Expectation("multi@1.5", "single@1.5", "lower", "between seen rho it interpolates"),
        ),
    )


def _offline_vs_online() -> Experiment:
    conditions = []
    for rho in (1.0, 2.0):
        f = Flight(rho_sim=rho, network="rho1")
        g = f"rho_sim {rho:g}"
        conditions += [
            _c(f"offline@{rho:g}", f"rho1 offline at {rho:g}", ONLINE_TRIALS, f, group=g),
            _c(f"online@{rho:g}", f"rho1 + naive online at {rho:g}", ONLINE_TRIALS,
               dataclasses.replace(f, online="naive"), group=g),
            _c(f"composite@{rho:g}", f"grounds + composite at {rho:g}", ONLINE_TRIALS,
               dataclasses.replace(f, network=BASIS, online="composite"), group=g),
        ]  # fmt: skip
    return Experiment(
        "4.3",
        "Offline against online learning",
        "The rho1 network flown offline and with naive online learning, where rho_sim equals "
        "the training rho (1) and where it differs (2).",
        tuple(conditions),
        (
            Expectation("online@2", "offline@2", "lower", "online adapts to an unseen rho"),
            Expectation("online@1", "offline@1", "similar", "nothing to gain at the trained rho"),
            Expectation("composite@2", "offline@2", "lower", "composite adapts to an unseen rho"),
            Expectation("composite@1", "offline@1", "similar", "composite does no harm at rho 1"),
            Expectation("online@2", "offline@2", "lower", "online's model adapts", MODEL),
            Expectation("composite@2", "offline@2", "lower", "composite's model adapts", MODEL),
        ),
    )


def _remembering() -> Experiment:
    back = Flight(rho_sim=1.0, network="rho1")
    conditions = [_c("never-adapted", "rho1 at 1, not adapted", METHOD_TRIALS, back)]
    for method in ONLINE_METHODS:
        adapt = Flight(rho_sim=2.0, network=network_for(method), online=method)
        # composite recalls a ground from its memory with the method on; the rest fly as adapted
        again = "composite" if method == "composite" else None
        conditions.append(
            _c(method, f"adapted at 2 by {method}, back at 1", METHOD_TRIALS, adapt,
               dataclasses.replace(back, carry_network=True, online=again))
        )  # fmt: skip
    return Experiment(
        "4.4",
        "Remembering previous knowledge",
        "The rho1 network adapts online at rho_sim 2, then flies offline at rho_sim 1 again: "
        "how much of rho 1 has each method forgotten?",
        tuple(conditions),
        (
            *(
                Expectation(m, "naive", "lower", f"{m} forgets less than naive")
                for m in (*PROTECTING, "composite")  # composite: its memory of grounds
            ),
            Expectation("composite", "never-adapted", "similar", "composite recalls rho 1"),
            *(
                Expectation(m, "naive", "lower", f"{m}'s model forgets less than naive", MODEL)
                for m in (*PROTECTING, "composite")
            ),
        ),
    )


def _online_methods() -> Experiment:
    f = Flight(rho_sim=2.0, network="rho1")
    conditions = [_c("offline", "rho1 offline", METHOD_TRIALS, f)]
    conditions += [
        _c(m, f"{network_for(m)} + {m}", METHOD_TRIALS,
           dataclasses.replace(f, network=network_for(m), online=m))
        for m in ONLINE_METHODS
    ]  # fmt: skip
    return Experiment(
        "4.5",
        "Comparing the online methods",
        "The rho1 network at rho_sim 2 with each online method.",
        tuple(conditions),
        (
            *(
                Expectation(m, "offline", "lower", f"{m} adapts towards rho 2")
                for m in ONLINE_METHODS
            ),
            *(
                Expectation(m, "offline", "lower", f"{m}'s model adapts towards rho 2", MODEL)
                for m in ONLINE_METHODS
            ),
        ),
    )


def _flight_test() -> Experiment:
    f = Flight(mission="flight_test", world="rho2")
    return Experiment(
        "4.6",
        "Flight test",
        "A mission of three approaches (a low pass 10 cm up, a 3 s hold 3 cm up, a climb to "
        "30 cm), then a landing, in the rho_sim = 2 world.",
        (
            _c("none", "no model", BASELINE_TRIALS, dataclasses.replace(f, model="none")),
            _c("analytic", "analytic", 2, dataclasses.replace(f, model="analytic")),
            _c("neural", "neural rho2", 3, dataclasses.replace(f, network="rho2")),
        ),
        (Expectation("neural", "none", "lower", "the network helps over a whole mission"),),
    )


def _size_and_obstacles() -> Experiment:
    conditions = []
    for rho in (0.5, 1.0, 2.0, 4.0):
        f = Flight(rho_sim=rho)
        g = f"rho_sim {rho:g}"
        conditions += [
            _c(f"none@{rho:g}", f"no model at {rho:g}", BASELINE_TRIALS,
               dataclasses.replace(f, model="none"), group=g),
            _c(f"neural@{rho:g}", f"{NEAREST[rho]} net at {rho:g}", 2,
               dataclasses.replace(f, network=NEAREST[rho]), group=g),
        ]  # fmt: skip
    for kind in ("box", "step", "wall"):
        f = Flight(mission=kind, world="obstacles")
        if kind != "wall":  # beside the wall the ground is open: compare with neural@1
            conditions.append(
                _c(f"none@{kind}", f"no model, {kind}", BASELINE_TRIALS,
                   dataclasses.replace(f, model="none"), group=kind)
            )  # fmt: skip
        conditions += [
            _c(f"analytic@{kind}", f"analytic, {kind}", 2,
               dataclasses.replace(f, model="analytic"), group=kind),
            _c(f"neural@{kind}", f"rho1 net, {kind}", 3,
               dataclasses.replace(f, network="rho1"), group=kind),
            _c(f"composite@{kind}", f"grounds + composite, {kind}", 3,
               dataclasses.replace(f, network=BASIS, online="composite"), group=kind),
        ]  # fmt: skip
    return Experiment(
        "4.7",
        "Size of the ground effect and real obstacles",
        "The baseline's error against rho_sim (0.5 to 4) with the nearest network; landing on "
        "a 10 cm box, on a 20 cm step and 20 cm beside a wall (obstacles world, rho_sim 1).",
        tuple(conditions),
        (
            Expectation("none@1", "none@4", "lower", "a larger rho, a larger baseline error"),
            Expectation("neural@box", "none@box", "lower", "the network helps on a box"),
            Expectation("neural@step", "none@step", "lower", "the network helps on a step"),
            Expectation("neural@wall", "neural@1", "similar", "a wall beside does not spoil it"),
        ),
    )


EXPERIMENTS: dict[str, Experiment] = {
    e.key: e
    for e in (
        _offline_vs_baseline(),
        _several_rho(),
        _offline_vs_online(),
        _remembering(),
        _online_methods(),
        _flight_test(),
        _size_and_obstacles(),
    )
}


def select(name: str) -> list[Experiment]:
    """`all`, or one experiment by its number (`4.1` or `1`)."""
    if name == "all":
        return list(EXPERIMENTS.values())
    key = name if name.startswith("4.") else f"4.{name}"
    if key not in EXPERIMENTS:
        raise KeyError(f"experiment {name!r}: choose all or one of {', '.join(EXPERIMENTS)}")
    return [EXPERIMENTS[key]]


def plan(experiment: Experiment, trials: int | None = None, first_seed: int = 0) -> list[Trial]:
    """Its trials: each condition's default count (or `trials` for every condition), seeds
    first_seed, first_seed + 1, ... shared across conditions."""
    out = []
    for c in experiment.conditions:
        for i in range(trials if trials is not None else c.trials):
            out.append(Trial(experiment.key, c.name, first_seed + i, c.flights))
    return out
