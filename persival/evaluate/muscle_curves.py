"""Calibration curves of the arm: every muscle's moment about the elbow against the angle.

Each muscle is solved on its own (module persival.model.arm.muscle_unit) at the origin-insertion
length of each angle, passive (activation 0) and fully active (1), by continuation along the
angle. Its moment is ``-T dL/dtheta``. Summed with gravity and the passive joint these curves
predict the equilibria: the hanging arm (all passive) and the reach of any muscle set at full
activation. They are the tool for editing a model file (mesh poses, bows, fibre prestretch)
without solving full states; ``persival simulate`` gives the exact equilibrium of one state.
Where the model's response tables are built (``persival tables``, levels 0 and 1 among theirs),
each point is the same FE equilibrium by the tables' exact path (Newton from the tabulated
states, persival.tables.table_solve): seconds instead of minutes of continuation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.figures import save_figure
from persival.model.arm.arm_model import ArmModel
from persival.model.fe.solver import ConvergenceError
from persival.tables.continuation import sweep_muscle
from persival.vocabulary import MUSCLES


def muscle_curves(arm: ArmModel, angles=None, progress=None, tables=None) -> dict:
    """Passive and active tension (N) and moment (N mm) of every muscle at each angle (deg).

    ``tables``: a :class:`~persival.tables.table_solve.TableSolver` of this arm to take the
    states from (default: continuation sweeps). Unreached points (a solve that did not
    converge) are NaN.
    """
    lower, upper = arm.spec.joint.limits_deg
    angles = np.arange(lower, upper + 1e-9, 10.0) if angles is None else np.asarray(angles, dtype=float)
    out = {"angles_deg": angles}
    for muscle in arm.spec.ordered_muscles():
        sweeps = {}
        for activation in (0.0, 1.0):
            sweeps[activation] = (sweep_muscle(arm, muscle, angles, activation) if tables is None  # along theta
                                  else _from_tables(tables, arm, muscle, angles, activation))
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


def _from_tables(tables, arm: ArmModel, muscle, angles: np.ndarray, activation: float) -> dict:
    """sweep_muscle's numbers at ``angles`` by the tables' exact path, one state at a time."""
    geometry = np.array([arm.muscle_length(muscle, t) for t in angles])
    tension, moment = np.full(len(angles), np.nan), np.full(len(angles), np.nan)
    for k, theta in enumerate(angles):
        try:
            state, _ = tables.muscle_state(muscle.name, float(theta), activation)
        except ConvergenceError:
            continue
        tension[k], moment[k] = state.tension, state.moment
    return {"length_mm": geometry[:, 0], "dL_dtheta_mm_per_rad": geometry[:, 1], "tension_N": tension,
            "moment_Nmm": moment}


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


#: Physiological moment arms (mm, flexion positive) the model is calibrated against (after
#: Murray et al. 1995, docs/design/arm_model_record.md): (muscle, angle range in deg, lowest, highest; None: no upper bound).
#: A range of None spans the joint's limits.
MOMENT_ARM_BANDS_MM = (
    ("biceps", (85.0, 95.0), 35.0, 45.0),
    ("biceps", (135.0, 145.0), 25.0, None),
    ("brachialis", (85.0, 95.0), 18.0, 30.0),
    ("brachialis", (135.0, 145.0), 18.0, None),
    ("brachioradialis", (90.0, 120.0), 45.0, 70.0),
    ("triceps", None, -25.0, -15.0),
    ("anconeus", None, -12.0, -5.0),
)


def moment_arms(curves: dict) -> dict[str, np.ndarray]:
    """Each muscle's moment arm (mm, flexion +) from its active FE sweep, M / T; where the
    tension is below 1 N (a slack muscle's M / T is noise) from the line of action, -dL/dtheta;
    NaN where the sweep did not converge."""
    out = {}
    for name in MUSCLES:
        c = curves[name]
        T, M = np.asarray(c["active_tension_N"], float), np.asarray(c["active_moment_Nmm"], float)
        line = -np.asarray(c["dL_dtheta_mm_per_rad"], float)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[name] = np.where(np.isnan(T), np.nan, np.where(np.abs(T) > 1.0, M / T, line))
    return out


def band_check(curves: dict) -> list[dict]:
    """Every band of MOMENT_ARM_BANDS_MM against the model: the moment arm's extremes over the
    band's angles (sampled at the curves' angles, interpolated at the band's ends); ``inside``
    is None where a sweep there did not converge."""
    angles = np.asarray(curves["angles_deg"], float)
    arms = moment_arms(curves)
    rows = []
    for name, span, low, high in MOMENT_ARM_BANDS_MM:
        lo_deg, hi_deg = span if span is not None else (angles[0], angles[-1])
        inside = np.concatenate([[lo_deg], angles[(angles > lo_deg) & (angles < hi_deg)], [hi_deg]])
        values = np.interp(inside, angles, arms[name])
        ok = None if np.isnan(values).any() else bool(np.all(values >= low) and (high is None or np.all(values <= high)))
        rows.append({"muscle": name, "angles_deg": [float(lo_deg), float(hi_deg)], "band_mm": [low, high],
                     "model_mm": [float(values.min()), float(values.max())], "inside": ok})
    return rows


def _moment_panels(curves: dict, axes) -> None:
    angles = curves["angles_deg"]
    for ax, key, title in ((axes[0], "passive_moment_Nmm", "passive (activation 0)"),
                           (axes[1], "active_moment_Nmm", "fully active (activation 1)")):
        for name in MUSCLES:
            ax.plot(angles, curves[name][key], marker="o", ms=3, label=name)
        ax.plot(angles, -curves["external_moment_Nmm"], "k--", label="gravity + joint (to overcome)")
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(title)
        ax.set_ylabel("moment about the elbow (N mm, flexion +)")


def _moment_arm_panel(curves: dict, ax) -> None:
    angles = np.asarray(curves["angles_deg"], float)
    arms = moment_arms(curves)
    colours = {name: f"C{i}" for i, name in enumerate(MUSCLES)}
    top, bottom = 80.0, -40.0
    for name, span, low, high in MOMENT_ARM_BANDS_MM:  # behind the curves
        lo_deg, hi_deg = span if span is not None else (angles[0], angles[-1])
        ax.fill_between([lo_deg, hi_deg], low, top if high is None else high, color=colours[name], alpha=0.15, lw=0)
    for name in MUSCLES:
        ax.plot(angles, arms[name], marker="o", ms=3, color=colours[name], label=name)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_ylim(bottom, top)
    ax.set_title("moment arm M / T (shaded: physiological bands, Murray et al. 1995)")
    ax.set_ylabel("moment arm (mm, flexion +)")


def _strength_panel(curves: dict, ax) -> None:
    """All flexors at 1 (extensors passive) and all extensors at 1 (flexors passive)."""
    angles = curves["angles_deg"]
    flexors, extensors = ("biceps", "brachialis", "brachioradialis"), ("triceps", "anconeus")

    def total(active):
        return sum(curves[n]["active_moment_Nmm" if n in active else "passive_moment_Nmm"] for n in MUSCLES)

    ax.plot(angles, total(flexors), "C3", marker="o", ms=3, label="flexors at 1")
    ax.plot(angles, total(extensors), "C0", marker="o", ms=3, label="extensors at 1")
    ax.plot(angles, -curves["external_moment_Nmm"], "k--", label="gravity + joint (to overcome)")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_title("maximal flexion and extension moment")
    ax.set_ylabel("moment about the elbow (N mm, flexion +)")
    ax.legend(fontsize=8)


def plot_curves(curves: dict, path: str | Path) -> Path:
    """Four panels: passive and active moments with the external load, moment arms with the
    physiological bands behind, and the maximal flexion and extension moments."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(13, 9), sharex=True)
    _moment_panels(curves, axes[0])
    _moment_arm_panel(curves, axes[1, 0])
    _strength_panel(curves, axes[1, 1])
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("elbow angle (deg)")
    # beside the panels: inside, the legend covered the curves of the real sweeps
    axes[0, 1].legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    profile = f" ({curves['profile']} profile)" if curves.get("profile") else ""
    fig.suptitle(f"FE arm{profile}: each muscle swept alone along the elbow angle", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)
