"""Surface surrogates against held-out states (docs/theory.md, 8.1 metrics, "error propagation").

Reads fitted surrogates from disk (``persival surrogate fit-sg`` / ``adapt``) and a campaign store
of states they were not fitted to (e.g. ``persival campaign run --design random``), and
tabulates MaxAE / MAE / MaxRE / MRE of the muscle surface plus the elbow-angle error. Every
number says what it was measured on: the simulator of the states (FE arm with its profile, the
analytic stand-in or an external FE code: ``describe_source``) and how many there were. For an
adaptive surrogate it also replays the refinement: the grid after every step is a prefix of the
final grid (new points are appended), and the FE values at those points are the final
interpolant's values there (interpolation property), so every intermediate surrogate is refitted
exactly without solving or reading any FE state again.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from persival.evaluate.metrics import state_errors, summarize
from persival.figures import save_figure
from persival.surrogate.dataset import describe_source
from persival.surrogate.sparse_grid import SparseGrid
from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate

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
    source: dict = field(default_factory=dict)  # describe_source: simulator, profile, states, label


def load_held_out(store_path: str | Path, muscles="biceps") -> HeldOutStates:
    """The done states of a campaign store (failed or missing states are left out).

    ``muscles``: one surface name, a surrogate's label of several ("biceps+brachialis+...", the
    order of its node list) or a sequence of names; several surfaces are concatenated in that order.
    """
    from persival.campaign.store import CampaignStore

    names = muscles.split("+") if isinstance(muscles, str) else list(muscles)
    with CampaignStore.open(store_path) as store:
        reference = store.reference
        missing = [m for m in names if m not in reference.surfaces]
        if missing:
            raise ValueError(f"{store_path} has no surface {missing[0]!r}; it has {sorted(reference.surfaces)}")
        done = np.flatnonzero(store.done_mask())
        if not len(done):
            raise ValueError(f"{store_path} has no done state to test against")
        positions = np.concatenate([store.surface_positions(m, done) for m in names], axis=1)
        reference_points = np.concatenate([np.asarray(reference.surfaces[m].reference_points) for m in names])
        return HeldOutStates(
            store.activations[done], positions, store.elbow_angles()[done], reference_points,
            reference.model_hash, str(store_path), describe_source(store.summary(), reference.description, len(done)),
        )


def _predict_errors(predict, test: HeldOutStates) -> dict[str, np.ndarray]:
    positions, angles = predict(test.activations)
    errors = state_errors(positions, test.positions, test.positions - test.reference_points)
    errors["angle_error_deg"] = np.abs(angles - test.angles)
    return errors


def surrogate_errors(surrogate: SparseGridSurrogate, test: HeldOutStates) -> dict[str, np.ndarray]:
    """Per-state errors of one surrogate on the held-out states (same model required)."""
    if surrogate.metadata.get("model_hash") != test.model_hash:
        raise ValueError(
            f"the surrogate was fitted to model {str(surrogate.metadata.get('model_hash'))[:12]}, the test "
            f"store {test.store} holds model {test.model_hash[:12]}: they are not comparable"
        )
    if surrogate.n_nodes != test.positions.shape[1]:
        raise ValueError(f"surrogate has {surrogate.n_nodes} surface nodes, the test states {test.positions.shape[1]}")
    return _predict_errors(surrogate.predict_with_angle, test)


def refinement_path(surrogate: SparseGridSurrogate) -> list[tuple[int, SparseGridSurrogate]]:
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


def training_source(metadata: dict, n_states: int) -> str:
    """What a surrogate was fitted to, e.g. "analytic stand-in, 243 states", from its metadata
    (fit-sg keeps the store's simulator kind and profile; adapt its simulator spec)."""
    simulator = metadata.get("simulator")
    if isinstance(simulator, dict):
        kind, profile = simulator.get("kind"), simulator.get("options", {}).get("profile")
    else:
        kind, profile = simulator, metadata.get("profile")
    return describe_source({"simulator": kind or "unknown"}, {"profile": profile} if profile else {}, n_states)["label"]


def accuracy_report(surrogates: dict[str, str | Path], test_store: str | Path) -> dict:
    """Summary rows per surrogate and, for adaptive ones, the error after every refinement step.

    ``states`` is the number of states a surrogate was fitted to (its grid points), ``source``
    what they are; ``test_source`` says what the held-out states are.
    """
    loaded = {label: SparseGridSurrogate.load(path) for label, path in surrogates.items()}
    muscles = {s.muscle for s in loaded.values()}
    if len(muscles) != 1:
        raise ValueError(f"the surrogates interpolate different muscles: {sorted(muscles)}")
    test = load_held_out(test_store, muscles.pop())
    rows, paths = {}, {}
    for label, surrogate in loaded.items():
        kind = "adaptive" if "adaptive" in surrogate.metadata else f"regular level {surrogate.metadata.get('level')}"
        n = surrogate.grid.n_points
        rows[label] = {"states": n, "source": training_source(surrogate.metadata, n), "kind": kind,
                       **summarize(surrogate_errors(surrogate, test))}
        path = refinement_path(surrogate)
        if path:
            paths[label] = [{"states": n, **summarize(_predict_errors(s.predict_with_angle, test))} for n, s in path]
    return {"test_store": str(test_store), "test_states": len(test.angles), "test_source": test.source,
            "surrogates": rows, "refinement": paths}


def _legend_name(label: str, kind: str) -> str:
    """"regular level 1", not "regular (regular level 1)": the kind only where it adds something."""
    return kind if label.lower() in kind.lower() else f"{label} ({kind})"


def _readable_log_axis(ax, values) -> None:
    """Log scale with plain labels at 1-2-5 steps and no minor labels (they overlapped within a
    decade); the limits span at least a factor 2.5, so at least one labelled tick shows."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    values = np.asarray([v for v in values if np.isfinite(v) and v > 0])
    ax.set_yscale("log")
    if len(values):
        ax.set_ylim(values.min() / 1.6, values.max() * 1.6)
    ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def plot_accuracy(report: dict, path: str | Path) -> Path:
    """Held-out MaxAE and MAE against the number of training states: adaptive paths as lines,
    regular grids as markers; titles and axes name the simulator of the states."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    metrics = [("max MaxAE_mm", "largest node error (mm)"), ("mean MAE_mm", "mean node error (mm)"),
               ("max angle_error_deg", "largest elbow-angle error (deg)")]
    colours = {label: f"C{i}" for i, label in enumerate(report["surrogates"])}
    simulator = report.get("test_source", {}).get("label", "").rsplit(",", 1)[0] or "the simulator"
    for ax, (key, title) in zip(axes, metrics):
        for label, steps in report["refinement"].items():
            ax.plot([s["states"] for s in steps], [s[key] for s in steps], "o-", ms=3, color=colours[label],
                    label=f"{label}, after each refinement step")
        for label, row in report["surrogates"].items():
            ax.plot(row["states"], row[key], "s", ms=8, color=colours[label], label=_legend_name(label, row["kind"]))
        _readable_log_axis(ax, [s[key] for steps in report["refinement"].values() for s in steps]
                           + [row[key] for row in report["surrogates"].values()])
        ax.set_xlabel(f"training states ({simulator})")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"surrogates vs {report['test_states']} held-out states of the {simulator}")
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
