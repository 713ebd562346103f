"""How a muscle's insertion face follows the elbow angle: the two ties of docs/theory.md, 3.3.

A muscle unit (persival.model.arm.muscle_unit) holds its origin face clamped and moves its
insertion face with theta; the tie says how, and in which frame the unit is solved:

* :class:`LineTie` (the default): both faces are ball joints on the line of action O-I(theta).
  The unit is solved in the frame turned by the minimal rotation Q(theta) of the mesh-pose line
  onto the current one; there the insertion face only translates along the mesh-pose line
  direction by ``L(theta) - L_mesh``, so a muscle without bones depends on L alone. A bone the
  muscle presses on makes its reaction turn with the line, though: the insertion face stays
  square to O-I and the contact's push reaches the forearm as a shear (docs/design/arm_model_record.md).
* :class:`ForearmTie`: the specification read literally, "insertion faces tied to the forearm (they move
  rigidly with theta)": the insertion face turns with the forearm about the hinge,
  ``x = c + R(theta - theta_mesh)(X - c)``, the origin face stays fixed to the humerus, and the
  unit is solved in the world frame. The tendon then leaves the bone in its own direction,
  which is what a belly wrapping a bone needs.

Each tie gives the motion of the insertion DOFs per radian, ``g = dp/dtheta`` and
``g2 = d2p/dtheta2``, from which the unit's moment is the virtual work of the face reaction f:
``dPi*/dtheta = f . g + dPi_c/dtheta`` (envelope theorem, docs/theory.md, 3.7); for the line tie
``f . g = T L'`` and ``f . g2 = T L''``.
"""

from __future__ import annotations

import numpy as np

from persival.model.fe.constraints import Dirichlet, Hinge
from persival.model.fe.rotations import line_rotation

__all__ = ["ForearmTie", "LineTie"]


def mesh_line(origin: np.ndarray, path) -> tuple[float, np.ndarray]:
    """Length and unit direction of the line of action O -> I at the mesh pose."""
    axis = np.asarray(path.insertion(float(path.mesh_angle_deg)), dtype=float) - origin
    length = float(np.linalg.norm(axis))
    if length <= 0:
        raise ValueError("origin and insertion coincide")
    return length, axis / length


class LineTie:
    """Ball joints on the line of action; the unit's frame turns with that line (module docstring)."""

    keyed_by_length = True  # without bones the state is a function of L(theta) alone

    def __init__(self, nodes: np.ndarray, n_dofs: int, origin: np.ndarray, path) -> None:
        self.path = path
        self.origin = origin
        self.mesh_length, self.direction = mesh_line(origin, path)
        self.constraint = Dirichlet("insertion", nodes)
        self._axial = np.zeros(n_dofs)  # the insertion face's unit axial translation
        self._axial[self.constraint.dofs] = np.tile(self.direction, len(self.constraint.nodes))

    def set_path(self, theta_from: float, theta_to: float) -> None:
        self.constraint.start[:] = (self.path.geometry(theta_from)[0] - self.mesh_length) * self.direction
        self.constraint.end[:] = (self.path.geometry(theta_to)[0] - self.mesh_length) * self.direction

    def rotation(self, theta_deg: float) -> np.ndarray:
        """Q(theta): the minimal rotation of the mesh-pose line of action onto the current one."""
        d = np.asarray(self.path.insertion(theta_deg), dtype=float) - self.origin
        return line_rotation(self.direction, d / np.linalg.norm(d))

    def motion(self, theta_deg: float, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        _, dL, d2L = self.path.geometry(theta_deg)
        return dL * self._axial, d2L * self._axial

    def tension(self, force: np.ndarray, theta_deg: float) -> float:
        """T: the axial part of the insertion face's reaction (force: the internal force vector)."""
        return float(self._axial @ force)


class ForearmTie:
    """Insertion face rigid with the forearm, origin face fixed to the humerus; world frame."""

    keyed_by_length = False  # the face turns with theta: the state is not a function of L alone

    def __init__(self, nodes: np.ndarray, n_dofs: int, origin: np.ndarray, path) -> None:
        if path.hinge is None:
            raise ValueError("a forearm tie needs the hinge (MusclePath.hinge = (centre, axis))")
        self.path = path
        self.origin = origin
        self.mesh_length, self.direction = mesh_line(origin, path)
        centre, axis = (np.asarray(v, dtype=float) for v in path.hinge)
        mesh_angle = float(path.mesh_angle_deg)
        self.constraint = Hinge("insertion", nodes, centre, axis, node_reference_deg=mesh_angle,
                                start_deg=mesh_angle, end_deg=mesh_angle)
        self.n_dofs = n_dofs

    def set_path(self, theta_from: float, theta_to: float) -> None:
        self.constraint.start_deg[:] = theta_from
        self.constraint.end_deg[:] = theta_to

    def rotation(self, theta_deg: float) -> np.ndarray:
        return np.eye(3)

    def motion(self, theta_deg: float, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """dx/dtheta = k x (x - c), d2x/dtheta2 = k x (k x (x - c)) of the face's rigid rotation."""
        hinge = self.constraint
        r = hinge.positions(points, theta_deg) - hinge.centre
        v = np.cross(hinge.axis, r)
        g, g2 = np.zeros(self.n_dofs), np.zeros(self.n_dofs)
        g[hinge.dofs], g2[hinge.dofs] = v.ravel(), np.cross(hinge.axis, v).ravel()
        return g, g2

    def tension(self, force: np.ndarray, theta_deg: float) -> float:
        """The insertion face's reaction along the current line O -> I(theta) (reported, not used)."""
        d = np.asarray(self.path.insertion(theta_deg), dtype=float) - self.origin
        total = force.reshape(-1, 3)[self.constraint.nodes].sum(axis=0)
        return float(d @ total / np.linalg.norm(d))
