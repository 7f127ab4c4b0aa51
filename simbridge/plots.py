"""The ground-effect force against altitude for several rho at hover speeds (thesis fig. 3.2)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from simbridge.effects.ground import (
    cutoff_height_m,
    ground_effect_force_n,
    hover_rotor_speed_in_ground_effect_rad_s,
)
from simbridge.vehicle import Vehicle


def ground_effect_curve(vehicle: Vehicle, rho: float, altitudes_m: np.ndarray) -> np.ndarray:
    """Total ground-effect force [N] of four level rotors hovering at each altitude."""
    cut = cutoff_height_m(rho, vehicle.rotor_radius_m)
    out = []
    for z in altitudes_m:
        n = hover_rotor_speed_in_ground_effect_rad_s(
            vehicle.weight_n, vehicle.thrust_coefficient_n_s2, z, rho, vehicle.rotor_radius_m, cut
        )
        thrust = vehicle.thrust_coefficient_n_s2 * n * n
        out.append(4.0 * ground_effect_force_n(thrust, z, rho, vehicle.rotor_radius_m, cut))
    return np.asarray(out)


def plot_ground_effect(
    vehicle: Vehicle, rhos: list[float], out: Path, max_altitude_m: float = 0.5
) -> Path:
    altitudes = np.linspace(0.005, max_altitude_m, 400)
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for rho in rhos:
        ax.plot(altitudes, ground_effect_curve(vehicle, rho, altitudes), label=f"rho = {rho:g}")
    ax.axhline(vehicle.weight_n, color="0.6", lw=0.8, ls="--", label="weight")
    ax.set_xlabel("rotor altitude above the surface [m]")
    ax.set_ylabel("ground effect, four rotors [N]")
    ax.set_title(f"Ground effect (thesis eq. 3.4) at hover rotor speeds, {vehicle.name} vehicle")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
