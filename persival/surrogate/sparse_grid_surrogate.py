"""The SG surrogate of a campaign (docs/theory.md, section 5): alpha -> muscle surface positions and the elbow angle.

Reads a campaign store (or a :class:`~persival.surrogate.dataset.Dataset` of one) whose design
is a regular sparse grid, interpolates every surface node's position of the chosen muscles and
the elbow angle with one B-spline sparse grid (one LU, one coefficient matrix: a whole state is
one basis row times that matrix), and answers in physical units (mm, degrees) with gradients
with respect to the activations for the inverse problem.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.surrogate.base import Surrogate
from persival.surrogate.dataset import Dataset, Surfaces
from persival.surrogate.sparse_grid import SparseGrid


def _as_surfaces(surface) -> Surfaces:
    if isinstance(surface, Surfaces):
        return surface
    if isinstance(surface, (list, tuple)):
        return Surfaces.from_topologies(surface)
    return Surfaces.from_topologies([surface])


class SparseGridSurrogate(Surrogate):
    """``fit(dataset or store)``, then ``predict(alpha) -> positions (m, N, 3)``, ``predict_angle``.

    ``muscles``: one name, several, or None for every surface of the campaign.
    """

    kind = "sparse-grid"

    def __init__(self, muscles="biceps", degree: int = 3) -> None:
        self.muscles = None if muscles is None else (muscles,) if isinstance(muscles, str) else tuple(muscles)
        self.degree = degree
        self.grid: SparseGrid | None = None
        self.surfaces: Surfaces | None = None
        self.metadata: dict = {}

    @property
    def muscle(self) -> str:
        """The muscle label ("biceps", or "biceps+triceps" for several)."""
        names = self.surfaces.names if self.surfaces is not None else self.muscles or ("all",)
        return "+".join(names)

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
            f"the campaign's {len(points)} finished design points are not a regular sparse grid "
            "(use a complete sparse-grid design: persival campaign run --design sparse-grid --level L)"
        )

    def fit(self, data) -> SparseGridSurrogate:
        """``data``: a :class:`Dataset` or the path of a finished sparse-grid campaign store."""
        if not isinstance(data, Dataset):
            from persival.campaign.store import CampaignStore

            with CampaignStore.open(data) as store:
                summary = store.summary()
                if not store.done_mask().all():
                    raise ValueError(f"campaign {data} is incomplete ({summary['done']} of {summary['total']} "
                                     "states done); resume it with persival campaign run")
            data = Dataset.from_store(data, self.muscles)
        grid = self._matching_grid(data.activations, self.degree)
        order = np.argsort(grid.locate(data.activations))  # dataset rows in grid order
        return self.fit_values(grid, data.positions[order], data.elbow_angles[order], data.surfaces, data.source)

    def fit_values(self, grid: SparseGrid, positions, angles, surface, metadata: dict | None = None) -> SparseGridSurrogate:
        """Fit to values at the points of any grid (regular or adaptive), given in ``grid.points`` order.

        ``positions`` (N, n_nodes, 3) mm, ``angles`` (N,) deg, ``surface`` the surfaces: a
        :class:`Surfaces`, one :class:`~persival.campaign.simulator.SurfaceTopology` or a list.
        """
        surfaces = _as_surfaces(surface)
        positions = np.asarray(positions, dtype=np.float64)
        angles = np.asarray(angles, dtype=np.float64)
        n = grid.n_points
        if positions.shape != (n, surfaces.n_nodes, 3) or angles.shape != (n,):
            raise ValueError(f"expected positions ({n}, {surfaces.n_nodes}, 3) and angles ({n},), got "
                             f"{positions.shape} and {angles.shape}")
        self.surfaces = surfaces
        self.muscles = surfaces.names
        values = np.column_stack([positions.reshape(n, -1), angles])
        # centred: SG++'s boundary B-splines do not reproduce constants (docs/sparse_grid.md)
        self.grid = grid.fit(values, center=True)
        source = {k: v for k, v in (metadata or {}).items() if k not in ("muscle", "level", "degree", "grid_points")}
        self.metadata = {**source, "kind": self.kind, "muscle": self.muscle, "muscles": list(surfaces.names),
                         "level": grid.level, "degree": self.degree, "grid_points": grid.n_points}
        return self

    @property
    def n_nodes(self) -> int:
        return self.surfaces.n_nodes

    @property
    def reference_points(self) -> np.ndarray:
        return self.surfaces.reference_points

    @property
    def triangles(self) -> np.ndarray:
        return self.surfaces.triangles

    @property
    def fitted(self) -> bool:
        return self.grid is not None

    def predict_with_angle(self, activations, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
        """Surface positions (m, N, 3) in mm and elbow angles (m,) in degrees (one matrix product)."""
        self._require_fit()
        out = self.grid.predict(np.atleast_2d(activations), dtype=dtype)
        return out[:, :-1].reshape(len(out), self.n_nodes, 3), out[:, -1]

    def predict(self, activations, dtype=np.float64) -> np.ndarray:
        return self.predict_with_angle(activations, dtype)[0]

    def predict_angle(self, activations) -> np.ndarray:
        """Elbow angles (m,) in degrees: one column of the coefficient matrix, not the whole surface."""
        self._require_fit()
        return self._angle_grid().predict(np.atleast_2d(activations))

    def angle_gradient(self, activations) -> np.ndarray:
        """d angle / d alpha (m, 5)."""
        self._require_fit()
        return self._angle_grid().gradient(np.atleast_2d(activations))

    def _angle_grid(self) -> SparseGrid:
        """The elbow-angle column as a scalar SG of its own (the inverse problem's hot path)."""
        if getattr(self, "_angle", None) is None or self._angle[0] is not self.grid:
            self._angle = (self.grid, self.grid.select_outputs(self.grid.n_outputs - 1))
        return self._angle[1]

    def gradient(self, activations) -> tuple[np.ndarray, np.ndarray]:
        """d positions / d alpha (m, N, 3, 5) and d angle / d alpha (m, 5)."""
        self._require_fit()
        g = self.grid.gradient(np.atleast_2d(activations))
        return g[:, :-1, :].reshape(len(g), self.n_nodes, 3, -1), g[:, -1, :]

    def save(self, path: str | Path) -> Path:
        """The grid (.npz) plus the surfaces and provenance next to it (.npz, .json)."""
        self._require_fit()
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        self.grid.save(path / "sparse_grid.npz")
        self.surfaces.save(path / "surfaces.npz")
        self.write_manifest(path, self.metadata)
        return path

    @classmethod
    def load(cls, path: str | Path) -> SparseGridSurrogate:
        path = Path(path)
        metadata = cls.read_manifest(path)
        surrogate = cls(metadata.get("muscles", metadata["muscle"]), metadata["degree"])
        surrogate.grid = SparseGrid.load(path / "sparse_grid.npz")
        surrogate.surfaces = Surfaces.load(path / "surfaces.npz")
        surrogate.metadata = metadata
        return surrogate
