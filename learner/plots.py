"""True against predicted f_ge,z over altitude at hover rotor speeds (thesis figure 3.2)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from learner.model import GroundEffectNet
from simbridge.effects.ground import (
    cutoff_height_m,
    ground_effect_force_n,
    hover_rotor_speed_in_ground_effect_rad_s,
)
from simbridge.vehicle import Vehicle

LOWEST_M = 0.015  # the vehicle's centre cannot come lower than 0.0126 m


def hover_curve(
    net: GroundEffectNet, vehicle: Vehicle, rho: float, altitudes_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(true, predicted) total f_ge,z [N] of a level vehicle hovering at each altitude."""
    cut = cutoff_height_m(rho, vehicle.rotor_radius_m)
    true, features = [], []
    for z in altitudes_m:
        n = hover_rotor_speed_in_ground_effect_rad_s(
            vehicle.weight_n, vehicle.thrust_coefficient_n_s2, z, rho, vehicle.rotor_radius_m, cut
        )
        thrust = vehicle.thrust_coefficient_n_s2 * n * n
        true.append(4 * ground_effect_force_n(thrust, z, rho, vehicle.rotor_radius_m, cut))
        features.append((z, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, n, n, n, n))
    return np.asarray(true), net.predict_batch(np.asarray(features))[:, 2]


def near_ground_error(
    net: GroundEffectNet, vehicle: Vehicle, rho: float, below_m: float = 0.1
) -> dict[str, float]:
    """RMSE of the predicted f_ge,z below `below_m`, and the true force's range there."""
    true, predicted = hover_curve(net, vehicle, rho, np.linspace(LOWEST_M, below_m, 200))
    rmse = float(np.sqrt(np.mean((predicted - true) ** 2)))
    span = float(true.max() - true.min())
    return {"rmse_n": rmse, "range_n": span, "relative": rmse / span}


def plot_prediction(net: GroundEffectNet, vehicle: Vehicle, rhos: list[float], out: Path) -> Path:
    altitudes = np.linspace(LOWEST_M, 0.5, 300)
    fig, ax = plt.subplots(figsize=(7, 4.2))
    trained = net.header.get("training", {}).get("rho", [])
    for rho, colour in zip(rhos, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False):
        true, predicted = hover_curve(net, vehicle, rho, altitudes)
        ax.plot(altitudes, true, color=colour, label=f"true, rho = {rho:g}")
        ax.plot(altitudes, predicted, color=colour, ls="--", label=f"predicted, rho = {rho:g}")
    ax.set_xlabel("altitude above the surface [m]")
    ax.set_ylabel("ground effect f_ge,z, four rotors [N]")
    ax.set_title(
        f"Ground-effect network (trained on rho = {', '.join(f'{r:g}' for r in trained)}) "
        "at hover rotor speeds"
    )
    ax.set_ylim(bottom=-0.01)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
