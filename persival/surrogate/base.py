"""One interface for every surrogate (sparse grid, paper network, POD network, response tables).

scikit-learn's convention: ``fit(dataset)`` returns the fitted surrogate, ``predict(alpha)``
answers surface positions ``(n, N, 3)`` in mm for activations ``(n, 5)``, ``predict_angle``
the elbow angle where the surrogate has it, ``save(dir)`` / ``load(dir)`` a folder whose
``surrogate.json`` names the kind, so :func:`load_surrogate` can open any of them and the
evaluation code never asks which one it measures.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from persival.surrogate.dataset import Dataset, Surfaces

__all__ = ["Surrogate", "load_surrogate", "KINDS"]


@runtime_checkable
class Surrogate(Protocol):
    kind: str
    surfaces: Surfaces
    metadata: dict  # provenance: the dataset's source, training config, ...

    def fit(self, dataset: Dataset) -> Surrogate: ...

    def predict(self, activations) -> np.ndarray: ...

    def predict_angle(self, activations) -> np.ndarray: ...

    def save(self, path: str | Path) -> Path: ...


def _kinds() -> dict:
    from persival.surrogate.network_surrogate import NetworkSurrogate
    from persival.surrogate.surface_surrogate import SurfaceSurrogate
    from persival.surrogate.table_surrogate import ResponseTableSurrogate

    return {"sparse-grid": SurfaceSurrogate, "network": NetworkSurrogate, "response-table": ResponseTableSurrogate}


KINDS = ("sparse-grid", "network", "response-table")


def load_surrogate(path: str | Path):
    """Open any saved surrogate folder (its ``surrogate.json`` names the kind)."""
    path = Path(path)
    meta_file = path / "surrogate.json"
    if not meta_file.is_file():
        raise FileNotFoundError(f"{path} is not a surrogate folder (no surrogate.json)")
    try:
        kind = json.loads(meta_file.read_text()).get("kind", "sparse-grid")
    except json.JSONDecodeError as exc:
        raise ValueError(f"{meta_file} is not valid JSON: {exc}") from None
    kinds = _kinds()
    if kind not in kinds:
        raise ValueError(f"{path}: unknown surrogate kind {kind!r} (known: {', '.join(kinds)})")
    return kinds[kind].load(path)
