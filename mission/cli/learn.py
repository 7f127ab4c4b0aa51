"""`groundfx learn gather|train|evaluate|memory|online-eval|plot`: data, training and
evaluation of the ground-effect network."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from learner.bounds import DEFAULT_CONTROL_GAIN_BOUND, DEFAULT_LAYER_BOUND
from mission.cli.online import add_online_learn_parsers
from mission.cli.options import DEFAULT_LOGS, add_campaign_options, positive_int
from simbridge.config import ConfigError


def add_parser(sub: Any) -> None:
    p = sub.add_parser("learn", help="gather data, train the ground-effect network, plot it")
    learn = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    g = learn.add_parser("gather", help="the expert flies the thesis's random waypoints")
    g.add_argument("--rho", type=float, required=True, help="rho_sim of the world and the expert")
    g.add_argument("--samples", type=int, default=10000, help="100 Hz samples (default: 10000)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--world", default="default", help="world whose ground effect rho replaces")
    g.add_argument("--out", type=Path, required=True, help="dataset file (.npz)")
    g.add_argument(
        "--flights", type=positive_int, default=1,
        help="split the samples over N flights (seeds SEED*1000+i), kept in OUT.parts/ as "
        "they land: a rerun flies only the missing ones (default: 1, one flight)",
    )  # fmt: skip
    add_campaign_options(g, "flights")
    g.set_defaults(func=cmd_learn)
    t = learn.add_parser("train", help="offline training")
    t.add_argument("data", type=Path, nargs="+", help="dataset files")
    t.add_argument("--out", type=Path, required=True, help="model file (.npz)")
    t.add_argument("--max-epochs", type=int, default=1000)
    t.add_argument(
        "--layer-bound",
        type=float,
        default=DEFAULT_LAYER_BOUND,
        help=f"spectral norm bound per layer (default: {DEFAULT_LAYER_BOUND:g})",
    )
    t.add_argument(
        "--control-gain-bound",
        type=float,
        default=DEFAULT_CONTROL_GAIN_BOUND,
        help="bound on |d f_ge / d thrust| near hover, N/N, through the rotor-speed inputs "
        f"(Neural Lander's stability condition; 0: none; default: {DEFAULT_CONTROL_GAIN_BOUND:g})",
    )
    t.add_argument("--seed", type=int, default=0)
    t.set_defaults(func=cmd_learn)
    b = learn.add_parser(
        "basis", help="a basis shared by several grounds, each ground's coefficients (DAIML)"
    )
    b.add_argument("data", type=Path, nargs="+", help="dataset files, one ground or more each")
    b.add_argument("--out", type=Path, required=True, help="model file (.npz)")
    b.add_argument("--home", default="rho1", help="the ground to start on (default: rho1)")
    b.add_argument("--max-epochs", type=int, default=300)
    b.add_argument(
        "--adversarial-weight",
        type=float,
        default=0.1,
        help="weight of the ground classifier's term (0: plain multi-ground training)",
    )
    b.add_argument("--seed", type=int, default=0)
    b.set_defaults(func=cmd_learn)
    e = learn.add_parser("evaluate", help="none, analytic and neural over seeded landing trials")
    e.add_argument("--world", default="rho2")
    e.add_argument(
        "--network", help="model file or packaged name (default: nearest the world's rho)"
    )
    e.add_argument("--trials", type=int, default=10)
    e.add_argument("--seed", type=int, default=0, help="first trial seed")
    e.add_argument("--json", action="store_true")
    e.add_argument(
        "--out", type=Path,
        help="keep each trial in OUT/results.jsonl as it lands: a rerun flies only the rest",
    )  # fmt: skip
    add_campaign_options(e, "trials")
    e.set_defaults(func=cmd_learn)
    add_online_learn_parsers(learn, cmd_learn)
    pl = learn.add_parser("plot", help="true against predicted f_ge,z over altitude")
    pl.add_argument("--network", default="rho1", help="model file or packaged name")
    pl.add_argument("--rho-list", default="1,2", help="rho values to draw (default: 1,2)")
    pl.add_argument("--out", type=Path, default=DEFAULT_LOGS / "prediction.png")
    pl.set_defaults(func=cmd_learn)


def cmd_learn(args: argparse.Namespace) -> int:
    if args.action == "gather":
        from mission.campaigns.gather import gather_flights

        if not 0 < args.rho <= 50:
            raise ConfigError(f"--rho: {args.rho:g} is outside the allowed range (0, 50]")
        if args.samples < 1:
            raise ConfigError(f"--samples: {args.samples} must be at least 1")
        print(
            gather_flights(
                args.rho, args.samples, args.seed, args.out, args.world, args.flights,
                args.workers, args.ray, progress=not args.no_progress,
            )
        )  # fmt: skip
        return 0
    if args.action == "train":
        from learner.dataset import load_dataset
        from learner.train import TrainConfig, train, write_outputs

        datasets = [load_dataset(p) for p in args.data]
        config = TrainConfig(
            max_epochs=args.max_epochs,
            seed=args.seed,
            layer_bound=args.layer_bound,
            control_gain_bound=args.control_gain_bound,
        )
        result = train(datasets, config, sources=[str(p) for p in args.data])
        paths = write_outputs(result, args.out)
        m = result.metrics
        print(
            f"trained on {m['train_samples']} samples ({m['outliers_dropped']} outliers dropped) "
            f"in {m['wall_s']:.1f} s, {m['epochs']} epochs; validation RMSE f_ge,z "
            f"{m['validation_rmse_n']['fge_z'] * 1000:.2f} mN; Lipschitz bound "
            f"{m['lipschitz_bound']:.2f}; rotor-speed columns {m['control_column_norm']:.4f}"
        )
        for kind, path in paths.items():
            print(f"{kind}: {path}")
        return 0
    if args.action == "basis":
        return _cmd_basis(args)
    if args.action in ("memory", "online-eval", "tour"):
        from mission.cli.online import cmd_online_learn

        return cmd_online_learn(args)
    if args.action == "evaluate":
        from mission.campaigns.trials import evaluate_models

        result = evaluate_models(
            list(range(args.seed, args.seed + args.trials)), args.world, args.network,
            workers=args.workers, ray_address=args.ray, out=args.out,
            progress=not args.no_progress and sys.stderr.isatty(),
        )  # fmt: skip
        if args.json:
            print(json.dumps(result))
        return 0
    from learner.model import load_model
    from learner.plots import plot_prediction
    from simbridge.vehicle import load_vehicle

    rhos = [float(r) for r in args.rho_list.split(",")]
    print(plot_prediction(load_model(args.network), load_vehicle(), rhos, args.out))
    return 0


def _cmd_basis(args: argparse.Namespace) -> int:
    from learner.basis import BasisConfig, ground_name, train_basis
    from learner.dataset import load_dataset
    from learner.model import save_model

    grounds: dict[str, list[Any]] = {}
    for path in args.data:
        dataset = load_dataset(path)
        grounds.setdefault(ground_name(dataset), []).append(dataset)
    if args.home not in grounds:
        raise ConfigError(f"--home: {args.home!r} is not among the grounds {sorted(grounds)}")
    if len(grounds) < 2:
        raise ConfigError(f"a shared basis needs two grounds or more; got {sorted(grounds)}")
    config = BasisConfig(
        max_epochs=args.max_epochs, adversarial_weight=args.adversarial_weight, seed=args.seed
    )
    net, metrics = train_basis(grounds, args.home, config, sources=[str(p) for p in args.data])
    save_model(args.out, net)
    args.out.with_suffix(".metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    for name, m in metrics["grounds"].items():
        rmse = m["validation_rmse_n"]["fge_z"] * 1000
        print(f"ground {name}: {m['samples']} samples, validation RMSE f_ge,z {rmse:.2f} mN")
    print(f"{metrics['epochs']} epochs in {metrics['wall_s']:.0f} s; home ground {args.home}")
    print(f"model: {args.out}")
    return 0
