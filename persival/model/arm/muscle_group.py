"""Muscles that touch each other, solved together (docs/theory.md, 3.5).

A muscle unit (persival.model.arm.muscle_unit) is solved alone in its own frame. Muscles that press
on each other cannot be: here their meshes form one body in the world frame, each muscle's end
faces placed where its own unit puts them at theta (``O + Q(theta)(y - O)``, the unit's tie
giving y), each muscle touching its own bones and walls as before, and the muscles touching each
other by frictionless penalty contact (persival.model.arm.muscle_contact). The group's state depends
on theta and the activations of all its muscles; the moment of each muscle is still the virtual
work of its own faces' reactions and bones (the contact between the muscles moves nothing that
theta prescribes, so it adds no term of its own):

    M_m = -(f . dp_m/dtheta + dPi_c,m/dtheta|_x)

Each state is handed back in its unit's frame, so the arm's bookkeeping (positions, outputs,
checks) reads it as any other muscle's.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from persival.model.arm.muscle_contact import ContactBody, MutualContact
from persival.model.arm.muscle_state import MuscleState
from persival.model.arm.muscle_unit import MuscleUnit
from persival.model.fe.assembly import MaterialField
from persival.model.fe.constraints import angle_derivatives
from persival.model.fe.contact import ObstacleContact
from persival.model.fe.mesh import Tet10Mesh
from persival.model.fe.solver import ConvergenceError, QuasiStaticSolver, SolverOptions

__all__ = ["MuscleGroup"]


class MovingFace:
    """A muscle's end face placed by its unit at theta (world frame); theta moves over the load steps."""

    def __init__(self, name: str, unit: MuscleUnit, face, offset: int) -> None:
        self.name, self.unit, self.face = name, unit, face
        self.nodes = face.nodes + offset
        self.dofs = (3 * self.nodes[:, None] + np.arange(3)).ravel()
        self.path = (unit.mesh_angle_deg, unit.mesh_angle_deg)

    def positions(self, theta_deg: float) -> np.ndarray:
        unit = self.unit
        unit.tie.set_path(theta_deg, theta_deg)
        y = unit.mesh.points[self.face.nodes] + self.face.values(unit.mesh.points, 1.0).reshape(-1, 3)
        return unit.origin + (y - unit.origin) @ unit.rotation(theta_deg).T

    def values(self, points: np.ndarray, t: float) -> np.ndarray:
        theta = self.path[0] + t * (self.path[1] - self.path[0])
        return (self.positions(theta) - points[self.nodes]).ravel()

    def velocity(self, theta_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """dx/dtheta, d2x/dtheta2 per radian (flat, the face's DOFs)."""
        velocity, acceleration = angle_derivatives(self.positions, theta_deg)
        return velocity.ravel(), acceleration.ravel()

    def moment_centre(self, points: np.ndarray) -> np.ndarray:
        return points[self.nodes].mean(axis=0)


class MuscleGroup:
    """Muscle units in contact with each other, one FE problem in the world frame (module docstring)."""

    contact_step_deg = MuscleUnit.contact_step_deg
    # N: the nodal force residual a group's Newton iteration stops at. The contact force turns
    # where a point passes from one element of its neighbour into the next (the interpolated
    # depth's gradient jumps there), a floor of 1e-3 to 1e-2 N measured; muscles pull 10-400 N
    contact_atol = 1e-2

    def __init__(self, units: list[MuscleUnit], penalty: float, attachment_mm: float,
                 options: SolverOptions | None = None) -> None:
        if len(units) < 2:
            raise ValueError("a muscle group needs at least two muscles")
        self.units = units
        self.names = [u.name for u in units]
        self.offsets = np.cumsum([0] + [u.mesh.n_nodes for u in units])
        self.mesh = Tet10Mesh(np.vstack([u.mesh.points for u in units]),
                              np.vstack([u.mesh.cells + o for u, o in zip(units, self.offsets)]))
        self.cells = np.cumsum([0] + [u.mesh.n_cells for u in units])
        fields = ("fibre", "muscle_fraction", "bulk_modulus", "fibre_prestretch")
        self.material = MaterialField(*(np.concatenate([getattr(u.material, k) for u in units]) for k in fields),
                                      units[0].material.parameters,
                                      np.concatenate([u.material.matrix_prestretch for u in units]))
        self.faces = []
        surfaces = []
        for unit, offset in zip(units, self.offsets):
            faces = [MovingFace(f"{unit.name}/{end}", unit, face, offset)
                     for end, face in (("origin", unit._origin_face), ("insertion", unit._insertion_face))]
            self.faces.append(faces)
            ends = [unit.mesh.points[face.face.nodes].mean(axis=0) for face in faces]
            tied = np.concatenate([face.face.nodes for face in faces])
            surfaces.append(ContactBody(unit.mesh, offset, exclude=tied, ends=ends, end_distance=attachment_mm))
        self.bones = [self._world_contact(unit, offset) for unit, offset in zip(units, self.offsets)]
        pairs = [(surfaces[i], surfaces[j]) for i in range(len(units)) for j in range(len(units)) if i != j]
        self.mutual = MutualContact(pairs, penalty)
        terms = [c for c in self.bones if c is not None] + [self.mutual]
        self.solver = QuasiStaticSolver(self.mesh, self.material, [f for faces in self.faces for f in faces],
                                        options, extra_terms=terms)
        self.options = self.solver.options

    def _world_contact(self, unit: MuscleUnit, offset: int) -> ObstacleContact | None:
        """The unit's contact with its bones and walls, on the group's nodes, in the world frame."""
        if unit.contact is None:
            return None
        N = unit.contact.interpolation.tocoo()
        interpolation = sp.csr_matrix((N.data, (N.row, N.col + offset)), shape=(N.shape[0], self.mesh.n_nodes))
        return ObstacleContact(interpolation, unit.contact.weights, unit.path.bones(unit.mesh_angle_deg),
                               unit.contact.penalty, near_ends=unit.contact.near_ends,
                               smoothing_mm=unit.contact.smoothing_mm)

    @property
    def options(self) -> SolverOptions:
        return self.solver.options

    @options.setter
    def options(self, value: SolverOptions) -> None:
        self.solver.options = replace(value, atol=max(value.atol, self.contact_atol), secant_predictor=False)

    def _set_path(self, theta_from: float, theta_to: float) -> None:
        for faces in self.faces:
            for face in faces:
                face.path = (theta_from, theta_to)
        for unit, contact in zip(self.units, self.bones):
            if contact is not None:
                contact.pose = lambda t, u=unit: u.path.bones(theta_from + t * (theta_to - theta_from))
                contact.set_load_factor(0.0)

    def _slice(self, k: int) -> slice:
        return slice(self.offsets[k], self.offsets[k + 1])

    # -- solves ------------------------------------------------------------------------------------
    def solve(self, theta_deg: float, activations: dict[str, float], starts: dict[str, MuscleState],
              progress=None) -> dict[str, MuscleState]:
        """The group's equilibrium at theta with each muscle's activation, continued from its
        muscles' states (all at one angle; a rest state from its unit's mesh pose)."""
        angles = {round(starts[n].angle_deg, 9) for n in self.names}
        if len(angles) != 1:
            raise ValueError(f"muscles {self.names} start at different angles {sorted(angles)}")
        theta_from = float(starts[self.names[0]].angle_deg)
        u0 = np.vstack([unit.positions(starts[unit.name]) - unit.mesh.points for unit in self.units])
        per_cell = lambda values: np.concatenate([np.full(u.mesh.n_cells, float(values[u.name])) for u in self.units])  # noqa: E731
        start_activation = per_cell({n: starts[n].activation for n in self.names})
        self._set_path(theta_from, float(theta_deg))
        options = self.solver.options
        near = abs(theta_deg - theta_from) <= MuscleUnit.small_step_deg and all(
            starts[n].activation == activations[n] for n in self.names)
        if near:
            self.solver.options = replace(options, initial_step=1.0)
        try:
            solution = self.solver.solve(per_cell(activations), initial_displacement=u0,
                                         initial_activation=start_activation, progress=progress)
        except ConvergenceError as exc:
            raise ConvergenceError(f"muscles {' + '.join(self.names)} from {theta_from:.1f} to {theta_deg:.1f} deg: "
                                   f"{exc}") from exc
        finally:
            self.solver.options = options
        return self._states(float(theta_deg), activations, solution)

    def _contact_rates(self, theta_deg: float, x: np.ndarray):
        """Per muscle: P = dPi_c/dtheta|_x, dP/dtheta and df_c/dtheta (central differences, as the unit's)."""
        return [(0.0, 0.0, np.zeros(x.size)) if contact is None
                else contact.angle_rates(x, unit.path.bones, theta_deg, self.contact_step_deg)
                for unit, contact in zip(self.units, self.bones)]

    def _states(self, theta_deg: float, activations: dict[str, float], solution) -> dict[str, MuscleState]:
        """Each muscle's state (its unit's frame): moment, its slope with the whole group
        re-equilibrated (the Schur complement along every face's motion) and du/dtheta."""
        u = solution.displacement.ravel()
        x = self.mesh.points + solution.displacement
        K, f = solution.tangent, solution.internal_force
        if K is None:
            self._set_path(theta_deg, theta_deg)
            K, f = self.solver.tangent(u, self._cell_activation(activations))
        velocities = [[face.velocity(theta_deg) for face in faces] for faces in self.faces]
        g, g2 = np.zeros(u.size), np.zeros(u.size)
        for faces, pairs in zip(self.faces, velocities):
            for face, (v, a) in zip(faces, pairs):
                g[face.dofs], g2[face.dofs] = v, a
        rates = self._contact_rates(theta_deg, x)
        total_rate = sum(r[2] for r in rates)
        _, du = self.solver.condensed_response(K, g, force_rate=total_rate)
        Kdu = self.solver.matvec(K, du)
        states = {}
        for k, (unit, faces, pairs) in enumerate(zip(self.units, self.faces, velocities)):
            dofs = np.concatenate([face.dofs for face in faces])
            g_m, g2_m = np.concatenate([v for v, _ in pairs]), np.concatenate([a for _, a in pairs])
            P, dP, rate = rates[k]
            work = float(f[dofs] @ g_m) + P
            slope = float(g_m @ Kdu[dofs]) + float(f[dofs] @ g2_m) + dP + float(rate @ du)
            states[unit.name] = self._unit_state(unit, k, theta_deg, float(activations[unit.name]), x, f, du,
                                                 -work, -slope, solution)
        return states

    def _cell_activation(self, activations: dict[str, float]) -> np.ndarray:
        return np.concatenate([np.full(u.mesh.n_cells, float(activations[u.name])) for u in self.units])

    def _unit_state(self, unit: MuscleUnit, k: int, theta_deg: float, activation: float, x: np.ndarray,
                    f: np.ndarray, du: np.ndarray, moment: float, slope: float, solution) -> MuscleState:
        """A muscle's part of the group's solution, turned into its unit's frame."""
        nodes = self._slice(k)
        Q = unit.rotation(theta_deg)
        y = unit.origin + (x[nodes] - unit.origin) @ Q
        force_unit = f.reshape(-1, 3)[nodes] @ Q
        contact = self.bones[k]
        pressure = depth = 0.0
        if contact is not None:
            contact.obstacles = tuple(unit.path.bones(theta_deg))
            pressure, depth = contact.load_and_depth(x)
        F = unit.assembler.deformation_gradient((y - unit.mesh.points).ravel())
        return MuscleState(
            theta_deg, unit.length(theta_deg), activation, y - unit.mesh.points,
            unit.tie.tension(force_unit.ravel(), theta_deg), float(moment), float(slope),
            float(np.abs(np.linalg.det(F) - 1).max()), iterations=solution.statistics.iterations,
            sensitivity=du.reshape(-1, 3)[nodes] @ Q, contact_force=pressure, max_penetration=depth,
        )

    def penetration(self, states: dict[str, MuscleState]) -> float:
        """Deepest point of one muscle of the group inside another (mm) at these states."""
        x = np.vstack([unit.positions(states[unit.name]) for unit in self.units])
        return self.mutual.penetration(x)
