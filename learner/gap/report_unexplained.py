"""The report's account of what the catalogue cannot explain: the learnt residual's model file,
a corrected world that carries it (`learned_residual`), its partial-dependence plot and the
report.md section."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from learner.gap.diagnose import Diagnosis
from learner.gap.numbers import fig, pct
from learner.gap.regimes import describe_range
from simbridge.effects.learned import save_residual_model

MODEL_FILE = "learned_residual.npz"
WORLD_FILE = "corrected_world_learned.yaml"
PLOT_FILE = "unexplained.png"


def write_learned(diagnosis: Diagnosis, corrected_yaml: str, out: Path) -> dict[str, Path]:
    """The model, the corrected world with it and the shape plot, where the learnt world is
    offered (it shrinks what the catalogue leaves on flights it was not trained on:
    learner/gap/structure.py); nothing otherwise, and no stale files of an earlier run."""
    offered = (diagnosis.unexplained.get("learned_world") or {}).get("offered", False)
    if diagnosis.learned_model is None or not offered:
        for name in (MODEL_FILE, WORLD_FILE, PLOT_FILE):
            (out / name).unlink(missing_ok=True)
        return {}
    meta = {"share": diagnosis.unexplained.get("share")}
    paths = {"learned_model": save_residual_model(out / MODEL_FILE, diagnosis.learned_model, meta)}
    data = yaml.safe_load(corrected_yaml)
    data["effects"] = [e for e in data.get("effects") or [] if e.get("name") != "learned_residual"]
    data["effects"].append({"name": "learned_residual", "model_path": MODEL_FILE})
    header = (
        "# Corrected by `groundfx gap diagnose`: the nominal world, the catalogue effects found\n"
        f"# and the residual they leave, learnt ({MODEL_FILE}, read from this folder).\n"
    )
    paths["world_learned"] = out / WORLD_FILE
    paths["world_learned"].write_text(header + yaml.safe_dump(data, sort_keys=False))
    shape = diagnosis.unexplained.get("shape")
    if shape:
        paths["plot_unexplained"] = _plot(shape, out / PLOT_FILE)
    return paths


def _plot(shape: dict[str, Any], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = {
        "height_log1p_radii": "height above the surface (rotor radii)",
        "time_since_takeoff_s": "time since take-off (s)",
        "horizontal_speed_m_s": "horizontal speed (m/s)",
        "thrust_per_rotor_over_quarter_weight": "rotor thrust / (weight / 4)",
    }
    fig, axes = plt.subplots(1, len(shape), figsize=(4 * len(shape), 3.4))
    for ax, (name, pd) in zip(np.atleast_1d(axes), shape.items(), strict=True):
        grid = np.asarray(pd["grid"])
        if name == "height_log1p_radii":
            grid = np.expm1(grid)
        f = np.asarray(pd["force_n"]) * 1000
        axes_ = ("forward", "left", "up")  # the heading frame
        for i, (axis, colour) in enumerate(zip(axes_, ("tab:red", "tab:green", "tab:blue"),
                                               strict=True)):  # fmt: skip
            ax.plot(grid, f[:, i], color=colour, label=axis)
        ax.set(xlabel=labels.get(name, name), ylabel="learnt residual force (mN)")
        ax.axhline(0.0, color="grey", lw=0.5)
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.suptitle("what the catalogue leaves, learnt: partial dependence (others as logged)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def markdown_section(diagnosis: Diagnosis) -> list[str]:
    u = diagnosis.unexplained
    if not u:
        return []
    lines = ["", "## Unexplained", "", u["sentence"] + "."]
    where = u.get("where") or []
    if where:
        lines += ["", "Where the corrected residual still is (significant regime bins):", ""]
        for w in where:
            lines.append(
                f"- {describe_range(w['variable'], w['low'], w['high'])}, {w['component']}: "
                f"{w['mean_share'] * 100:+.1f}% of the weight"
            )
    learned = diagnosis.gap.get("force_rms_n_learned")
    offer = u.get("learned_world") or {}
    if learned:
        lines += [
            "",
            f"Held out: force gap {fig(learned['before'], '.2f', 1000, 'mN')} -> "
            f"{fig(learned['after_catalogue'], '.2f', 1000, 'mN')} with the catalogue (shrink "
            f"{pct(learned['shrink_catalogue'])}) -> {fig(learned['after'], '.2f', 1000, 'mN')} "
            f"with the learnt residual too (shrink {pct(learned['shrink'])}).",
        ]
    if offer.get("offered"):
        lines += ["", f"`{WORLD_FILE}` carries it as a `learned_residual` effect: {offer['why']}."]
        if u.get("shape"):
            lines += ["", f"![unexplained]({PLOT_FILE})"]
    elif offer:
        lines += ["", f"`{WORLD_FILE}` is not written: {offer['why']}."]
    return lines
