"""The built-in FE arm (persival.model) as a campaign simulator: the ``arm`` kind of the registry.

It lives with the other simulators because it adapts the model to the campaign's interface;
the model stage itself knows nothing of campaigns.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from persival.campaign.simulator import ReferenceGeometry, SimulationResult, SurfaceTopology
from persival.model.arm import ArmModel, ArmState
from persival.model.mesh import Tet10Mesh
from persival.model.output import muscle_submesh
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


class ArmSimulator:
    """Simulator protocol of persival.campaign over :class:`ArmModel` (warm starts: ArmState)."""

    name = "arm"

    def __init__(self, model_file: str | None = None, profile: str = "quick") -> None:
        self.arm = ArmModel(model_file, profile)
        self.default_options = self.arm.options
        self.surfaces = {name: muscle_surface(self.arm, name) for name in MUSCLES}

    def reference(self) -> ReferenceGeometry:
        return ReferenceGeometry(
            surfaces={
                name: SurfaceTopology(name, self.arm.mesh.points[ids], triangles, node_ids=ids)
                for name, (ids, triangles) in self.surfaces.items()
            },
            model_hash=self.arm.model_hash,
            description={"model": self.arm.spec.name, "profile": self.arm.profile, "units": "mm"},
        )

    def simulate(self, activations, warm_start: ArmState | None = None, attempt: int = 0):
        # retries: smaller first load steps
        self.arm.set_options(replace(self.default_options, initial_step=self.default_options.initial_step / 2**attempt))
        state = self.arm.solve(activations, warm_start=warm_start)
        x = self.arm.mesh.points + state.displacement
        result = SimulationResult(
            elbow_angle_deg=state.elbow_angle_deg,
            surfaces={name: x[ids] for name, (ids, _) in self.surfaces.items()},
            statistics={k: v for k, v in state.summary().items() if k not in ("activations",)},
            wall_time_s=state.wall_time_s,
        )
        return result, state
