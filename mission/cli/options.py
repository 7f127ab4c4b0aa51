"""Options and argument types that several subcommands share."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

DEFAULT_LOGS = Path("logs")


def speedup(text: str) -> float | None:
    if text == "max":
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0 or 'max', got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0 or 'max', got {text!r}")
    return value


def port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}")
    return value


SENSOR_SET_NAMES = ("mocap", "flow", "gps")


def add_sensor_options(p: argparse.ArgumentParser) -> None:
    """`--sensors` and `--ideal-sensors`: what the estimator fuses, and whether the simulated
    sensors err as real ones do."""
    p.add_argument(
        "--sensors",
        choices=SENSOR_SET_NAMES,
        default="mocap",
        help="the estimator's sensors: motion capture (default), flow and range, GPS and "
        "barometer (sets the EKF2_* parameters; the IMU always predicts)",
    )
    p.add_argument(
        "--ideal-sensors",
        action="store_true",
        help="sensors without noise, bias or latency (the simulator's truth, on time)",
    )
    p.add_argument(
        "--sensor-seed",
        type=int,
        metavar="N",
        help="seed of the sensor errors, overriding the world's sensor_noise.seed",
    )


def sensor_arguments(args: argparse.Namespace) -> tuple[list[str], list[str]]:
    """(the simulator's options, the autopilot's --param options) for the chosen sensors."""
    from autopilot.estimation.estimator_params import SENSOR_SETS

    sim = ["--ideal-sensors"] if args.ideal_sensors else []
    if args.sensor_seed is not None:
        sim += ["--sensor-seed", str(args.sensor_seed)]
    params = [a for k, v in SENSOR_SETS[args.sensors].items() for a in ("--param", f"{k}={v}")]
    return sim, params
