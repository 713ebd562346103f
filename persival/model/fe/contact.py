"""Muscle-bone contact: frictionless normal penalty contact with rigid obstacles (docs/theory.md, 3.5).

The obstacles (persival.model.anatomy.obstacles: capsules, half-spaces; the bones' shaped surfaces in
persival.model.anatomy.bone_fields; the fascial walls in persival.model.anatomy.walls) give, for a body point at
current position x, the penetration g(x), the outward normal n = -dg/dx and its gradient
``dn/dx``. Contact adds the penalty energy

    Pi_c = sum_p 0.5 eps w_p <g_p>^2,    <g> = max(0, g)        (docs/theory.md, 3.5)

over contact points p of the body's surface, each with an area weight w_p: the surface nodes
with their tributary areas (:func:`surface_node_weights`), or the quadrature points of the
6-node boundary faces. eps (N/mm^3) turns a penetration into a contact pressure ``p = eps g``.
With ``dg/dx = -n``:

    force     f_p = dPi_c/dx_p = -eps w_p g_p n_p                (residual contribution)
    tangent   K_p = df_p/dx_p  = eps w_p (n n^T - g dn/dx)

with dn/dx from the obstacle (for a capsule ``(I - n n^T - t t^T) / d``). The curvature term
``-eps w g dn/dx`` (the normal turns as the point slides over the curved surface) makes the
tangent the exact Hessian of Pi_c, so Newton stays quadratic once the active set (the points
with g > 0) settles. The tangent couples only nodes of one boundary face (one 3x3 block per
node for nodal contact points): entries that the FE pattern already has, so the sparse
factorization keeps its one symbolic analysis while the active set changes (see
QuasiStaticSolver's ``extra_terms``). Frictionless and rigid: bones do not deform, and muscles
do not touch each other.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse as sp

from persival.model.fe.mesh import Tet10Mesh


def onset_penalty(depth: np.ndarray, onset_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The contact energy per unit penalty and area at penetration depths >= 0, its slope and its
    curvature (docs/theory.md, 3.5): D^2/2 (the plain penalty) for ``onset_mm`` = 0, else cubic up to
    d0 = onset_mm (D^3 / (6 d0)) and quadratic beyond (D^2/2 - d0 D/2 + d0^2/6), C2 where they meet,
    so the stiffness grows from 0 to 1 over the first d0 mm instead of jumping at D = 0."""
    D = np.maximum(depth, 0.0)
    if onset_mm == 0.0:
        return 0.5 * D**2, D, (depth > 0.0).astype(float)
    d0, ramp = onset_mm, D < onset_mm
    return (np.where(ramp, D**3 / (6 * d0), 0.5 * D**2 - 0.5 * d0 * D + d0**2 / 6),
            np.where(ramp, D**2 / (2 * d0), D - 0.5 * d0), np.where(ramp, D / d0, 1.0))


# the four 3-node sub-triangles of a 6-node face (corners 0-2, mid-sides 3 = (0,1), 4 = (1,2), 5 = (2,0))
_SUB_TRIANGLES = np.array([[0, 3, 5], [1, 4, 3], [2, 5, 4], [3, 4, 5]])


def surface_node_weights(mesh: Tet10Mesh, points: np.ndarray | None = None,
                         faces: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Surface nodes (sorted) and their tributary areas (mm^2) from the 6-node boundary faces.

    Each face is split into its four 3-node sub-triangles, each giving a third of its area to
    its nodes: on a flat face a corner gets A/12 and a mid-side node A/4, all positive (the
    consistent weights of the quadratic triangle, 0 and A/3, would leave the corners out of
    contact). The weights sum to the surface area of the sub-triangulation.
    """
    faces = mesh.boundary_faces() if faces is None else np.asarray(faces, dtype=np.int64)
    X = mesh.points if points is None else np.asarray(points, dtype=float)
    tri = faces[:, _SUB_TRIANGLES]  # (k, 4, 3)
    P = X[tri]
    area = 0.5 * np.linalg.norm(np.cross(P[:, :, 1] - P[:, :, 0], P[:, :, 2] - P[:, :, 0]), axis=2)
    w = np.bincount(tri.ravel(), weights=np.repeat(area.ravel() / 3.0, 3), minlength=len(X))
    nodes = np.unique(faces)
    return nodes, w[nodes]


def _triangle6_rule() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shape functions N (6, 6) and their (xi, eta) derivatives (6, 2, 6) of the 6-node triangle
    at the 6-point Dunavant rule (degree 4, positive weights), and the weights (sum 1/2)."""
    a, b = 0.445948490915965, 0.091576213509771
    L = np.array([[a, a, 1 - 2 * a], [a, 1 - 2 * a, a], [1 - 2 * a, a, a],
                  [b, b, 1 - 2 * b], [b, 1 - 2 * b, b], [1 - 2 * b, b, b]])
    w = 0.5 * np.repeat([0.223381589678011, 0.109951743655322], 3)
    edges = np.array([[0, 1], [1, 2], [2, 0]])
    N = np.hstack([L * (2 * L - 1), 4 * L[:, edges[:, 0]] * L[:, edges[:, 1]]])
    dL = np.array([[-1.0, 1.0, 0.0], [-1.0, 0.0, 1.0]])  # d(L0, L1, L2)/d(xi, eta)
    dcorner = (4 * L - 1)[:, None, :] * dL[None]
    dedge = 4 * (dL[None, :, edges[:, 0]] * L[:, None, edges[:, 1]] + L[:, None, edges[:, 0]] * dL[None, :, edges[:, 1]])
    return N, np.concatenate([dcorner, dedge], axis=2), w


class ObstacleContact:
    """Penalty contact of body points with rigid obstacles: an extra term of QuasiStaticSolver.

    The contact points are fixed combinations of nodes, ``x_p = sum_a N_pa x_a`` (a sparse
    ``interpolation`` matrix, n_points x n_nodes), each with an area weight w_p: the surface
    nodes themselves with their tributary areas (:meth:`at_nodes`), or the quadrature points of
    the 6-node boundary faces (:meth:`on_faces`: consistent with the traction field, it passes the
    contact patch test exactly). Energy, force and tangent as in the module docstring, mapped
    to the nodes by N: ``f = N^T f_p``, ``K = N^T K_p N`` (couplings within a face: in the FE
    pattern). ``pose(t)``, if given, returns the obstacles at load factor t (the solver calls
    :meth:`set_load_factor`): obstacles moving along the continuation, e.g. with the joint angle.
    """

    def __init__(self, interpolation, weights, obstacles: Sequence, penalty: float,
                 pose: Callable[[float], Sequence] | None = None, near_ends: np.ndarray | None = None,
                 smoothing_mm: float = 0.0) -> None:
        self.interpolation = sp.csr_matrix(interpolation)
        self.weights = np.broadcast_to(np.asarray(weights, dtype=float), (self.interpolation.shape[0],)).copy()
        if np.any(self.weights < 0) or not penalty > 0 or not smoothing_mm >= 0:
            raise ValueError("contact weights must be non-negative, the penalty positive and the smoothing >= 0")
        self.penalty = float(penalty)
        self.smoothing_mm = float(smoothing_mm)
        self.pose = pose
        self.obstacles = tuple(obstacles if pose is None else pose(0.0))
        # points at the body's attachments: obstacles with ``spares_ends`` (a bone the muscle is
        # attached to, by its shaped surface) leave them out
        self.near_ends = None if near_ends is None else np.asarray(near_ends, dtype=bool)

    def _law(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Energy psi(g) / w, pressure psi' and stiffness psi'' at penetrations g > 0: eps times
        :func:`onset_penalty` over the smoothing (docs/theory.md, 3.5)."""
        return tuple(self.penalty * v for v in onset_penalty(g, self.smoothing_mm))

    @classmethod
    def at_nodes(cls, mesh: Tet10Mesh, obstacles: Sequence, penalty: float, faces=None, exclude=(),
                 pose=None, ends=None, end_distance: float = 0.0, smoothing_mm: float = 0.0) -> ObstacleContact:
        """Every node of the boundary faces (or of ``faces``) except ``exclude`` (e.g. tied end
        faces), with its tributary area on those faces; nodes within ``end_distance`` of one of
        ``ends`` ((k, 3) mesh-pose points) are the body's attachments (``near_ends``)."""
        nodes, w = surface_node_weights(mesh, faces=faces)
        keep = ~np.isin(nodes, np.asarray(exclude, dtype=np.int64))
        nodes, w = nodes[keep], w[keep]
        N = sp.csr_matrix((np.ones(len(nodes)), (np.arange(len(nodes)), nodes)), shape=(len(nodes), mesh.n_nodes))
        near = None
        if ends is not None and end_distance > 0:
            offsets = mesh.points[nodes][:, None, :] - np.asarray(ends, dtype=float)[None]
            near = np.min(np.linalg.norm(offsets, axis=2), axis=1) < end_distance
        return cls(N, w, obstacles, penalty, pose, near, smoothing_mm)

    @classmethod
    def on_faces(cls, mesh: Tet10Mesh, obstacles: Sequence, penalty: float, faces=None, exclude=(),
                 pose=None) -> ObstacleContact:
        """The 6 quadrature points of every boundary face (or of ``faces``, (k, 6)) that has no
        node in ``exclude``; weights: the reference area element times the rule's weight."""
        faces = mesh.boundary_faces() if faces is None else np.asarray(faces, dtype=np.int64)
        faces = faces[~np.isin(faces, np.asarray(exclude, dtype=np.int64)).any(axis=1)]
        N, dN, w = _triangle6_rule()
        tangents = np.einsum("qdj,kji->kqdi", dN, mesh.points[faces])  # (k, 6 points, 2, 3)
        area = np.linalg.norm(np.cross(tangents[:, :, 0], tangents[:, :, 1]), axis=2) * w  # (k, 6)
        rows = np.repeat(np.arange(6 * len(faces)), 6)
        cols = np.repeat(faces, 6, axis=0).ravel()
        interp = sp.csr_matrix((np.tile(N.ravel(), len(faces)), (rows, cols)), shape=(6 * len(faces), mesh.n_nodes))
        return cls(interp, area.ravel(), obstacles, penalty, pose)

    def set_load_factor(self, t: float) -> None:
        if self.pose is not None:
            self.obstacles = tuple(self.pose(t))

    def points(self, x: np.ndarray) -> np.ndarray:
        """Contact point positions (n_points, 3) for node positions x (n_nodes, 3)."""
        return self.interpolation @ np.asarray(x, dtype=float).reshape(-1, 3)

    def _pairs(self, x: np.ndarray):
        """Per obstacle: (obstacle, active mask over the points, g, n, dn_dx) at node positions x."""
        xp = self.points(x)
        for obstacle in self.obstacles:
            g, n, dn_dx = obstacle.project(xp)
            if self.near_ends is not None and getattr(obstacle, "spares_ends", False):
                g = np.where(self.near_ends, np.minimum(g, 0.0), g)
            yield obstacle, g > 0.0, g, n, dn_dx

    def energy(self, x: np.ndarray) -> float:
        """Pi_c = sum_p 0.5 eps w_p <g_p>^2 (N mm; docs/theory.md, 3.5)."""
        return sum(float(self.weights[a] @ self._law(g[a])[0]) for _, a, g, _, _ in self._pairs(x))

    def force_and_tangent(self, x: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """Residual contribution dPi_c/dx (n_dofs,) and its full symmetric Hessian (n_dofs x n_dofs):
        per active point f_p = -eps w g n, K_p = eps w (n n^T - g dn/dx) (docs/theory.md, 3.5)."""
        n_points = self.interpolation.shape[0]
        f_p = np.zeros((n_points, 3))
        rows, blocks = [], []
        for _, a, g, n, dn_dx in self._pairs(x):
            w, na = self.weights[a], n[a]
            _, pressure, stiffness = self._law(g[a])
            f_p[a] -= (w * pressure)[:, None] * na
            blocks.append(w[:, None, None] * (stiffness[:, None, None] * na[:, :, None] * na[:, None, :]
                                               - pressure[:, None, None] * dn_dx(a)))
            rows.append(np.flatnonzero(a))
        active = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
        dofs = 3 * np.arange(len(active))[:, None] + np.arange(3)
        K_p = sp.csr_matrix(
            (np.concatenate(blocks).ravel() if blocks else np.zeros(0),
             (np.repeat(dofs, 3, axis=1).ravel(), np.tile(dofs, (1, 3)).ravel())),
            shape=(3 * len(active), 3 * len(active)),
        )
        G = sp.kron(self.interpolation[active], sp.identity(3), format="csr")  # dx_p/du
        return (self.interpolation.T @ f_p).ravel(), (G.T @ K_p @ G).tocsr()

    def force(self, x: np.ndarray) -> np.ndarray:
        """Residual contribution dPi_c/dx (n_dofs,) alone (docs/theory.md, 3.5: f_p = -eps w g n)."""
        f_p = np.zeros((self.interpolation.shape[0], 3))
        for _, a, g, n, _ in self._pairs(x):
            f_p[a] -= (self.weights[a] * self._law(g[a])[1])[:, None] * n[a]
        return (self.interpolation.T @ f_p).ravel()

    def angle_rates(self, x: np.ndarray, obstacles_at: Callable[[float], Sequence], theta_deg: float,
                    step_deg: float, slopes: bool = True) -> tuple[float, float, np.ndarray | None]:
        """P = dPi_c/dtheta|_x (N mm/rad), dP/dtheta|_x and df_c/dtheta|_x (n_dofs,) by central
        differences in theta, the obstacles at an angle from ``obstacles_at``; they are left at
        ``theta_deg``. Without ``slopes``: P alone (0 and None for the rest)."""
        h = np.radians(step_deg)
        energy, force = [], []
        for step in (-1, 0, 1) if slopes else (-1, 1):
            self.obstacles = tuple(obstacles_at(theta_deg + step * step_deg))
            energy.append(self.energy(x))
            if slopes and step:
                force.append(self.force(x))
        self.obstacles = tuple(obstacles_at(theta_deg))
        P = (energy[-1] - energy[0]) / (2 * h)
        if not slopes:
            return P, 0.0, None
        return P, (energy[2] - 2 * energy[1] + energy[0]) / h**2, (force[1] - force[0]) / (2 * h)

    def load_and_depth(self, x: np.ndarray) -> tuple[float, float]:
        """What a state reports of its contact: the summed magnitude of the nodal contact forces (N)
        and the deepest penetration (mm)."""
        return (float(np.linalg.norm(self.force(x).reshape(-1, 3), axis=1).sum()),
                float(self.penetration(x).max(initial=0.0)))

    def penetration(self, x: np.ndarray) -> np.ndarray:
        """Largest penetration (mm, >= 0) of each contact point into any obstacle."""
        depth = np.zeros(self.interpolation.shape[0])
        for _, _, g, _, _ in self._pairs(x):
            depth = np.maximum(depth, g)
        return depth

    def obstacle_loads(self, x: np.ndarray, centre) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per obstacle: total force (N) and moment (N mm, about ``centre``) that the body exerts on it.

        The body pushes an obstacle with ``-eps w g n`` per point (docs/theory.md, 3.5): a bone on
        the forearm passes this moment on to the elbow's balance.
        """
        xp, c, out = self.points(x), np.asarray(centre, dtype=float).reshape(3), {}
        for obstacle, a, g, n, _ in self._pairs(x):
            push = -(self.weights[a] * self._law(g[a])[1])[:, None] * n[a]
            force, moment = out.get(obstacle.name, (np.zeros(3), np.zeros(3)))
            out[obstacle.name] = (force + push.sum(axis=0), moment + np.cross(xp[a] - c, push).sum(axis=0))
        return out
