"""The FE arm's response tables as a surrogate: five 2-D interpolations and one root.

Beyond the paper: instead of one 5-D sparse grid over the activations, each muscle's states are
tabulated over its own two variables (elbow angle, own activation; persival.tables.response_table)
and an activation vector is answered by the scalar joint equilibrium on the tabulated moments and
the interpolated node states there (:meth:`TableSolver.interpolate`, the "table-only path").
Its cost is in the tables (built once per model by ``persival tables``), not in a campaign.

``fit(dataset)`` picks the surfaces the dataset has and checks that its states come from the
same model (hash); there is nothing to train. Like every surrogate it answers ``predict`` and
``predict_angle`` and saves to a folder that :func:`~persival.surrogate.open.load_surrogate` opens.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.surrogate.base import Surrogate
from persival.surrogate.dataset import Dataset, Surfaces

__all__ = ["ResponseTableSurrogate"]


class ResponseTableSurrogate(Surrogate):
    """Surfaces and elbow angle of the FE arm from its response tables (no FE solve per state).

    ``profile``, ``model_file``: the arm; ``tables``: the table folder (default: the one
    ``persival tables`` builds in the model's state cache).
    """

    kind = "response-table"

    def __init__(self, profile: str = "quick", model_file: str | None = None, tables: str | None = None) -> None:
        self.profile = profile
        self.model_file = None if model_file is None else str(model_file)
        self.tables = None if tables is None else str(tables)
        self.surfaces: Surfaces | None = None
        self.metadata: dict = {}
        self._solver = None
        self._node_ids: list[np.ndarray] = []

    # ------------------------------------------------------------------ the arm and its tables
    @property
    def solver(self):
        """The table solver (opened on first use: it meshes or reads the cached mesh)."""
        if self._solver is None:
            from persival.model.arm.arm_model import ArmModel
            from persival.tables.open import open_tables
            from persival.tables.table_solve import TableSolver

            arm = ArmModel(self.model_file, self.profile)
            self._solver = TableSolver(arm, open_tables(arm, self.tables))
        return self._solver

    def fit(self, dataset: Dataset) -> ResponseTableSurrogate:
        """Answer the surfaces of ``dataset`` (same model: its hash must match the tables')."""
        from persival.campaign.arm_simulator import muscle_surface

        arm = self.solver.arm
        dataset.require_model(arm.model_hash)
        ids = []
        for name, count in zip(dataset.surfaces.names, dataset.surfaces.node_counts):
            if name not in arm.units:
                raise ValueError(f"the FE arm has no muscle {name!r} (dataset surfaces: {list(dataset.surfaces.names)})")
            nodes, _ = muscle_surface(arm, name)
            if len(nodes) != count:
                raise ValueError(f"surface {name!r}: the dataset has {count} nodes, the {self.profile} mesh {len(nodes)}: "
                                 "fit on states of the same mesh profile")
            ids.append(nodes)
        self._node_ids = ids
        self.surfaces = dataset.surfaces
        table = self.solver.table
        self.metadata = {"kind": self.kind, "source": dataset.source, "profile": self.profile,
                         "model_hash": arm.model_hash, "tables": str(table.root), "muscles": list(dataset.surfaces.names),
                         "grid": {"angles_deg": [float(table.angles_deg[0]), float(table.angles_deg[-1]),
                                                 len(table.angles_deg)], "levels": table.levels.tolist()}}
        return self

    # ------------------------------------------------------------------ answers
    def predict_with_angle(self, activations) -> tuple[np.ndarray, np.ndarray]:
        """Positions (m, N, 3) mm and elbow angles (m,) deg; activations (m, 5) or (5,)."""
        self._require_fit()
        alpha = np.atleast_2d(np.asarray(activations, dtype=float))
        points = self.solver.arm.mesh.points
        positions = np.empty((len(alpha), self.surfaces.n_nodes, 3))
        angles = np.empty(len(alpha))
        for i, a in enumerate(alpha):
            angles[i], u = self.solver.interpolate(a)
            positions[i] = np.concatenate([points[ids] + u[ids] for ids in self._node_ids])
        return positions, angles

    def predict_angle(self, activations) -> np.ndarray:
        alpha = np.atleast_2d(np.asarray(activations, dtype=float))
        return np.array([self.solver.start_angle(a) for a in alpha])

    # ------------------------------------------------------------------ folder
    def save(self, path: str | Path) -> Path:
        self._require_fit()
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        self.surfaces.save(path / "surfaces.npz")
        self.write_manifest(path, {"profile": self.profile, "model_file": self.model_file, "tables": self.tables,
                                   "metadata": self.metadata})
        return path

    @classmethod
    def load(cls, path: str | Path) -> ResponseTableSurrogate:
        path = Path(path)
        meta = cls.read_manifest(path)
        surrogate = cls(meta["profile"], meta.get("model_file"), meta.get("tables"))
        surfaces = Surfaces.load(path / "surfaces.npz")
        source = meta["metadata"].get("source", {})
        empty = Dataset(np.zeros((0, 5)), np.zeros((0, surfaces.n_nodes, 3)), np.zeros(0), surfaces,
                        {"model_hash": meta["metadata"].get("model_hash"), **source})
        surrogate.fit(empty)
        surrogate.metadata = meta["metadata"]
        return surrogate
