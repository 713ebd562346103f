"""The motion-and-load model in one picture: activations against the elbow angle for a few loads,
and the required against the reachable moment."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.surrogate.motion_model import MotionActivationModel
from persival.vocabulary import MUSCLES

__all__ = ["plot_motion_model"]


def plot_motion_model(model: MotionActivationModel, path: str | Path, loads=(0.0, 1.0, 2.0, 5.0)) -> Path:
    """Activations against Theta for a few loads (zero velocity and acceleration); dotted where
    the load cannot be held (the saturated best effort); last panel: required vs reachable moment."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from persival.figures import save_figure

    theta = np.linspace(*model.range_deg, 321)
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), sharex=True)
    for k, load in enumerate(loads):
        motion = np.column_stack([theta, 0 * theta, 0 * theta, np.full_like(theta, load)])
        a, ok = model.predict(motion)
        colour = f"C{k}"
        for m, ax in enumerate(axes.flat[:5]):
            ax.plot(theta, np.where(ok, a[:, m], np.nan), color=colour, label=f"{load:g} kg")
            ax.plot(theta, np.where(ok, np.nan, a[:, m]), color=colour, ls=":")
        axes.flat[5].plot(theta, model.required_moment(motion) / 1e3, color=colour, label=f"required, {load:g} kg")
    for m, ax in enumerate(axes.flat[:5]):
        ax.set(title=MUSCLES[m], ylim=(-0.03, 1.03))
        ax.grid(alpha=0.3)
    axes.flat[5].plot(model.theta, model.m_max / 1e3, "k-", label="max muscle moment")
    axes.flat[5].plot(model.theta, model.m_min / 1e3, "k--", label="min muscle moment")
    axes.flat[5].set(title="moment about the elbow (N m)")
    axes.flat[5].grid(alpha=0.3)
    axes.flat[5].legend(fontsize=7)
    axes.flat[0].legend(fontsize=8)
    for ax in axes[1]:
        ax.set_xlabel("elbow angle (deg), zero velocity and acceleration")
    fig.suptitle(f"least-effort activations (sum of a^2), loads at {model.params['hand_distance_mm']:.0f} mm; "
                 "dotted: the load cannot be held")
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
