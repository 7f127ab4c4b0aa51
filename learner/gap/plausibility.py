"""Whether a log and a vehicle can describe one flying vehicle at all, checked on the nominal
residual before any fit: a flying vehicle's mean vertical residual is a few percent of its
weight (a ground effect, a thrust error), never half of it. Half the weight or the weight
itself means the inputs are wrong, and a fit on them would answer wrongly without a word
(gravity left in the acceleration gives a gap of twice the weight; thrust in newtons read
as rad/s a thrust of nearly nothing)."""

from __future__ import annotations

import numpy as np

from simbridge.config import ConfigError
from simbridge.vehicle import Vehicle

MAX_VERTICAL_SHARE = 0.5  # of the weight: a mean vertical residual beyond it is no effect

CAUSES_POSITIVE = (
    "gravity left in the accelerometer (the log's acceleration must be the kinematic one, "
    "gravity removed; say in the column mapping that it includes gravity)",
    "thrust in the wrong units, too small: per-rotor thrust in newtons (or a throttle) passed "
    "as rotor speeds in rad/s",
    "the wrong vehicle: heavier, or with a smaller thrust coefficient C_T, than the one flown "
    "(--vehicle, or the world's `vehicle:` key)",
    "rows on the ground that the contact test did not see (the vehicle's body_size_m against "
    "the logged resting height)",
)
CAUSES_NEGATIVE = (
    "thrust in the wrong units, too large: rotor speeds in rpm passed as rad/s",
    "the wrong vehicle: lighter, or with a larger thrust coefficient C_T, than the one flown "
    "(--vehicle, or the world's `vehicle:` key)",
    "gravity removed twice from the acceleration (the accelerometer's convention in the mapping)",
)


def vertical_share(residual_n: np.ndarray, vehicle: Vehicle) -> float:
    """A flight's mean vertical residual over the vehicle's weight."""
    return float(np.mean(residual_n[:, 2]) / vehicle.weight_n)


def implausible(
    names: list[str], residuals: list[np.ndarray], vehicle: Vehicle
) -> tuple[str, float, float] | None:
    """The first flight whose mean vertical residual is beyond MAX_VERTICAL_SHARE of the
    weight: (name, mean residual in N, share of the weight); None if every flight is fine."""
    for name, r in zip(names, residuals, strict=True):
        share = vertical_share(r, vehicle)
        if not np.isfinite(share) or abs(share) > MAX_VERTICAL_SHARE:
            return name, float(np.mean(r[:, 2])), share
    return None


def message(name: str, mean_n: float, share: float, vehicle: Vehicle) -> str:
    causes = CAUSES_NEGATIVE if share < 0 else CAUSES_POSITIVE
    return (
        f"{name}: the residual against the nominal world is implausible for a flying vehicle: "
        f"its mean vertical residual is {mean_n:+.4g} N, {share:+.2f} times the weight "
        f"{vehicle.weight_n:.4g} N of the vehicle {vehicle.name!r} ({vehicle.mass_kg:g} kg); "
        f"a missing effect is a few percent of it. Likely causes: " + "; ".join(causes)
    )


def check(names: list[str], residuals: list[np.ndarray], vehicle: Vehicle) -> None:
    """Stop with a ConfigError naming the likely causes when a flight's nominal residual is
    implausible (`implausible`)."""
    found = implausible(names, residuals, vehicle)
    if found is not None:
        raise ConfigError(message(*found, vehicle))
