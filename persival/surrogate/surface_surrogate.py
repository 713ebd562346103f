"""The SG surrogate of a campaign (SPEC 4): alpha -> one muscle's surface positions and the elbow angle.

Reads a campaign store whose design is a regular sparse grid, interpolates every surface
node's position and the elbow angle with one B-spline sparse grid (one LU, one coefficient
matrix: a whole state is one basis row times that matrix), and answers in physical units
(mm, degrees) with gradients with respect to the activations for the inverse problem.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from persival.surrogate.sparse_grid import SparseGrid


class SurfaceSurrogate:
    """``fit(store)``, then ``predict(alpha) -> (positions (m, n, 3), angles (m,))``."""

    def __init__(self, muscle: str = "biceps", degree: int = 3) -> None:
        self.muscle = muscle
        self.degree = degree
        self.grid: SparseGrid | None = None
        self.reference_points: np.ndarray | None = None
        self.triangles: np.ndarray | None = None
        self.metadata: dict = {}

    @staticmethod
    def _matching_grid(points: np.ndarray, degree: int) -> SparseGrid:
        for level in range(1, 8):
            grid = SparseGrid(points.shape[1], level, degree)
            if grid.n_points == len(points):
                try:
                    rows = grid.locate(points)
                except ValueError:
                    break
                if len(np.unique(rows)) == len(points):
                    return grid
            if grid.n_points > len(points):
                break
        raise ValueError(
            f"the campaign's {len(points)} design points are not a regular sparse grid "
            "(use a sparse-grid design: persival campaign run --design sparse-grid --level L)"
        )

    def fit(self, store_path: str | Path) -> SurfaceSurrogate:
        from persival.campaign.store import CampaignStore

        with CampaignStore.open(store_path) as store:
            summary = store.summary()
            if not store.done_mask().all():
                raise ValueError(
                    f"campaign {store_path} is incomplete ({summary}); resume it with persival campaign run"
                )
            design = store.design
            reference = store.reference
            if self.muscle not in reference.surfaces:
                raise ValueError(f"the campaign has no surface {self.muscle!r}; it has {sorted(reference.surfaces)}")
            positions = store.surface_positions(self.muscle)
            angles = store.elbow_angles()
            metadata = {"store": str(store_path), "model_hash": reference.model_hash, **reference.description}
        grid = self._matching_grid(design.points, self.degree)
        rows = grid.locate(design.points)
        order = np.argsort(rows)  # design rows in grid order
        return self.fit_values(grid, positions[order], angles[order], reference.surfaces[self.muscle], metadata)

    def fit_values(self, grid: SparseGrid, positions, angles, surface, metadata: dict | None = None) -> SurfaceSurrogate:
        """Fit to FE values at the points of any grid (regular or adaptive), given in ``grid.points`` order.

        ``positions`` (N, n_nodes, 3) mm, ``angles`` (N,) deg, ``surface`` the muscle's
        :class:`~persival.campaign.simulator.SurfaceTopology`.
        """
        positions = np.asarray(positions, dtype=np.float64)
        angles = np.asarray(angles, dtype=np.float64)
        n = grid.n_points
        if positions.shape != (n, len(surface.reference_points), 3) or angles.shape != (n,):
            raise ValueError(
                f"expected positions ({n}, {len(surface.reference_points)}, 3) and angles ({n},), got "
                f"{positions.shape} and {angles.shape}"
            )
        self.reference_points = np.asarray(surface.reference_points, dtype=float)
        self.triangles = np.asarray(surface.triangles)
        values = np.column_stack([positions.reshape(n, -1), angles])
        # centred: SG++'s boundary B-splines do not reproduce constants (docs/sparse_grid.md)
        self.grid = grid.fit(values, center=True)
        self.metadata = {**(metadata or {}), "muscle": self.muscle, "level": grid.level,
                         "degree": self.degree, "grid_points": grid.n_points}
        return self

    @property
    def n_nodes(self) -> int:
        return len(self.reference_points)

    def _require_fit(self) -> None:
        if self.grid is None:
            raise RuntimeError("fit() or load() the surrogate first")

    def predict(self, activations, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
        """Surface positions (m, n, 3) in mm and elbow angles (m,) in degrees."""
        self._require_fit()
        out = self.grid.predict(np.atleast_2d(activations), dtype=dtype)
        return out[:, :-1].reshape(len(out), self.n_nodes, 3), out[:, -1]

    def gradient(self, activations) -> tuple[np.ndarray, np.ndarray]:
        """d positions / d alpha (m, n, 3, 5) and d angle / d alpha (m, 5)."""
        self._require_fit()
        g = self.grid.gradient(np.atleast_2d(activations))
        return g[:, :-1, :].reshape(len(g), self.n_nodes, 3, -1), g[:, -1, :]

    def save(self, path: str | Path) -> Path:
        """The grid (.npz) plus the surface topology and provenance next to it (.json, .npz)."""
        self._require_fit()
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        self.grid.save(path / "sparse_grid.npz")
        np.savez(path / "surface.npz", reference_points=self.reference_points, triangles=self.triangles)
        (path / "surrogate.json").write_text(json.dumps(self.metadata, indent=2))
        return path

    @classmethod
    def load(cls, path: str | Path) -> SurfaceSurrogate:
        path = Path(path)
        metadata = json.loads((path / "surrogate.json").read_text())
        surrogate = cls(metadata["muscle"], metadata["degree"])
        surrogate.grid = SparseGrid.load(path / "sparse_grid.npz")
        with np.load(path / "surface.npz", allow_pickle=False) as z:
            surrogate.reference_points, surrogate.triangles = z["reference_points"], z["triangles"]
        surrogate.metadata = metadata
        return surrogate
