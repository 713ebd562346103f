"""The arm's fixed parts: its mesh and material, the joint's kinematics and the loads on the hinge.

docs/theory.md, 3.2. Each muscle is a swept solid around its centre line (origin, via points, insertion
in the muscle's mesh pose), meshed stress free by gmsh and graded from tendon to belly, or a
segmented surface placed between its origin and insertion (docs/own_anatomy.md, persival.model.surface_muscle); the
forearm turns about the elbow hinge, and gravity on forearm plus hand and a passive joint moment
that stiffens beyond the anatomical limits load the hinge. Everything here is fixed once the
model file and mesh profile are chosen; the solved states live in :mod:`persival.model.arm`.
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

import numpy as np

from persival.model.arm_file import Muscle, load_model_file
from persival.model.assembly import MaterialField
from persival.model.external_moments import ExternalMoments
from persival.model.mesh import Tet10Mesh
from persival.model.muscle_sweep import Sweep, muscle_profile, outlined_centre_line, sweep_sections
from persival.model.rotations import rotation_about
from persival.model.state_cache import cached_mesh
from persival.model.surface_muscle import place_muscle_surface, surface_muscle
from persival.model.wrapping import WrapCylinder

__all__ = ["ArmBody", "ArmKinematics", "muscle_profile", "rotation_about"]


class ArmKinematics:
    """The joint's kinematics of a model file, without a mesh: where forearm points and the
    muscles' ends are at an elbow angle (enough to place bones and attachments)."""

    def __init__(self, model_file: str | Path | None = None, *, check_outlines: bool = True):
        """``check_outlines``: refuse a model file whose muscles' outlines overlap (only files that
        lay muscles out by outlines; ``persival anatomy --outlines`` reports them instead)."""
        self.spec, self.model_hash = load_model_file(model_file)
        joint = self.spec.joint
        self.axis = np.asarray(joint.axis, dtype=float) / np.linalg.norm(joint.axis)
        self.centre = np.asarray(joint.centre, dtype=float)
        if check_outlines and any(m.outlines for m in self.spec.muscles):
            # a layout drawn from an atlas is held to it: no outline overlaps another or the humerus
            # (persival.model.cross_sections), before anything is meshed or written
            from persival.model.cross_sections import check_outlines as refuse_overlaps

            refuse_overlaps(self)

    def forearm_point(self, p: np.ndarray, theta_deg: float) -> np.ndarray:
        """A forearm-frame point (given at theta = 0) at elbow angle theta."""
        return self.centre + (np.asarray(p, dtype=float) - self.centre) @ rotation_about(self.axis, theta_deg).T

    def wrap_cylinder(self, muscle: Muscle) -> WrapCylinder:
        """The cylinder on the hinge axis the muscle's path wraps (radius 0: a straight path)."""
        return WrapCylinder(self.centre, self.axis, muscle.wrap_radius, 1 if muscle.action == "extensor" else -1)

    def muscle_length(self, muscle: Muscle, theta_deg: float) -> tuple[float, float, float]:
        """The muscle's length L (mm) and its derivatives dL/dtheta, d2L/dtheta2 (per radian).

        L is the origin-insertion path's length less the wrapped path's cable (``wrap_cable``):
        the length of the FE body between its end faces. The insertion turns about the hinge:
        I' = k x (I - c), I'' = k x I'. A wrapped path (docs/theory.md 3.4, :mod:`persival.model.wrapping`)
        gains r per radian while it wraps.
        """
        insertion = self.forearm_point(muscle.insertion, theta_deg)
        v1 = np.cross(self.axis, insertion - self.centre)
        v2 = np.cross(self.axis, v1)
        L, dL, d2L = self.wrap_cylinder(muscle).geometry(np.asarray(muscle.origin, dtype=float), insertion, v1, v2)
        if L <= muscle.wrap_cable:
            raise ValueError(f"muscle {muscle.name!r}: wrap_cable {muscle.wrap_cable} mm is longer than its path "
                             f"({L:.1f} mm at {theta_deg} deg)")
        return L - muscle.wrap_cable, dL, d2L

    def body_end(self, muscle: Muscle, theta_deg: float) -> np.ndarray:
        """Where the muscle's FE body ends at theta: its insertion, or for a wrapped path the point
        ``L(theta) - wrap_cable`` along the path's first segment (the rest is cable)."""
        insertion = self.forearm_point(muscle.insertion, theta_deg)
        if muscle.wrap_radius == 0:
            return insertion
        origin = np.asarray(muscle.origin, dtype=float)
        cylinder = self.wrap_cylinder(muscle)
        if muscle.wrap_cable == 0 and not cylinder.wraps(origin, insertion):
            # exactly the insertion, not O + L d rounded: gmsh's loft meshes a centre line that
            # differs in the 14th digit differently (measured: 2548 against 1754 nodes)
            return insertion
        return origin + self.muscle_length(muscle, theta_deg)[0] * cylinder.first_direction(origin, insertion)


    def centre_line(self, muscle: Muscle, stations: int = 33) -> np.ndarray:
        """Stations along origin -> via points -> insertion in the muscle's mesh pose (through its
        outlines' centres when it has outlines: persival.model.muscle_sweep)."""
        if muscle.outlines:
            return outlined_centre_line(muscle, np.asarray(muscle.origin, dtype=float),
                                        self.body_end(muscle, muscle.mesh_angle_deg), stations)
        knots = np.array([muscle.origin, *muscle.via, self.body_end(muscle, muscle.mesh_angle_deg)])
        seg = np.linalg.norm(np.diff(knots, axis=0), axis=1)
        if np.any(seg <= 0):
            raise ValueError(f"muscle {muscle.name!r}: consecutive centre-line points coincide")
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        s = np.linspace(0.0, cum[-1], stations)
        line = np.column_stack([np.interp(s, cum, knots[:, k]) for k in range(3)])
        if muscle.bow > 0:
            # bowed away from the hinge in the plane normal to its axis: a slack muscle then
            # shortens by bending further, smoothly, instead of buckling at a bifurcation
            chord = knots[-1] - knots[0]
            normal = np.cross(self.axis, chord)
            normal /= np.linalg.norm(normal)
            if normal @ (0.5 * (knots[0] + knots[-1]) - self.centre) < 0:
                normal = -normal
            line += muscle.bow * np.sin(np.pi * s / cum[-1])[:, None] * normal
        return line

    def centre_line_length(self, muscle: Muscle) -> float:
        """Length (mm) of the muscle's centre line in its mesh pose: the scale of its tissue layout."""
        return float(np.linalg.norm(np.diff(self.centre_line(muscle), axis=0), axis=1).sum())

    def sweep(self, muscle: Muscle) -> Sweep:
        """The built-in muscle's solid: its centre line and the section at each station."""
        return sweep_sections(muscle, self.centre_line(muscle), self.centre_line_length(muscle))


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
        from a surface the centre line of its Laplace level sets (persival.model.laplace_fibres)."""
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
        gamma, k, pre = np.empty(n), np.empty(n), np.empty(n)
        for muscle in self.spec.ordered_muscles():
            cells = self.muscle_cells[muscle.name]
            _, g = muscle_profile(muscle, self.mesh.cell_data["arclength"][cells], self.body_length(muscle))
            gamma[cells] = g
            k[cells] = g * muscle.bulk_modulus[0] + (1.0 - g) * muscle.bulk_modulus[1]
            pre[cells] = muscle.fibre_prestretch
        self.mesh.cell_data["muscle_fraction"] = gamma
        return MaterialField.from_cells(4, self.mesh.cell_data["fibre"], gamma, k, pre)

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
