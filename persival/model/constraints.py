"""Boundary sets of the quasi-static problem: prescribed displacements and rigid-body ties.

A constraint owns a set of nodes and tells, for a load factor t in [0, 1], the displacement
of those nodes. The solver eliminates their degrees of freedom and reports the reaction
(force, and moment about the tie's centre) that the constraint exerts on the body.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def rotation_matrix(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rodrigues' rotation about a unit axis."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1.0 - np.cos(angle_rad)) * (K @ K)


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


@dataclass
class RigidTie:
    """Nodes tied to a rigid body: x = c + R(theta) (X - c) + t * translation.

    The body rotates about ``axis`` through ``centre`` from ``start_angle`` to ``end_angle``
    (degrees) as the load factor goes from 0 to 1 (a hinge, for the elbow).
    """

    name: str
    nodes: np.ndarray
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    end_angle: float = 0.0
    start_angle: float = 0.0
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        self.nodes = np.unique(np.asarray(self.nodes, dtype=np.int64))
        if len(self.nodes) == 0:
            raise ValueError(f"tie {self.name!r} has no nodes")
        self.centre = np.asarray(self.centre, dtype=float)
        self.axis = np.asarray(self.axis, dtype=float)
        if np.linalg.norm(self.axis) == 0:
            raise ValueError(f"tie {self.name!r}: rotation axis must be non-zero")
        self.axis = self.axis / np.linalg.norm(self.axis)
        self.translation = np.asarray(self.translation, dtype=float)

    @property
    def dofs(self) -> np.ndarray:
        return (3 * self.nodes[:, None] + np.arange(3)[None, :]).ravel()

    def angle(self, t: float) -> float:
        return self.start_angle + t * (self.end_angle - self.start_angle)

    def values(self, points: np.ndarray, t: float) -> np.ndarray:
        X = points[self.nodes]
        R = rotation_matrix(self.axis, np.radians(self.angle(t)))
        x = self.centre + (X - self.centre) @ R.T + t * self.translation
        return (x - X).ravel()

    def moment_centre(self, points: np.ndarray) -> np.ndarray:
        return self.centre
