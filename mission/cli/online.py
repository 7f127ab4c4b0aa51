"""The command-line side of online learning: what `--online METHOD` and its companions (the
flight request's options, autopilot/request.py) ask of the autopilot (with a ground station,
GFX_OL_METHOD and the other GFX_OL_* parameters do the same in flight), and `groundfx learn
memory|online-eval|tour`."""

from __future__ import annotations

import argparse
from pathlib import Path

from learner.online.names import METHODS, method_number
from mission.cli.options import add_campaign_options, positive_int
from simbridge.config import ConfigError


def online_overrides(args: argparse.Namespace) -> dict[str, float]:
    """--online as the parameter GFX_OL_METHOD."""
    method = getattr(args, "online", None)
    if method is None:
        return {}
    if getattr(args, "model", None) not in (None, "neural"):
        raise ConfigError(f"--online {method}: needs --model neural, not --model {args.model}")
    return {"GFX_OL_METHOD": float(method_number(method))}


def online_options(args: argparse.Namespace, reproducible: bool) -> object:
    """The runner's OnlineOptions: deterministic unless asked otherwise where the flight is
    reproducible anyway (--auto-start), asynchronous with a ground station."""
    from autopilot.online.online_control import OnlineOptions

    deterministic = args.online_deterministic
    if deterministic is None:
        deterministic = reproducible
    return OnlineOptions(
        deterministic=deterministic,
        save_path=args.save_model,
        alternate_s=getattr(args, "online_alternate", None),
    )


def add_online_learn_parsers(learn: argparse._SubParsersAction, func: object) -> None:
    m = learn.add_parser("memory", help="store offline samples beside a model (ewc, replay)")
    m.add_argument("data", type=Path, nargs="+", help="the model's offline dataset files")
    m.add_argument("--out", type=Path, required=True, help="NAME.memory.npz beside NAME.npz")
    m.add_argument("--samples", type=int, default=2048, help="samples kept (default: 2048)")
    m.add_argument("--seed", type=int, default=0)
    m.set_defaults(func=func)
    e = learn.add_parser(
        "online-eval", help="thesis experiments 4.3 and 4.4: online methods over seeded trials"
    )
    e.add_argument("--trials", type=int, default=10, help="seeded trials per condition")
    e.add_argument("--seed", type=int, default=0, help="first trial seed")
    e.add_argument("--methods", default=",".join(METHODS), help="comma-separated methods")
    e.add_argument("--rho", default="2,0.5,4,1", help="rho_sim of the worlds (1: the training rho)")
    e.add_argument("--network", default="rho1", help="the offline network (default: rho1)")
    e.add_argument("--hold-s", type=float, default=10.0, help="hold 3 cm above ground this long")
    e.add_argument("--no-remember", action="store_true", help="skip experiment 4.4")
    _composite_options(e, "thesis")
    add_campaign_options(e, "flights", progress=False)
    e.add_argument("--json", action="store_true")
    e.set_defaults(func=func)
    t = learn.add_parser(
        "tour", help="composite's memory: chained flights over grounds, each from the model the "
        "one before saved",
    )  # fmt: skip
    t.add_argument(
        "--grounds", default="rho1,rho2,box,rho1,rho2",
        help="the tour: rhoX (a flat ground of rho_sim X) or box (the obstacles world's box), "
        "comma-separated (default: rho1,rho2,box,rho1,rho2)",
    )  # fmt: skip
    t.add_argument("--trials", type=int, default=3, help="seeded tours (default: 3)")
    t.add_argument("--seed", type=int, default=0, help="first seed")
    _composite_options(t, "default")
    t.add_argument(
        "--workers", type=positive_int, help="local processes running the tours (default: cores)"
    )
    t.add_argument("--out", type=Path, default=Path("logs/tour"), help="flights and tour.json")
    t.set_defaults(func=func)


def _composite_options(parser: argparse.ArgumentParser, controller: str) -> None:
    """--basis, --controller (its default `controller`) and --param, as the online
    evaluation and the tour take them."""
    parser.add_argument(
        "--basis", default="grounds", help="the basis model composite adapts (default: grounds)"
    )
    parser.add_argument(
        "--controller",
        choices=("thesis", "default"),
        default=controller,
        help=f"thesis: the thesis's position PD, where a model error shows in the hold; "
        f"default: the autopilot's PD with its integral (default: {controller})",
    )
    parser.add_argument(
        "--param", action="append", default=[], metavar="NAME=VALUE", help="e.g. GFX_OL_LR=0.01"
    )


def _workers(args: argparse.Namespace) -> int:
    """--workers (at least 1 by its type), or one per core."""
    import os

    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    if workers > 64:
        raise ConfigError(f"--workers: {workers} is outside the allowed range [1, 64]")
    return workers


def cmd_online_learn(args: argparse.Namespace) -> int:
    if args.action == "memory":
        from learner.dataset import load_dataset
        from learner.online.memory import make_memory, save_memory

        if args.samples < 1:
            raise ConfigError(f"--samples: {args.samples} must be at least 1")
        memory = make_memory([load_dataset(p) for p in args.data], args.samples, args.seed)
        memory.header["sources"] = [str(p) for p in args.data]
        print(save_memory(args.out, memory))
        return 0
    if args.action == "tour":
        return _tour(args)
    import json

    from mission.campaigns.online_eval import run_online_eval

    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    for m in methods:
        if m not in METHODS:
            raise ConfigError(f"--methods: unknown method {m!r}; choose from {', '.join(METHODS)}")
    try:
        rhos = tuple(float(r) for r in args.rho.split(","))
    except ValueError:
        raise ConfigError(
            f"--rho: expected numbers separated by commas, got {args.rho!r}"
        ) from None
    if not all(0 < r <= 50 for r in rhos):
        raise ConfigError(f"--rho: each rho must be in (0, 50], got {args.rho!r}")
    if args.trials < 1:
        raise ConfigError(f"--trials: {args.trials} must be at least 1")
    workers = _workers(args)
    if not 1.0 <= args.hold_s <= 120.0:
        raise ConfigError(f"--hold-s: {args.hold_s:g} is outside the allowed range [1, 120] s")
    result = run_online_eval(
        list(range(args.seed, args.seed + args.trials)),
        methods,
        rhos,
        args.network,
        args.hold_s,
        remember=not args.no_remember,
        params=tuple(args.param),
        workers=workers,
        controller=args.controller,
        basis=args.basis,
        ray_address=args.ray,
    )
    if args.json:
        print(json.dumps(result))
    return 0


def _tour(args: argparse.Namespace) -> int:
    from mission.campaigns.online_tour import parse_grounds, run_tour

    grounds = parse_grounds(args.grounds)
    if not 1 <= args.trials <= 100:
        raise ConfigError(f"--trials: {args.trials} is outside the allowed range [1, 100]")
    workers = _workers(args)
    run_tour(args.trials, args.seed, grounds, args.out, args.basis, args.controller,
             tuple(args.param), workers)  # fmt: skip
    return 0
