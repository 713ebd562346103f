"""Boundary sets of the quasi-static problem: prescribed displacements and rigid-body ties.

A constraint owns a set of nodes and tells, for a load factor t in [0, 1], the displacement
of those nodes (a free hinge also adds its angle to the unknowns). The solver eliminates their degrees of freedom
and reports the reaction
(force, and moment about the tie's centre) that the constraint exerts on the body.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Dirichlet:
    """Prescribed displacement of ``nodes``: ``start + t (end - start)`` on the chosen components.

    ``end`` and ``start`` broadcast to (n_nodes, 3); ``components`` masks x, y, z.
    """

    name: str
    nodes: np.ndarray
    end: np.ndarray | float = 0.0
    start: np.ndarray | float = 0.0
    components: tuple[bool, bool, bool] = (True, True, True)

    def __post_init__(self) -> None:
        self.nodes = np.unique(np.asarray(self.nodes, dtype=np.int64))
        if len(self.nodes) == 0:
            raise ValueError(f"constraint {self.name!r} has no nodes")
        n = len(self.nodes)
        self.end = np.broadcast_to(np.asarray(self.end, dtype=float), (n, 3)).copy()
        self.start = np.broadcast_to(np.asarray(self.start, dtype=float), (n, 3)).copy()
        if not (np.all(np.isfinite(self.end)) and np.all(np.isfinite(self.start))):
            raise ValueError(f"constraint {self.name!r}: prescribed displacement is not finite")
        self._mask = np.asarray(self.components, dtype=bool)

    @property
    def dofs(self) -> np.ndarray:
        return (3 * self.nodes[:, None] + np.flatnonzero(self._mask)[None, :]).ravel()

    def values(self, points: np.ndarray, t: float) -> np.ndarray:
        u = self.start + t * (self.end - self.start)
        return u[:, self._mask].ravel()

    def moment_centre(self, points: np.ndarray) -> np.ndarray:
        return points[self.nodes].mean(axis=0)


def angle_derivatives(positions_at: Callable[[float], np.ndarray], theta_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """dx/dtheta and d2x/dtheta2 per radian of positions given at an angle (deg), by central
    differences (4th order for the velocity, whose error enters the moment residual; h = 1e-3 rad
    gives about 1e-12 relative error)."""
    h = np.degrees(1e-3)
    xm2, xm1, x0, xp1, xp2 = (positions_at(theta_deg + k * h) for k in (-2, -1, 0, 1, 2))
    return (xm2 - 8.0 * xm1 + 8.0 * xp1 - xp2) / (12.0 * 1e-3), (xp1 - 2.0 * x0 + xm1) / 1e-6


@dataclass
class Hinge:
    """Nodes tied to a rigid body that rotates about a fixed axis (the elbow, docs/theory.md, 3.1).

    A node with reference position X, meshed while the body stood at ``node_reference_deg``,
    sits at ``x = c + R(theta - theta_ref) (X - c)``.

    With ``muscle_lines`` = (O, I, is_insertion), per node, the nodes are the two end faces
    of muscles whose line of action runs from a fixed origin point O to an insertion point I
    on the rotating body. Both faces then act as ball joints aligned with that line: the
    insertion point moves with the body, ``I(theta) = c + R(theta - theta_ref)(I - c)``, and
    each face turns by the minimal rotation Q taking the mesh-pose line direction to the
    current one, ``x = a(theta) + Q (X - a_ref)`` (a = O or I(theta)). Tying the faces rigidly
    to the bones instead would bend a short muscle near the joint into an S over a 150 deg
    flexion. The angle is prescribed
    (``start_deg + t (end_deg - start_deg)`` over the load factor) unless ``free``: then theta
    is an unknown of the Newton system, balanced by ``external_moment(theta_rad) -> (M, dM/dtheta)``
    (N mm about +axis; gravity and the passive joint for the elbow).
    """

    name: str
    nodes: np.ndarray
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    node_reference_deg: np.ndarray | float = 0.0
    start_deg: np.ndarray | float = 0.0
    end_deg: np.ndarray | float | None = None
    free: bool = False
    external_moment: Callable[[float], tuple[float, float]] | None = None
    muscle_lines: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    # theta_deg -> (n, 3) per node (given order): the lines' end points when they do not turn
    # rigidly with the body (a wrapped path, persival.model.anatomy.wrapping); I of muscle_lines at each
    # node's reference angle
    line_ends: Callable[[float], np.ndarray] | None = None

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=np.int64)
        order = np.argsort(nodes)
        self._order = order
        per_node = lambda v: np.broadcast_to(np.asarray(v, dtype=float), nodes.shape)[order].copy()  # noqa: E731
        if self.end_deg is None:
            self.end_deg = self.start_deg
        self.node_reference_deg = per_node(self.node_reference_deg)
        if self.muscle_lines is not None:
            O, I, is_insertion = self.muscle_lines
            per_point = lambda v: np.broadcast_to(np.asarray(v, dtype=float), nodes.shape + (3,))[order].copy()  # noqa: E731
            insertion = np.broadcast_to(np.asarray(is_insertion, dtype=bool), nodes.shape)[order].copy()
            self.muscle_lines = (per_point(O), per_point(I), insertion)
        if self.free:
            if np.ndim(self.start_deg) != 0:
                raise ValueError(f"hinge {self.name!r}: a free hinge has one start angle")
        else:  # a prescribed hinge may start every node at its own angle (e.g. its mesh pose)
            self.start_deg, self.end_deg = per_node(self.start_deg), per_node(self.end_deg)
        self.nodes = nodes[order]
        if len(self.nodes) == 0:
            raise ValueError(f"hinge {self.name!r} has no nodes")
        if len(np.unique(self.nodes)) != len(self.nodes):
            raise ValueError(f"hinge {self.name!r} lists a node twice")
        self.centre = np.asarray(self.centre, dtype=float)
        axis = np.asarray(self.axis, dtype=float)
        if np.linalg.norm(axis) == 0:
            raise ValueError(f"hinge {self.name!r}: rotation axis must be non-zero")
        self.axis = axis / np.linalg.norm(axis)
        if self.free and self.external_moment is None:
            self.external_moment = lambda theta: (0.0, 0.0)

    @property
    def dofs(self) -> np.ndarray:
        return (3 * self.nodes[:, None] + np.arange(3)[None, :]).ravel()

    def angle_deg(self, t: float) -> np.ndarray | float:
        return self.start_deg + t * (self.end_deg - self.start_deg)

    def _rotate(self, X: np.ndarray, theta_deg) -> np.ndarray:
        """c + R(theta - theta_ref) X, per node (Rodrigues: each node may have its own reference)."""
        phi = np.radians(theta_deg - self.node_reference_deg)
        k = self.axis
        cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
        return self.centre + X * cos + np.cross(k, X) * sin + np.outer(X @ k, k) * (1.0 - cos)

    def positions(self, points: np.ndarray, theta_deg) -> np.ndarray:
        """Current positions (n, 3) of the hinge nodes at angle theta (scalar or per node)."""
        X = points[self.nodes]
        if self.muscle_lines is None:
            return self._rotate(X - self.centre, theta_deg)
        O, I_ref, is_insertion = self.muscle_lines
        if self.line_ends is None:
            I = self._rotate(I_ref - self.centre, theta_deg)
        else:
            I = np.asarray(self.line_ends(float(theta_deg)), dtype=float)[self._order]
        d_ref = (I_ref - O) / np.linalg.norm(I_ref - O, axis=1)[:, None]
        d = (I - O) / np.linalg.norm(I - O, axis=1)[:, None]
        v = np.cross(d_ref, d)
        cos = np.einsum("ni,ni->n", d_ref, d)[:, None]
        a_ref = np.where(is_insertion[:, None], I_ref, O)
        a = np.where(is_insertion[:, None], I, O)
        y = X - a_ref
        # minimal rotation d_ref -> d: Q y = y + v x y + v x (v x y) / (1 + cos)
        vy = np.cross(v, y)
        return a + y + vy + np.cross(v, vy) / (1.0 + cos)

    def velocity(self, points: np.ndarray, theta_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """dx/dtheta and d2x/dtheta2 per radian, (n, 3) each (:func:`angle_derivatives`)."""
        return angle_derivatives(lambda theta: self.positions(points, theta), theta_deg)

    def displacement_at(self, points: np.ndarray, theta_deg: float) -> np.ndarray:
        return (self.positions(points, theta_deg) - points[self.nodes]).ravel()

    def values(self, points: np.ndarray, t: float) -> np.ndarray:
        return self.displacement_at(points, self.angle_deg(t))

    def moment_centre(self, points: np.ndarray) -> np.ndarray:
        return self.centre
