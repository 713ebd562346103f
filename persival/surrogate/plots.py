"""Figures of the surrogate stage: alpha_opt(Theta) and a network's training history."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.figures import save_figure
from persival.vocabulary import MUSCLES

__all__ = ["plot_activation_model", "plot_training_history"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_activation_model(model, path: str | Path, source_label: str = "", solved=None) -> Path:
    """One curve per muscle of the least-effort activations over the model's range.

    ``solved``: an optional :class:`~persival.surrogate.inverse.InverseSolution` drawn as markers.
    """
    plt = _pyplot()
    theta = np.linspace(*model.range_deg, 600)
    alpha = model.predict(theta)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for m, name in enumerate(MUSCLES):
        ax.plot(theta, alpha[:, m], color=f"C{m}", label=name, lw=1.8)
        if solved is not None:
            ax.plot(solved.target_deg, solved.activations[:, m], "o", color=f"C{m}", ms=4)
    for note in model.branch_notes:
        if "jump" in note:
            ax.axvline(note["angle_deg"], color="0.6", ls=":", lw=1)
    ax.set_xlabel("elbow angle Theta (deg)")
    ax.set_ylabel("activation alpha_opt")
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlim(*model.range_deg)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=9, ncols=2)
    title = "least-effort activations  min |Theta - theta(alpha)| + 0.05 sum(alpha)"
    ax.set_title(title + (f"\nSG of {source_label}" if source_label else ""), fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_training_history(history: list[dict], path: str | Path, title: str = "") -> Path:
    """Validation MAE (mm) per epoch and coordinate, one line per fold, and the losses."""
    plt = _pyplot()
    fig, (ax_mae, ax_loss) = plt.subplots(1, 2, figsize=(11, 4))
    folds = sorted({h["fold"] for h in history})
    epochs_per_fold = max(h["epoch"] for h in history)
    for f in folds:
        rows = [h for h in history if h["fold"] == f]
        epoch = np.array([h["epoch"] for h in rows]) + f * epochs_per_fold
        mae = np.array([h["val_mae_mm"] for h in rows])
        for k, axis in enumerate("xyz"):
            ax_mae.plot(epoch, mae[:, k], color=f"C{k}", lw=1.2, label=f"{axis} coordinate" if f == folds[0] else None)
        ax_loss.plot(epoch, [h["train_loss"] for h in rows], color="C3", lw=1, label="training" if f == folds[0] else None)
        ax_loss.plot(epoch, [h["val_loss"] for h in rows], color="C4", lw=1, label="validation" if f == folds[0] else None)
    for ax in (ax_mae, ax_loss):
        for f in folds[1:]:
            ax.axvline(f * epochs_per_fold, color="0.8", lw=0.8)
        ax.set_yscale("log")
        ax.set_xlabel(f"epoch ({len(folds)} folds of {epochs_per_fold})")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=9)
    ax_mae.set_ylabel("validation MAE (mm)")
    ax_loss.set_ylabel("MSE loss")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)
