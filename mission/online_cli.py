"""The command-line side of online learning: `--online METHOD` and its companions for
`groundfx autopilot`, `groundfx fly` and `groundfx sitl`."""

from __future__ import annotations

import argparse
from pathlib import Path

from autopilot.params import ONLINE_METHODS
from learner.online.settings import METHODS
from simbridge.config import ConfigError


def add_online_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("online learning")
    g.add_argument(
        "--online",
        choices=METHODS,
        metavar="METHOD",
        help=f"adapt the neural model in flight: {', '.join(METHODS)} (parameter GFX_OL_METHOD; "
        "hyperparameters GFX_OL_LR, GFX_OL_LAMBDA, GFX_OL_MARGIN, GFX_OL_FORGET via --param)",
    )
    mode = g.add_mutually_exclusive_group()
    mode.add_argument(
        "--online-deterministic",
        dest="online_deterministic",
        action="store_true",
        default=None,
        help="update inside the control step when a batch completes: the same simulated "
        "times on every run (default with --auto-start / --no-gcs)",
    )
    mode.add_argument(
        "--online-async",
        dest="online_deterministic",
        action="store_false",
        help="update in the learner thread; the control loop never waits "
        "(default with a ground station)",
    )
    g.add_argument("--save-model", type=Path, help="save the adapted network here at the end")


def online_overrides(args: argparse.Namespace) -> dict[str, float]:
    """--online as the parameter GFX_OL_METHOD."""
    method = getattr(args, "online", None)
    if method is None:
        return {}
    if getattr(args, "model", None) not in (None, "neural"):
        raise ConfigError(f"--online {method}: needs --model neural, not --model {args.model}")
    return {"GFX_OL_METHOD": float(ONLINE_METHODS.index(method))}


def online_options(args: argparse.Namespace, reproducible: bool) -> object:
    """The runner's OnlineOptions: deterministic unless asked otherwise where the flight is
    reproducible anyway (--auto-start), asynchronous with a ground station."""
    from autopilot.online_control import OnlineOptions

    deterministic = args.online_deterministic
    if deterministic is None:
        deterministic = reproducible
    return OnlineOptions(deterministic=deterministic, save_path=args.save_model)


def pass_through(args: argparse.Namespace) -> list[str]:
    """The online options again, for the autopilot process that `fly` and `sitl` start."""
    out: list[str] = []
    if getattr(args, "online", None):
        out += ["--online", args.online]
    if args.online_deterministic is not None:
        out.append("--online-deterministic" if args.online_deterministic else "--online-async")
    if args.save_model is not None:
        out += ["--save-model", str(args.save_model.resolve())]
    return out


def add_online_learn_parsers(learn: argparse._SubParsersAction, func: object) -> None:
    m = learn.add_parser("memory", help="store offline samples beside a model (ewc, replay)")
    m.add_argument("data", type=Path, nargs="+", help="the model's offline dataset files")
    m.add_argument("--out", type=Path, required=True, help="NAME.memory.npz beside NAME.npz")
    m.add_argument("--samples", type=int, default=2048, help="samples kept (default: 2048)")
    m.add_argument("--seed", type=int, default=0)
    m.set_defaults(func=func)


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
    raise ConfigError(f"unknown action {args.action!r}")
