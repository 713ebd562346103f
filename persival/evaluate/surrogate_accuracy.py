"""Surface surrogates against held-out FE states (SPEC section 7 metrics, "error propagation").

Reads fitted surrogates from disk (``persival surrogate fit-sg`` / ``adapt``) and a campaign store
of FE states they were not fitted to (e.g. ``persival campaign run --design random``), and
tabulates MaxAE / MAE / MaxRE / MRE of the muscle surface plus the elbow-angle error. For an
adaptive surrogate it also replays the refinement: the grid after every step is a prefix of the
final grid (new points are appended), and the FE values at those points are the final
interpolant's values there (interpolation property), so every intermediate surrogate is refitted
exactly without solving or reading any FE state again.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from persival.evaluate.metrics import state_errors, summarize
from persival.figures import save_figure
from persival.surrogate.sparse_grid import SparseGrid
from persival.surrogate.surface_surrogate import SurfaceSurrogate

__all__ = ["HeldOutStates", "load_held_out", "surrogate_errors", "refinement_path", "accuracy_report",
           "plot_accuracy"]


@dataclass
class HeldOutStates:
    activations: np.ndarray  # (m, 5)
    positions: np.ndarray  # (m, n_nodes, 3) mm
    angles: np.ndarray  # (m,) deg
    reference_points: np.ndarray  # (n_nodes, 3) mm, the mesh pose the displacements are measured from
    model_hash: str
    store: str


def load_held_out(store_path: str | Path, muscle: str = "biceps") -> HeldOutStates:
    """The done states of a campaign store (failed or missing states are left out)."""
    from persival.campaign.store import CampaignStore

    with CampaignStore.open(store_path) as store:
        reference = store.reference
        if muscle not in reference.surfaces:
            raise ValueError(f"{store_path} has no surface {muscle!r}; it has {sorted(reference.surfaces)}")
        done = np.flatnonzero(store.done_mask())
        if not len(done):
            raise ValueError(f"{store_path} has no done state to test against")
        return HeldOutStates(
            store.activations[done], store.surface_positions(muscle, done), store.elbow_angles()[done],
            np.asarray(reference.surfaces[muscle].reference_points), reference.model_hash, str(store_path),
        )


def _predict_errors(predict, test: HeldOutStates) -> dict[str, np.ndarray]:
    positions, angles = predict(test.activations)
    errors = state_errors(positions, test.positions, test.positions - test.reference_points)
    errors["angle_error_deg"] = np.abs(angles - test.angles)
    return errors


def surrogate_errors(surrogate: SurfaceSurrogate, test: HeldOutStates) -> dict[str, np.ndarray]:
    """Per-state errors of one surrogate on the held-out states (same model required)."""
    if surrogate.metadata.get("model_hash") != test.model_hash:
        raise ValueError(
            f"the surrogate was fitted to model {str(surrogate.metadata.get('model_hash'))[:12]}, the test "
            f"store {test.store} holds model {test.model_hash[:12]}: they are not comparable"
        )
    if surrogate.n_nodes != test.positions.shape[1]:
        raise ValueError(f"surrogate has {surrogate.n_nodes} surface nodes, the test states {test.positions.shape[1]}")
    return _predict_errors(surrogate.predict_with_angle, test)


def refinement_path(surrogate: SurfaceSurrogate) -> list[tuple[int, SurfaceSurrogate]]:
    """(grid points, surrogate) after every refinement step of an adaptive surrogate ([] otherwise)."""
    sizes = surrogate.metadata.get("adaptive", {}).get("grid_points_per_step", [])
    grid = surrogate.grid
    out = []
    for n in sizes:
        sub = SparseGrid.from_levels_indices(grid.levels[:n], grid.indices[:n], grid.degree)
        sub.fit(grid.predict(grid.points[:n]), center=True)
        step = copy.copy(surrogate)  # same surface and metadata, the step's grid
        step.grid = sub
        out.append((int(n), step))
    return out


def accuracy_report(surrogates: dict[str, str | Path], test_store: str | Path) -> dict:
    """Summary rows per surrogate and, for adaptive ones, the error after every refinement step."""
    loaded = {label: SurfaceSurrogate.load(path) for label, path in surrogates.items()}
    muscles = {s.muscle for s in loaded.values()}
    if len(muscles) != 1:
        raise ValueError(f"the surrogates interpolate different muscles: {sorted(muscles)}")
    test = load_held_out(test_store, muscles.pop())
    rows, paths = {}, {}
    for label, surrogate in loaded.items():
        kind = "adaptive" if "adaptive" in surrogate.metadata else f"regular level {surrogate.metadata.get('level')}"
        rows[label] = {"fe_states": surrogate.grid.n_points, "kind": kind,
                       **summarize(surrogate_errors(surrogate, test))}
        path = refinement_path(surrogate)
        if path:
            paths[label] = [{"fe_states": n, **summarize(_predict_errors(s.predict_with_angle, test))} for n, s in path]
    return {"test_store": str(test_store), "test_states": len(test.angles), "surrogates": rows, "refinement": paths}


def plot_accuracy(report: dict, path: str | Path) -> Path:
    """Held-out MaxAE and MAE against the number of FE states: adaptive paths as lines, regular grids as markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    metrics = [("max MaxAE_mm", "largest node error (mm)"), ("mean MAE_mm", "mean node error (mm)"),
               ("max angle_error_deg", "largest elbow-angle error (deg)")]
    colours = {label: f"C{i}" for i, label in enumerate(report["surrogates"])}
    for ax, (key, title) in zip(axes, metrics):
        for label, steps in report["refinement"].items():
            ax.plot([s["fe_states"] for s in steps], [s[key] for s in steps], "o-", ms=3, color=colours[label],
                    label=f"{label}: after each refinement step")
        for label, row in report["surrogates"].items():
            ax.plot(row["fe_states"], row[key], "s", ms=8, color=colours[label], label=f"{label} ({row['kind']})")
        ax.set_xlabel("FE states")
        ax.set_yscale("log")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"surrogates vs {report['test_states']} held-out FE states")
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
