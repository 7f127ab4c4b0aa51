"""Options and argument types that several subcommands share."""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterator
from pathlib import Path

DEFAULT_LOGS = Path("logs")
DEFAULT_GCS_URLS = ("udpout:127.0.0.1:14550", "udpin:0.0.0.0:14540")


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


def max_flight_s(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 1.0 <= value <= 86400.0:
        raise argparse.ArgumentTypeError(f"expected seconds in [1, 86400], got {text!r}")
    return value


def port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}")
    return value


def model_options(
    p: argparse.ArgumentParser,
    rho_default: float | None = 1.0,
    model_default: str | None = "analytic",
) -> None:
    p.add_argument(
        "--model",
        default=model_default,
        choices=["none", "analytic", "neural"],
        help="ground-effect model of the controller (default: "
        + (model_default or "parameter GFX_GE_MODEL, analytic")
        + ")",
    )
    p.add_argument(
        "--rho",
        type=float,
        default=rho_default,
        help="rho of the analytic model (fly's default: the world's rho_sim)",
    )
    p.add_argument(
        "--network",
        help="model file or packaged name for --model neural "
        "(default: the packaged network trained nearest --rho)",
    )


def gcs_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--out",
        action="append",
        metavar="URL",
        help="ground-station endpoint, repeatable: udpout:HOST:PORT, udpin:HOST:PORT, "
        "tcpin:HOST:PORT (default: udpout:127.0.0.1:14550 and udpin:0.0.0.0:14540)",
    )
    p.add_argument("--no-gcs", action="store_true", help="no ground-station endpoint at all")
    p.add_argument(
        "--identity",
        choices=["px4", "ardupilot"],
        default="px4",
        help="autopilot type and mode numbering in HEARTBEAT (default: px4)",
    )
    p.add_argument(
        "--params-file",
        type=Path,
        default=DEFAULT_LOGS / "params.yaml",
        help="YAML file parameters set over MAVLink persist in (default: logs/params.yaml; "
        "none: nothing persists)",
    )
    p.add_argument(
        "--param",
        action="append",
        metavar="NAME=VALUE",
        default=[],
        help="a parameter for this run only, repeatable (e.g. --param MIS_TAKEOFF_ALT=2)",
    )
    p.add_argument(
        "--signing-key-file",
        type=Path,
        help="sign MAVLink 2 to ground stations and accept only signed packets; the file "
        "holds 64 hex digits or a passphrase",
    )


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
