"""The quadratic 10-node tetrahedron (docs/theory.md, 2.1): shape functions and quadrature.

Node order is VTK's / meshio's ``tetra10``: corners 0-3, then the mid-side nodes of the
edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3). gmsh numbers the last two edges the other
way round; :mod:`persival.model.fe.mesh` converts on import.
"""

from __future__ import annotations

import numpy as np

EDGES = np.array([(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)])
GMSH_TO_VTK = np.array([0, 1, 2, 3, 4, 5, 6, 7, 9, 8])

# Faces of the tetrahedron as 6-node triangles (3 corners, then mid-sides of the edges
# (c0,c1), (c1,c2), (c2,c0)), oriented with outward normals for a positively oriented tet.
FACES = np.array(
    [
        [0, 2, 1, 6, 5, 4],
        [0, 1, 3, 4, 8, 7],
        [1, 2, 3, 5, 9, 8],
        [0, 3, 2, 7, 9, 6],
    ]
)


def _barycentric(xi: np.ndarray) -> np.ndarray:
    xi = np.asarray(xi, dtype=float)
    return np.stack([1.0 - xi.sum(axis=-1), xi[..., 0], xi[..., 1], xi[..., 2]], axis=-1)


def shape_functions(xi: np.ndarray) -> np.ndarray:
    """N(xi) for reference points xi (..., 3) -> (..., 10)."""
    L = _barycentric(xi)
    corners = L * (2.0 * L - 1.0)
    edges = 4.0 * L[..., EDGES[:, 0]] * L[..., EDGES[:, 1]]
    return np.concatenate([corners, edges], axis=-1)


def shape_gradients(xi: np.ndarray) -> np.ndarray:
    """dN/dxi for reference points xi (..., 3) -> (..., 10, 3)."""
    L = _barycentric(xi)
    # dL/dxi: L0 = 1 - xi - eta - zeta, L1 = xi, L2 = eta, L3 = zeta
    dL = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    corner = (4.0 * L - 1.0)[..., :, None] * dL
    a, b = EDGES[:, 0], EDGES[:, 1]
    edge = 4.0 * (L[..., a, None] * dL[b] + L[..., b, None] * dL[a])
    return np.concatenate([corner, edge], axis=-2)


def quadrature(order: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Points (nq, 3) and weights (nq,) on the reference tet (volume 1/6).

    order 2: the 4-point rule (Keast), exact for quadratic integrands: the full integration of
    the tet10 stiffness for affine elements, as LS-DYNA's tet10 does.
    order 4: the 11-point Keast rule, exact to degree 4 (used to check quadrature sensitivity).
    """
    if order == 2:
        a, b = 0.5854101966249685, 0.1381966011250105
        pts = np.array([[b, b, b], [a, b, b], [b, a, b], [b, b, a]])
        return pts, np.full(4, 1.0 / 24.0)
    if order == 4:
        a, b = 0.0714285714285714, 0.785714285714286
        c, d = 0.399403576166799, 0.100596423833201
        pts = np.array(
            [
                [0.25, 0.25, 0.25],
                [a, a, a], [b, a, a], [a, b, a], [a, a, b],
                [c, c, d], [c, d, c], [d, c, c], [c, d, d], [d, c, d], [d, d, c],
            ]
        )
        w = np.array([-0.0131555555555556] + [0.00762222222222222] * 4 + [0.0248888888888889] * 6)
        return pts, w
    raise ValueError(f"quadrature order must be 2 or 4, got {order}")
