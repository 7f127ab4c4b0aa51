"""Options and argument types that several subcommands share."""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterator
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


class _SensorSetNames:
    """The sensor sets the estimator's sources declare, asked for only when the parser
    checks or lists them (the parser imports none of the autopilot until then)."""

    def __iter__(self) -> Iterator[str]:
        from autopilot.estimation.sources import sensor_sets

        return iter(sensor_sets())

    def __contains__(self, name: object) -> bool:
        return name in list(self)


SENSOR_SET_NAMES = _SensorSetNames()


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
    from autopilot.estimation.sources import sensor_sets

    sim = ["--ideal-sensors"] if args.ideal_sensors else []
    if args.sensor_seed is not None:
        sim += ["--sensor-seed", str(args.sensor_seed)]
    chosen = sensor_sets()[args.sensors]
    params = [a for k, v in chosen.items() for a in ("--param", f"{k}={v}")]
    return sim, params


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def add_campaign_options(p: argparse.ArgumentParser, what: str, progress: bool = True) -> None:
    """Where a campaign's tasks (`what`: "flights", "cases") run, and (`progress`) the
    option that turns its progress bar off."""
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=positive_int, help=f"local processes running the {what} (default: cores)"
    )
    where.add_argument(
        "--ray",
        metavar="ADDRESS",
        help=f"run the {what} as tasks on a Ray cluster (auto, HOST:PORT, ray://HOST:PORT; "
        "local: start one here); needs the ray extra",
    )
    if progress:
        p.add_argument("--no-progress", action="store_true", help="no progress bar")
