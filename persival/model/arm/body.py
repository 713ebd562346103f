"""The arm's fixed parts: its mesh and material, the joint's kinematics and the loads on the hinge.

docs/theory.md, 3.2. Each muscle is a swept solid around its centre line (origin, via points, insertion
in the muscle's mesh pose), meshed stress free by gmsh and graded from tendon to belly, or a
segmented surface placed between its origin and insertion (docs/own_anatomy.md, persival.model.anatomy.surface_muscle); the
forearm turns about the elbow hinge, and gravity on forearm plus hand and a passive joint moment
that stiffens beyond the anatomical limits load the hinge. Everything here is fixed once the
model file and mesh profile are chosen; the solved states live in :mod:`persival.model.arm.arm_model`.
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

import numpy as np

from persival.model.anatomy.muscle_schema import Muscle
from persival.model.anatomy.muscle_sweep import muscle_profile
from persival.model.anatomy.surface_muscle import place_muscle_surface, surface_muscle
from persival.model.arm.external_moments import ExternalMoments
from persival.model.arm.kinematics import ArmKinematics
from persival.model.arm.state_cache import cached_mesh
from persival.model.fe.assembly import MaterialField
from persival.model.fe.mesh import Tet10Mesh

__all__ = ["ArmBody"]


class ArmBody(ArmKinematics):
    """The meshed arm of a model file and mesh profile: geometry, kinematics, external loads."""

    def __init__(self, model_file: str | Path | None = None, profile: str = "quick"):
        self._set_frame(model_file, profile)
        self.mesh, self.muscle_cells, self.muscle_nodes = self._mesh()
        self.material = self._material()

    def _set_frame(self, model_file: str | Path | None, profile: str) -> None:
        """The model file, the joint's frame and the muscles' own surfaces read, repaired and
        placed (docs/own_anatomy.md): every check of the model before any meshing."""
        ArmKinematics.__init__(self, model_file)
        self.model_file = None if model_file is None else str(model_file)  # None: the built-in model
        self.profile = profile
        self.spec.profile(profile)  # unknown profile -> clear error
        self.surfaces = {m.name: place_muscle_surface(m, np.asarray(m.origin, dtype=float), self.body_end(m, m.mesh_angle_deg))
                         for m in self.spec.ordered_muscles() if m.surface is not None}

    @classmethod
    def frame(cls, model_file: str | Path | None = None, profile: str = "quick") -> ArmBody:
        """The model's kinematics and placed surfaces without a mesh (seconds): a command's check
        of its --model before it writes anything."""
        body = object.__new__(ArmBody)
        body._set_frame(model_file, profile)
        return body

    def body_length(self, muscle: Muscle) -> float:
        """Length (mm) the muscle's tissue layout is measured along: its centre line, or for a muscle
        from a surface the centre line of its Laplace level sets (persival.model.anatomy.laplace_fibres)."""
        if muscle.surface is None:
            return self.centre_line_length(muscle)
        return float(self.mesh.cell_data["body_length"][self.muscle_cells[muscle.name][0]])

    # -- geometry -----------------------------------------------------------------------------

    def _mesh(self):
        """The arm's mesh (from the on-disk cache when this model and profile were meshed before)
        and each muscle's cells and nodes (contiguous ranges, in file order)."""
        mesh = cached_mesh(self.model_hash, self.spec.name, self.profile, self._build_mesh)
        muscle_cells, muscle_nodes = {}, {}
        for index, muscle in enumerate(self.spec.ordered_muscles()):
            cells = np.flatnonzero(mesh.cell_data["muscle"] == index)
            muscle_cells[muscle.name] = cells
            nodes = np.unique(mesh.cells[cells])
            muscle_nodes[muscle.name] = np.arange(nodes[0], nodes[-1] + 1)
        return mesh, muscle_cells, muscle_nodes

    def _build_mesh(self) -> Tet10Mesh:
        """gmsh: every muscle's swept solid, numbered one after the other (cell data "muscle")."""
        points, cells, node_sets, cell_data = [], [], {}, {"muscle": [], "fibre": [], "arclength": []}
        if self.surfaces:  # phi of the Laplace fibres and the length the tissue layout is scaled to
            cell_data.update(laplace=[], body_length=[])
        offset = 0
        for index, muscle in enumerate(self.spec.ordered_muscles()):
            size = self.spec.mesh_size(self.profile, muscle.name)
            if muscle.name in self.surfaces:
                own = surface_muscle(muscle, self.surfaces[muscle.name], size)
                mesh, length = own.mesh, own.fibres.length
            else:
                length = self.centre_line_length(muscle)
                mesh = self.sweep(muscle).mesh(size)
                mesh.cell_data["laplace"] = np.full(mesh.n_cells, np.nan)
            if self.surfaces:
                cell_data["laplace"].append(mesh.cell_data["laplace"])
                cell_data["body_length"].append(np.full(mesh.n_cells, length))
            points.append(mesh.points)
            cells.append(mesh.cells + offset)
            node_sets[f"{muscle.name}/origin"] = mesh.node_sets["origin"] + offset
            node_sets[f"{muscle.name}/insertion"] = mesh.node_sets["insertion"] + offset
            cell_data["muscle"].append(np.full(mesh.n_cells, index))
            cell_data["fibre"].append(mesh.cell_data["fibre"])
            cell_data["arclength"].append(mesh.cell_data["arclength"])
            offset += mesh.n_nodes
        mesh = Tet10Mesh(
            np.vstack(points), np.vstack(cells), node_sets=node_sets,
            cell_data={k: np.concatenate(v) for k, v in cell_data.items()},
        )
        mesh.check()
        return mesh

    def _material(self) -> MaterialField:
        n = self.mesh.n_cells
        gamma, k, pre, matrix = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        for muscle in self.spec.ordered_muscles():
            cells = self.muscle_cells[muscle.name]
            _, g = muscle_profile(muscle, self.mesh.cell_data["arclength"][cells], self.body_length(muscle))
            gamma[cells] = g
            k[cells] = g * muscle.bulk_modulus[0] + (1.0 - g) * muscle.bulk_modulus[1]
            pre[cells] = muscle.fibre_prestretch
            matrix[cells] = muscle.matrix_prestretch
        self.mesh.cell_data["muscle_fraction"] = gamma
        return MaterialField.from_cells(4, self.mesh.cell_data["fibre"], gamma, k, pre, matrix_prestretch=matrix)

    def line_moment_arm(self, muscle: Muscle, theta_deg: float) -> float:
        """Moment arm (mm, flexion positive) of the straight origin-insertion line at theta: -dL/dtheta."""
        return -self.muscle_length(muscle, theta_deg)[1]

    # -- loads --------------------------------------------------------------------------------
    @cached_property
    def external(self) -> ExternalMoments:
        """Gravity on forearm and hand and the passive joint moment (docs/theory.md, 3.6)."""
        return ExternalMoments.of_arm(self.spec)

    def gravity_moment(self, theta_deg: float) -> float:
        """Moment of the forearm's weight about the hinge (N mm, flexion positive): -m g r sin(theta)."""
        return float(self.external.gravity(theta_deg))

    def passive_joint_moment(self, theta_deg: float) -> float:
        """K [exp((theta_min - theta)/w) - exp((theta - theta_max)/w)]: stiffens beyond the limits."""
        return float(self.external.joint(theta_deg))

    #: kg held in the hand (at the forearm's hand_distance): part of the hinge's external moment.
    #: Each muscle's state depends on (theta, its activation) only, so a load changes the joint's
    #: equilibrium and nothing cached per muscle (docs/theory.md, 3.6).
    hand_load_kg: float = 0.0

    def external_moment(self, theta_rad: float) -> tuple[float, float]:
        """Gravity (with the hand's load) + passive joint moment and its derivative per radian (the hinge's load)."""
        theta = np.degrees(theta_rad)
        external, load = self.external, self.hand_load_kg
        return float(external.value(theta, load)), float(external.slope(theta, load) * (180.0 / np.pi))

    def cell_activation(self, activations: np.ndarray) -> np.ndarray:
        return np.asarray(activations, dtype=float)[self.mesh.cell_data["muscle"]]
