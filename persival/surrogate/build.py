"""The surrogate stage's steps, each reading the previous artifact from disk and writing its own.

The CLI (``persival fit-sg / inverse / data / train``) and ``persival run`` both call these, so
the command line is a thin layer over the Python API.

    campaign store --fit_sparse_grid--> sg/ --build_activation_model--> activation_model.json
      sg/ + activation_model.json --make_training_data--> data/ --train_network--> network/
"""

from __future__ import annotations

from pathlib import Path

from persival.surrogate.activation_model import AngleActivationModel
from persival.surrogate.dataset import Dataset
from persival.surrogate.inverse import InverseProblem, InverseSolution
from persival.surrogate.open import load_surrogate
from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate
from persival.surrogate.training_data import open_dataset

__all__ = ["parse_muscles", "fit_sparse_grid", "solve_inverse", "build_activation_model", "make_training_data",
           "train_network", "load_angle_surrogate", "fit_structured"]


def parse_muscles(text: str | None):
    """``all`` (or None) -> every surface; ``biceps,triceps`` -> those."""
    if text is None or text.strip().lower() == "all":
        return None
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise ValueError("--muscle: give a muscle name, a comma-separated list, or all")
    return names


def fit_sparse_grid(store: str | Path, out: str | Path, muscles=None, degree: int = 3) -> SparseGridSurrogate:
    surrogate = SparseGridSurrogate(muscles, degree).fit(store)
    surrogate.save(out)
    return surrogate


def fit_structured(store: str | Path, out: str | Path, profile: str = "quick", model_file=None, tables=None,
                   tolerance_mm: float | None = None, frame: str = "world", progress=None):
    """The structured surrogate of the FE arm, fitted to its response tables, answering the
    surfaces of ``store`` (a campaign of the same arm: only its surfaces and model are read);
    ``tolerance_mm``: the POD truncation (default ``DEFAULT_TOLERANCE_MM``)."""
    from persival.surrogate.structured.surrogate import DEFAULT_TOLERANCE_MM, StructuredSurrogate

    data = Dataset.from_store(store)
    tolerance = DEFAULT_TOLERANCE_MM if tolerance_mm is None else tolerance_mm
    surrogate = StructuredSurrogate(profile, model_file, tables, tolerance, frame=frame).fit(data, progress)
    surrogate.save(out)
    return surrogate


def load_angle_surrogate(path: str | Path):
    """A saved surrogate that has the elbow-angle output and its gradient (the SG)."""
    surrogate = load_surrogate(path)
    if not hasattr(surrogate, "angle_gradient"):
        raise ValueError(f"{path}: this {surrogate.kind} surrogate has no elbow-angle gradient; "
                         "the inverse problem needs a sparse-grid surrogate (persival surrogate fit-sg)")
    return surrogate


def solve_inverse(surrogate_dir: str | Path, angles, n_starts: int = 4) -> tuple[InverseSolution, InverseProblem]:
    problem = InverseProblem(load_angle_surrogate(surrogate_dir))
    return problem.solve(angles, n_starts=n_starts), problem


def build_activation_model(surrogate_dir: str | Path, out: str | Path, progress=None) -> AngleActivationModel:
    """The angle activation model of the SG, saved as ``out`` (JSON) with its plot beside it."""
    from persival.surrogate.plots import plot_activation_model

    sg = load_angle_surrogate(surrogate_dir)
    model = AngleActivationModel.build(InverseProblem(sg), progress=progress)
    model.metadata["source"] = {k: sg.metadata.get(k) for k in ("label", "simulator", "model_hash")}
    model.save(out)
    plot_activation_model(model, Path(out).with_suffix(".png"), sg.metadata.get("label", ""))
    return model


def make_training_data(surrogate_dir: str | Path, activation_model: str | Path, out: str | Path,
                       n_samples: int, angle_fraction: float = 0.5, seed: int = 0, progress=None) -> Path:
    from persival.surrogate.training_data import generate_training_data

    sg = load_angle_surrogate(surrogate_dir)
    model = AngleActivationModel.load(activation_model)
    return generate_training_data(sg, model, out, n_samples, angle_fraction, seed, progress=progress)


def train_network(data: str | Path, out: str | Path, config, muscles=None, progress=None, device: str = "auto"):
    """Train a network on a dataset folder (training data or a saved dataset); saves it in ``out``."""
    from persival.surrogate.network_surrogate import NetworkSurrogate
    from persival.surrogate.plots import plot_training_history

    dataset = open_dataset(data)
    if muscles is not None:
        dataset = dataset.select(muscles)
    surrogate = NetworkSurrogate(config).fit(dataset, out, progress, device)
    plot_training_history(surrogate.history, Path(out) / "history.png",
                          f"{config.arch} network on {dataset.source.get('label', 'data')}")
    return surrogate
