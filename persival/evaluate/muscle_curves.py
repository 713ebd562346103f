"""Calibration curves of the arm: every muscle's moment about the elbow against the angle.

Each muscle is solved on its own (module persival.model.muscle_unit) at the origin-insertion
length of each angle, passive (activation 0) and fully active (1), by continuation along the
angle. Its moment is ``-T dL/dtheta``. Summed with gravity and the passive joint these curves
predict the equilibria: the hanging arm (all passive) and the reach of any muscle set at full
activation. They are the tool for editing a model file (mesh poses, bows, fibre prestretch)
without solving full states; ``persival simulate`` gives the exact equilibrium of one state.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.campaign.moment_table import sweep_muscle
from persival.figures import save_figure
from persival.model.arm import ArmModel
from persival.vocabulary import MUSCLES


def muscle_curves(arm: ArmModel, angles=None, progress=None) -> dict:
    """Passive and active tension (N) and moment (N mm) of every muscle at each angle (deg).

    Unreached points (a solve that did not converge) are NaN.
    """
    lower, upper = arm.spec.joint.limits_deg
    angles = np.arange(lower, upper + 1e-9, 10.0) if angles is None else np.asarray(angles, dtype=float)
    out = {"angles_deg": angles}
    for muscle in arm.spec.ordered_muscles():
        sweeps = {}
        for activation in (0.0, 1.0):
            sweeps[activation] = sweep_muscle(arm, muscle, angles, activation)  # continuation along theta
            if progress is not None:
                progress(muscle.name, activation)
        passive, active = sweeps[0.0], sweeps[1.0]
        out[muscle.name] = {
            "length_mm": passive["length_mm"],
            "dL_dtheta_mm_per_rad": passive["dL_dtheta_mm_per_rad"],
            "passive_tension_N": passive["tension_N"],
            "active_tension_N": active["tension_N"],
            "passive_moment_Nmm": passive["moment_Nmm"],
            "active_moment_Nmm": active["moment_Nmm"],
        }
    out["external_moment_Nmm"] = np.array([arm.external_moment(np.radians(t))[0] for t in angles])
    return out


def predicted_equilibrium(curves: dict, activations) -> float:
    """Estimated elbow angle (deg) for activations in {0, 1} per muscle (other values are
    interpolated linearly between the passive and active curves: an estimate only).

    The first angle where the net moment turns from flexing to extending (stable equilibrium).
    """
    angles = curves["angles_deg"]
    net = curves["external_moment_Nmm"].copy()
    for name, a in zip(MUSCLES, activations):
        c = curves[name]
        net = net + (1.0 - a) * c["passive_moment_Nmm"] + a * c["active_moment_Nmm"]
    if net[0] <= 0:
        return float(angles[0])
    for k in range(len(angles) - 1):
        if net[k] > 0 >= net[k + 1]:
            return float(angles[k] + (angles[k + 1] - angles[k]) * net[k] / (net[k] - net[k + 1]))
    return float("nan")


REPORTED_SETS = {
    "hanging (all 0)": (0, 0, 0, 0, 0),
    "biceps 1": (1, 0, 0, 0, 0),
    "brachialis 1": (0, 1, 0, 0, 0),
    "brachioradialis 1": (0, 0, 1, 0, 0),
    "flexors 1": (1, 1, 1, 0, 0),
    "triceps 1": (0, 0, 0, 1, 0),
    "extensors 1": (0, 0, 0, 1, 1),
}


def plot_curves(curves: dict, path: str | Path) -> Path:
    """One panel of passive moments, one of active moments, with the external load."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    angles = curves["angles_deg"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharex=True)
    panels = ((axes[0], "passive_moment_Nmm", "passive (activation 0)"),
              (axes[1], "active_moment_Nmm", "fully active (activation 1)"))
    for ax, key, title in panels:
        for name in MUSCLES:
            ax.plot(angles, curves[name][key], marker="o", ms=3, label=name)
        ax.plot(angles, -curves["external_moment_Nmm"], "k--", label="gravity + joint (to overcome)")
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(title)
        ax.set_xlabel("elbow angle (deg)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("moment about the elbow (N mm, flexion +)")
    # beside the panels: inside, the legend covered the curves of the real sweeps
    axes[1].legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    profile = f" ({curves['profile']} profile)" if curves.get("profile") else ""
    fig.suptitle(f"FE arm{profile}: each muscle's moment, swept alone along the elbow angle", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)
