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
    vehicle: Vehicle, rhos: list[float], out: Path, max_altitude_m: float = 0.15
) -> Path:
    """The curves over the first `max_altitude_m` (where the effect lives), each curve's
    cut-off height marked: below it the thesis holds the height (section 3.3.1), so a curve
    is flat there, and its peak depends on how close its cut-off sits to the singular height
    R sqrt(rho) / 4 (rho 0.5 is cut at 1 cm, 2 mm above its singularity, and peaks highest)."""
    altitudes = np.linspace(0.002, max_altitude_m, 600)
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for rho in rhos:
        (line,) = ax.plot(
            altitudes, ground_effect_curve(vehicle, rho, altitudes), label=f"rho = {rho:g}"
        )
        cut = cutoff_height_m(rho, vehicle.rotor_radius_m)
        ax.plot(
            [cut], ground_effect_curve(vehicle, rho, np.array([cut])), "o", color=line.get_color()
        )
    ax.axhline(vehicle.weight_n, color="0.6", lw=0.8, ls="--", label="weight")
    ax.plot([], [], "o", color="0.3", label="cut-off height (flat below)")
    ax.text(
        0.98,
        0.3,
        "the cut-off: the smallest whole cm above R sqrt(rho) / 4;\n"
        "the nearer it is to that singular height, the higher the peak",
        transform=ax.transAxes,
        ha="right",
        fontsize=8,
        color="0.3",
    )
    ax.set_xlabel("rotor altitude above the surface [m]")
    ax.set_ylabel("ground effect, four rotors [N]")
    ax.set_title(
        f"Ground effect at hover rotor speeds (thesis eq. 3.4), {vehicle.name}, "
        f"R = {vehicle.rotor_radius_m * 100:.1f} cm"
    )
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
