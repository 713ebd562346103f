"""One interface for every surrogate (sparse grid, paper network, POD network, response tables,
structured).

scikit-learn's convention: ``fit(dataset)`` returns the fitted surrogate, ``predict(alpha)``
answers surface positions ``(n, N, 3)`` in mm for activations ``(n, 5)``, ``predict_angle`` the
elbow angle where the surrogate has it (``has_angle``), ``predict_with_angle`` both at once,
``save(dir)`` / ``load(dir)`` a folder whose ``surrogate.json`` names the kind and the format
version, so :func:`persival.surrogate.open.load_surrogate` opens any of them and the evaluation code never asks which one
it measures. Every surrogate inherits :class:`Surrogate`; tests/surrogate/test_surrogate_conformance.py
runs the same checks over every kind.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from pathlib import Path
from typing import ClassVar

import numpy as np

from persival.file_header import check_header
from persival.surrogate.dataset import Dataset, Surfaces

__all__ = ["Surrogate", "NotFittedError", "MANIFEST", "manifest_of"]

MANIFEST = "surrogate.json"


class NotFittedError(RuntimeError):
    """A surrogate asked to answer (or to be saved) before ``fit`` or ``load``."""


class Surrogate(ABC):
    """The interface every surrogate implements (see the module docstring)."""

    kind: ClassVar[str]
    #: version of the folder layout this class writes and reads
    format_version: ClassVar[int] = 1
    has_angle: bool = True
    surfaces: Surfaces | None = None
    metadata: dict

    @abstractmethod
    def fit(self, dataset: Dataset) -> Surrogate:
        """Fit to ``dataset`` (its states, or only its surfaces and model, as the kind needs); returns self."""

    @abstractmethod
    def predict_with_angle(self, activations) -> tuple[np.ndarray, np.ndarray | None]:
        """Positions (n, N, 3) mm and elbow angles (n,) deg (None without ``has_angle``)."""

    def predict(self, activations) -> np.ndarray:
        return self.predict_with_angle(activations)[0]

    def predict_angle(self, activations) -> np.ndarray:
        if not self.has_angle:
            raise ValueError(f"the {self.kind} surrogate ({self.metadata.get('arch', '')}) has no elbow-angle output")
        return self.predict_with_angle(activations)[1]

    @property
    def fitted(self) -> bool:
        return self.surfaces is not None

    def _require_fit(self) -> None:
        if not self.fitted:
            raise NotFittedError(f"{type(self).__name__}: call fit(dataset) or load(folder) first")

    @abstractmethod
    def save(self, path: str | Path) -> Path:
        """Write the folder (it holds ``surrogate.json``, written by :meth:`write_manifest`)."""

    @classmethod
    @abstractmethod
    def load(cls, path: str | Path) -> Surrogate:
        """Open a folder that :meth:`save` wrote."""

    # ------------------------------------------------------------------ the manifest
    def write_manifest(self, path: Path, content: dict) -> None:
        """``surrogate.json``: ``content`` with this class's kind and format version."""
        manifest = {**content, "kind": self.kind, "format_version": self.format_version}
        (Path(path) / MANIFEST).write_text(json.dumps(manifest, indent=2, default=_json_default))

    @classmethod
    def read_manifest(cls, path: str | Path) -> dict:
        """The folder's ``surrogate.json``, checked: it exists, names this kind and a version this
        PerSival reads (folders written before versions were recorded count as version 1)."""
        manifest = manifest_of(Path(path))
        if manifest.get("kind", "sparse-grid") != cls.kind:
            raise ValueError(f"{path} holds a {manifest.get('kind')!r} surrogate, not a {cls.kind!r} one")
        return check_header({"format_version": 1, **manifest}, path, f"{cls.kind} surrogate", None, cls.format_version,
                            version_key="format_version", advice="fit it again")


def _json_default(value):
    return value.item() if isinstance(value, np.generic) else str(value)


def manifest_of(path: Path) -> dict:
    """A surrogate folder's surrogate.json, with a clear error where there is none."""
    manifest = path / MANIFEST
    if not manifest.is_file():
        raise FileNotFoundError(f"{path} is not a surrogate folder (no {MANIFEST})")
    try:
        return json.loads(manifest.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{manifest} is not valid JSON: {exc}") from None
