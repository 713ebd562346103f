"""Muscle-muscle contact: frictionless penalty between deformable bodies (docs/theory.md, 3.5).

Two passes, each body against the other. The contact points are one body's surface nodes, each
with its tributary area w (persival.model.fe.contact.surface_node_weights); the obstacle is the
other body's volume. A point x_s that lies in a deformed element of the other body, at its
reference coordinates xi (x_s = sum_a N_a(xi) x_a), sits at X = sum_a N_a(xi) X_a in that body's
mesh pose, and penetrates by

    D = -phi(X) - delta,   Pi = eps w e(D) where D > 0,

phi the signed distance to the body's own surface in its mesh pose (negative inside; sampled
once and interpolated by a tricubic B-spline, persival.model.anatomy.bone_fields.sampled_field) and delta
the largest -phi on the body's surface nodes, so that D vanishes on the whole discrete boundary
and a point entering the body meets no force jump; e (onset_energy) grows the stiffness from
zero to eps over the first ONSET_MM of depth, so it does not jump either. Since
dxi = J^-1 (dx_s - sum_a N_a dx_a) at fixed x_s (J = dx/dxi, J_0 = dX/dxi of the element),

    f = eps w e'(D) B^T nu,   B = [I, -N_1 I, ..., -N_10 I],   nu = -J^-T J_0^T grad phi(X):

the reference normal pushed forward by the element's deformation gradient. phi is C2, so the
force turns smoothly inside an element; between elements only the deformation gradient jumps.
The tangent is the exact Hessian, the pair's gradient differentiated by central differences over
its 33 coordinates (the point's node and the element's ten). Two earlier forms stalled Newton:
the nearest flat triangle's plane (the nearest triangle switches between neighbours, the force
turning by their angle: residuals stuck at 0.05 N), and the nodes' depths interpolated by the
tet10 shape functions (its gradient jumps by O(1) between the elements of a mesh two or three
elements thick: residuals stuck at 1e-3 N). The couplings between the bodies lie outside the
finite-element pattern (``couples_bodies``): the solver keeps them beside it
(QuasiStaticSolver._add_extra_terms).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from persival.model.anatomy.bone_fields import GRID_MM, sampled_field
from persival.model.fe import tet10
from persival.model.fe.contact import _SUB_TRIANGLES, onset_penalty, surface_node_weights
from persival.model.fe.mesh import Tet10Mesh

__all__ = ["ContactBody", "MutualContact"]


class ContactBody:
    """One body of a mesh of several (its nodes from ``offset`` on): its contact points (surface
    nodes, minus ``exclude`` and those within ``end_distance`` of ``ends``), its cells, its mesh
    pose and its distance field phi with the clearance delta (module docstring)."""

    def __init__(self, mesh: Tet10Mesh, offset: int, exclude=(), ends=None, end_distance: float = 0.0,
                 spacing: float = GRID_MM) -> None:
        faces = mesh.boundary_faces()
        nodes, weights = surface_node_weights(mesh, faces=faces)
        keep = ~np.isin(nodes, np.asarray(exclude, dtype=np.int64))
        if ends is not None and end_distance > 0:
            offsets = mesh.points[nodes][:, None, :] - np.asarray(ends, dtype=float)[None]
            keep &= np.min(np.linalg.norm(offsets, axis=2), axis=1) >= end_distance
        self.nodes = nodes[keep] + offset
        self.weights = weights[keep]
        self.cells = mesh.cells + offset
        self.reference = mesh.points
        self.offset = offset
        self.field = sampled_field(mesh.points, faces[:, _SUB_TRIANGLES].reshape(-1, 3), "muscle", spacing=spacing,
                                   pad=4 * spacing)
        self.clearance = max(0.0, float(-self.field.evaluate(mesh.points[nodes], order=1)[0].min()))

    def depth(self, xi: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """D at reference coordinates xi (k, 3) of elements ``cells`` (k, 10; the whole mesh's numbering)."""
        X = np.einsum("ka,kai->ki", tet10.shape_functions(xi), self.reference[cells - self.offset])
        return -self.field.evaluate(X, order=1)[0] - self.clearance


def _reference_coordinates(X: np.ndarray, xi: np.ndarray, iterations: int = 3) -> np.ndarray:
    """xi with sum_a N_a(xi) x_a = x_s, by Newton from ``xi``; X (k, 11, 3): x_s, then the nodes."""
    for _ in range(iterations):
        J = np.einsum("kai,kaj->kij", X[:, 1:], tet10.shape_gradients(xi))
        mismatch = np.einsum("ka,kai->ki", tet10.shape_functions(xi), X[:, 1:]) - X[:, 0]
        xi = xi - np.linalg.solve(J, mismatch[..., None])[..., 0]
    return xi


def _smallest_barycentric(xi: np.ndarray) -> np.ndarray:
    """min(1 - xi_1 - xi_2 - xi_3, xi_1, xi_2, xi_3): negative outside the element."""
    return np.minimum(1.0 - xi.sum(axis=1), xi.min(axis=1))


def _depth_gradient(X: np.ndarray, body: ContactBody, cells: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """d(0.5 D^2)/dX (k, 11, 3) at the point's reference coordinates in ``body``'s elements
    ``cells`` (k, 10) (module docstring); X (k, 11, 3): x_s, then the element's nodes."""
    xi = _reference_coordinates(X, xi)
    N, dN = tet10.shape_functions(xi), tet10.shape_gradients(xi)
    reference = body.reference[cells - body.offset]
    J = np.einsum("kai,kaj->kij", X[:, 1:], dN)
    J0 = np.einsum("kai,kaj->kij", reference, dN)
    phi, grad = body.field.evaluate(np.einsum("ka,kai->ki", N, reference), order=1)
    D = -phi - body.clearance
    nu = np.linalg.solve(J.transpose(0, 2, 1), -np.einsum("kij,ki->kj", J0, grad)[..., None])[..., 0]
    beta = np.column_stack([np.ones(len(X)), -N])
    return (onset_slope(D)[:, None] * beta)[:, :, None] * nu[:, None, :]


ONSET_MM = 0.2  # the depth over which the contact stiffness grows from zero to eps (module docstring)


def onset_energy(D: np.ndarray) -> np.ndarray:
    """Pi / (eps w) at depth D: cubic up to ONSET_MM, then quadratic (C2 at both joins)."""
    return onset_penalty(D, ONSET_MM)[0]


def onset_slope(D: np.ndarray) -> np.ndarray:
    """d(onset_energy)/dD."""
    return onset_penalty(D, ONSET_MM)[1]


class MutualContact:
    """Penalty contact between bodies of one mesh: an extra term of QuasiStaticSolver (module docstring).

    ``pairs``: (points' body, obstacle body) per pass, :class:`ContactBody` each.
    """

    couples_bodies = True  # its tangent couples DOFs of different bodies (outside the FE pattern)
    difference_step = 1e-5  # mm, central differences of a pair's gradient (its Hessian)
    overreach = 0.05  # how far (smallest barycentric) a point may leave the element it was in
    straight_margin = 0.3  # how far outside an element's straight-sided tet a point may be and still lie in it

    def __init__(self, pairs: list[tuple[ContactBody, ContactBody]], penalty: float) -> None:
        if not penalty > 0:
            raise ValueError("the contact penalty must be positive")
        self.pairs = pairs
        self.penalty = float(penalty)
        self._element: list[np.ndarray] = []  # per pass and node: its element at the last iterate, or -1

    def _locate(self, points: ContactBody, other: ContactBody, x: np.ndarray, previous: np.ndarray):
        """The points of ``points`` that lie in an element of ``other``'s deformed mesh: their
        indices into points.nodes, the elements (rows of other.cells), the pairs' coordinates X
        (k, 11, 3) and the reference coordinates xi. ``previous``: per point, its element at the
        last Newton iterate (-1 if none)."""
        none = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 11, 3)), np.zeros((0, 3)))
        cells, xs = other.cells, x[points.nodes]
        corners = x[cells[:, :4]]
        low, high = corners.reshape(-1, 3).min(axis=0), corners.reshape(-1, 3).max(axis=0)
        near = np.flatnonzero(np.all((xs >= low) & (xs <= high), axis=1))
        # every element whose nodes' farthest reach from its centroid covers the point: the one
        # that contains it is among them (a fixed number of nearest ones can miss it)
        centroids = corners.mean(axis=1)
        reach = 1.01 * np.linalg.norm(x[cells] - centroids[:, None], axis=2).max()
        found = cKDTree(centroids).query_ball_point(xs[near], reach) if len(near) else []
        counts = np.array([len(c) for c in found], dtype=np.int64)
        if counts.sum() == 0:
            return none
        owner = near[np.repeat(np.arange(len(near)), counts)]
        cand = np.concatenate([np.asarray(c, dtype=np.int64) for c in found])
        edges = corners[cand, 1:] - corners[cand, :1]  # the straight-sided tet's map: the first guess
        xi = np.linalg.solve(edges.transpose(0, 2, 1), (xs[owner] - corners[cand, 0])[..., None])[..., 0]
        was = previous[owner] == cand
        # only elements whose straight-sided tet nearly holds the point need the curved map (the
        # ball holds tens of candidates per point, most of them far outside)
        close = (_smallest_barycentric(xi) >= -self.straight_margin) | was
        owner, cand, xi, was = owner[close], cand[close], xi[close], was[close]
        X = np.concatenate([xs[owner][:, None], x[cells[cand]]], axis=1)
        xi = _reference_coordinates(X, xi)
        L = _smallest_barycentric(xi)
        # per point, the element it was in at the last Newton iterate while it stays within
        # ``overreach`` of it, else its candidate deepest inside one (the largest smallest
        # barycentric): a point on the face between two elements would otherwise swap them at
        # every iterate, the force turning by the jump of the deformation gradient
        kept = was & (L >= -self.overreach)
        order = np.lexsort((-(L + 2.0 * kept), owner))
        first = order[np.r_[0, np.flatnonzero(np.diff(owner[order])) + 1]] if len(order) else order
        first = first[(L[first] >= -1e-9) | kept[first]]
        return owner[first], cand[first], X[first], xi[first]

    def _active(self, x: np.ndarray, remember: bool = False):
        """Per pass, the points inside the other body: node, weight, the other body, the element's
        nodes (k, 10), the pair's coordinates X (k, 11, 3), reference coordinates xi and depth D.
        ``remember``: this is a Newton iterate, whose elements the next evaluations keep."""
        n_nodes = max(int(body.cells.max()) for pair in self.pairs for body in pair) + 1
        if not self._element or len(self._element[0]) != n_nodes:
            self._element = [np.full(n_nodes, -1, dtype=np.int64) for _ in self.pairs]
        for previous, (points, other) in zip(self._element, self.pairs):
            index, cand, X, xi = self._locate(points, other, x, previous[points.nodes])
            depth = other.depth(xi, other.cells[cand]) if len(index) else np.zeros(0)
            inside = depth > 0
            index, cand = index[inside], cand[inside]
            if remember:
                previous[:] = -1
                previous[points.nodes[index]] = cand
            if len(index):
                yield (points.nodes[index], points.weights[index], other, other.cells[cand], X[inside], xi[inside],
                       depth[inside])

    def energy(self, x: np.ndarray) -> float:
        """Pi = sum eps w e(D) over the points inside the other body (N mm; e: onset_energy)."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        return sum(self.penalty * float(w @ onset_energy(D)) for _, w, *_, D in self._active(x))

    def _weighted_gradients(self, x: np.ndarray):
        """Per pass: the pairs' nodes (k, 11), eps w, the other body, its elements, X, xi and
        eps w d(e(D))/dX (k, 11, 3). A Newton iterate: the elements are remembered."""
        for node, w, other, cell, X, xi, _ in self._active(x, remember=True):
            ew = self.penalty * w
            yield (np.column_stack([node, cell]), ew, other, cell, X, xi,
                   ew[:, None, None] * _depth_gradient(X, other, cell, xi))

    def force(self, x: np.ndarray) -> np.ndarray:
        """dPi/dx (n_dofs,) alone, without the Hessian's 66 gradient evaluations per point."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        f = np.zeros_like(x)
        for ids, *_, gradient in self._weighted_gradients(x):
            np.add.at(f, ids.ravel(), gradient.reshape(-1, 3))
        return f.ravel()

    def force_and_tangent(self, x: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """dPi/dx (n_dofs,) and its symmetric Hessian (the pairs' gradients by central differences)."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        f = np.zeros_like(x)
        rows, cols, vals = [], [], []
        h = self.difference_step
        steps = h * np.eye(33).reshape(1, 33, 11, 3)
        for ids, ew, other, cell, X, xi, gradient in self._weighted_gradients(x):
            np.add.at(f, ids.ravel(), gradient.reshape(-1, 3))
            k = len(ids)
            grads = [_depth_gradient((X[:, None] + steps * sign).reshape(-1, 11, 3), other, np.repeat(cell, 33, axis=0),
                                     np.repeat(xi, 33, axis=0)).reshape(k, 33, 33) for sign in (1.0, -1.0)]
            H = (grads[0] - grads[1]).transpose(0, 2, 1) / (2 * h)
            H = 0.5 * (H + H.transpose(0, 2, 1)) * ew[:, None, None]
            dofs = (3 * ids[:, :, None] + np.arange(3)).reshape(-1, 33)
            rows.append(np.repeat(dofs, 33, axis=1).ravel())
            cols.append(np.tile(dofs, (1, 33)).ravel())
            vals.append(H.ravel())
        n = x.size
        if not vals:
            return f.ravel(), sp.csr_matrix((n, n))
        K = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
        return f.ravel(), K

    def penetration(self, x: np.ndarray) -> float:
        """Deepest point inside the other body by its distance field, less the clearance (mm, 0 if none)."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        return max((float(D.max()) for *_, D in self._active(x)), default=0.0)
