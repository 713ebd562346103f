"""The built-in FE arm (persival.model) as a campaign simulator: the ``arm`` kind of the registry.

It lives with the other simulators because it adapts the model to the campaign's interface;
the model stage itself knows nothing of campaigns.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from persival.campaign.simulator import ReferenceGeometry, SimulationResult, SimulatorSpec, SurfaceTopology
from persival.model.arm.arm_model import ArmModel, ArmState
from persival.model.arm.output import muscle_submesh
from persival.model.fe.mesh import Tet10Mesh
from persival.tables.open import ensure_tables, open_tables
from persival.vocabulary import MUSCLES


def display_triangles(faces6: np.ndarray) -> np.ndarray:
    """Split 6-node boundary triangles into 4 linear ones each (mid-side nodes kept as vertices)."""
    c0, c1, c2, m01, m12, m20 = faces6.T
    return np.concatenate(
        [np.column_stack(t) for t in ((c0, m01, m20), (m01, c1, m12), (m20, m12, c2), (m01, m12, m20))]
    )


def muscle_surface(arm: ArmModel, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Global node ids of one muscle's surface and its display triangles (local numbering)."""
    nodes, cells = muscle_submesh(arm, name)
    body = Tet10Mesh(arm.mesh.points[nodes], cells)
    faces = body.boundary_faces()
    surface = np.unique(faces)
    local = np.full(len(nodes), -1, dtype=np.int64)
    local[surface] = np.arange(len(surface))
    return nodes[surface], display_triangles(local[faces])


METHODS = ("tables", "direct", "interpolate")


class ArmSimulator:
    """Simulator protocol of persival.campaign over :class:`ArmModel` (warm starts: ArmState).

    ``method``: "tables" (default; docs/theory.md, 4.3): the exact FE state from the per-muscle
    response tables (persival.tables.table_solve), which must be built first
    (``persival tables``, or :func:`ensure_tables`); a retry falls back to the direct solve.
    "direct": the coupled solve continued from the hanging arm or a neighbour.
    "interpolate": the table-only path (no FE solve; a surrogate, for comparisons).
    """

    name = "arm"

    def __init__(self, model_file: str | None = None, profile: str = "quick", method: str = "tables",
                 tables: str | None = None) -> None:
        if method not in METHODS:
            raise ValueError(f"arm simulator method must be one of {', '.join(METHODS)}, got {method!r}")
        self.arm = ArmModel(model_file, profile)
        self.method = method
        self.default_options = self.arm.options
        self.surfaces = {name: muscle_surface(self.arm, name) for name in MUSCLES}
        self.table_solver = None
        if method != "direct":
            from persival.tables.table_solve import TableSolver

            self.table_solver = TableSolver(self.arm, open_tables(self.arm, tables))

    def reference(self) -> ReferenceGeometry:
        return ReferenceGeometry(
            surfaces={
                name: SurfaceTopology(name, self.arm.mesh.points[ids], triangles, node_ids=ids)
                for name, (ids, triangles) in self.surfaces.items()
            },
            model_hash=self.arm.model_hash,
            description={"model": self.arm.spec.name, "profile": self.arm.profile, "units": "mm", "method": self.method},
        )

    def simulate(self, activations, warm_start: ArmState | None = None, attempt: int = 0):
        # retries: the direct path with smaller first load steps
        self.arm.set_options(replace(self.default_options, initial_step=self.default_options.initial_step / 2**attempt))
        if self.method == "interpolate":
            return self._interpolated(activations), None
        state = None
        if self.table_solver is not None and attempt == 0:
            from persival.tables.table_solve import OutsideTableError

            try:
                state = self.table_solver.solve(activations)
                state.statistics["path"] = "tables"
            except OutsideTableError as exc:  # e.g. strong extensors: equilibrium below the table's 0 deg
                path = f"direct ({exc})"
        else:
            path = "direct" if self.table_solver is None else "direct (retry)"
        if state is None:
            state = self.arm.solve(activations, warm_start=warm_start)
            state.statistics["path"] = path
        x = self.arm.mesh.points + state.displacement
        result = SimulationResult(
            elbow_angle_deg=state.elbow_angle_deg,
            surfaces={name: x[ids] for name, (ids, _) in self.surfaces.items()},
            statistics={k: v for k, v in state.summary().items() if k not in ("activations",)},
            wall_time_s=state.wall_time_s,
        )
        return result, state

    def _interpolated(self, activations) -> SimulationResult:
        t0 = time.perf_counter()
        theta, u = self.table_solver.interpolate(activations)
        x = self.arm.mesh.points + u
        return SimulationResult(elbow_angle_deg=theta, surfaces={name: x[ids] for name, (ids, _) in self.surfaces.items()},
                                statistics={"path": "interpolate"}, wall_time_s=time.perf_counter() - t0)


def arm_spec(profile: str, method: str = "tables", model_file: str | None = None) -> SimulatorSpec:
    """The FE arm's simulator spec; ``model_file`` only when given, so that a built-in-arm store
    keeps the spec (and digest) it was created with."""
    options = {"profile": profile, "method": method}
    if model_file is not None:
        options["model_file"] = str(model_file)
    return SimulatorSpec("arm", options)


def prepare_spec(spec, progress=None, scheduler: str | None = None, n_workers: int | None = None):
    """Before a campaign of the arm with the tables (the default method): build or finish the
    response tables once, in the driver, so that no worker builds them. Other specs: nothing."""
    if spec.kind != "arm" or spec.options.get("method", "tables") == "direct":
        return None
    options = spec.options
    return ensure_tables(options.get("model_file"), options.get("profile", "quick"), options.get("tables"), progress,
                         scheduler, n_workers)
