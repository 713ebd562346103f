"""Fibres and the position along a muscle from a Laplace problem between its two end regions.

A muscle from a segmented surface has no centre line to take fibre directions and tendon
regions from. Solve instead, on its volume mesh (docs/theory.md, Laplace fibres)

    div grad phi = 0,   phi = 0 on the origin region, phi = 1 on the insertion region,
    grad phi . n = 0 elsewhere on the surface,

with linear elements on the tet10's corner nodes. phi rises monotonically from origin to
insertion (maximum principle) and its level sets are the muscle's cross sections: the fibre
direction is grad phi / |grad phi| (smoothed: averaged to the nodes, back to the cells), and
the position along the muscle follows from phi. phi itself is not arclength (it changes fast
where the section is thin: the flux through every section is the same), so the centre line is
read off the level sets, the volume-weighted centroid of each slab of phi, and the position of
a cell is the arclength of that centre line at its phi. The tendon / blend / belly regions then
follow the muscle's tendon and transition lengths in mm, as for the built-in muscles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from persival.model import tet10
from persival.model.mesh import Tet10Mesh

__all__ = ["LaplaceFibres", "laplace_fibres"]

SLABS = 40  # level-set slabs of phi for the centre line


@dataclass
class LaplaceFibres:
    phi_nodes: np.ndarray  # (n_nodes,) phi at every node (mid-side nodes: the mean of their edge's ends)
    phi: np.ndarray  # (n_cells,) at the cell centroids
    fibre: np.ndarray  # (n_cells, 3) unit fibre direction, origin -> insertion
    position: np.ndarray  # (n_cells,) normalized arclength 0..1 along the centre line
    centre_line: np.ndarray  # (k, 3) the level sets' centroids, origin end to insertion end
    length: float  # mm, the centre line's length


def laplace_fibres(mesh: Tet10Mesh, origin_nodes: np.ndarray, insertion_nodes: np.ndarray,
                   ends: tuple[np.ndarray, np.ndarray] | None = None) -> LaplaceFibres:
    """Solve the Laplace problem (module docstring) between two node sets of ``mesh``. ``ends``:
    the centre line's two end points (default: the centroids of the two node sets; on a coarse
    mesh those lie up to an element inside a rounded tip, and the muscle would come out short)."""
    corners = mesh.cells[:, :4]
    used = np.unique(corners)
    local = np.full(mesh.n_nodes, -1, dtype=np.int64)
    local[used] = np.arange(len(used))
    tets = local[corners]
    gradients, volumes = _barycentric_gradients(mesh.points[corners])
    phi = _solve(tets, gradients, volumes, len(used), local, origin_nodes, insertion_nodes)
    cell_gradient = np.einsum("mi,mij->mj", phi[tets], gradients)
    fibre = _smoothed_directions(tets, cell_gradient, volumes, len(used))
    phi_cells = phi[tets].mean(axis=1)
    phi_nodes = np.zeros(mesh.n_nodes)
    phi_nodes[used] = phi
    ends_of_edges = mesh.cells[:, tet10.EDGES]  # (m, 6, 2): the corners each mid-side node sits between
    phi_nodes[mesh.cells[:, 4:]] = phi_nodes[ends_of_edges].mean(axis=2)
    if ends is None:
        ends = (mesh.points[np.asarray(origin_nodes)].mean(axis=0), mesh.points[np.asarray(insertion_nodes)].mean(axis=0))
    centroids = mesh.points[corners].mean(axis=1)
    line, line_phi = _centre_line(phi_cells, centroids, volumes, ends)
    arclength = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    position = np.interp(phi_cells, line_phi, arclength / arclength[-1])
    return LaplaceFibres(phi_nodes, phi_cells, fibre, position, line, float(arclength[-1]))


def _barycentric_gradients(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients (m, 4, 3) of the four barycentric coordinates of each tetrahedron, and volumes."""
    M = np.concatenate([np.ones((len(X), 4, 1)), X], axis=2)  # rows [1, x_i]
    inverse = np.linalg.inv(M)  # lambda_i(x) = inverse[:, :, i] . [1, x]
    return np.transpose(inverse[:, 1:, :], (0, 2, 1)), np.abs(np.linalg.det(M)) / 6.0


def _solve(tets, gradients, volumes, n, local, origin_nodes, insertion_nodes) -> np.ndarray:
    values = np.einsum("m,mik,mjk->mij", volumes, gradients, gradients)
    rows = np.repeat(tets, 4, axis=1).ravel()
    cols = np.tile(tets, (1, 4)).ravel()
    K = sp.csr_matrix((values.ravel(), (rows, cols)), shape=(n, n))
    low = local[np.asarray(origin_nodes)]
    high = local[np.asarray(insertion_nodes)]
    low, high = low[low >= 0], high[high >= 0]
    if len(low) == 0 or len(high) == 0 or np.intersect1d(low, high).size:
        raise ValueError("the two end regions must be separate, non-empty sets of mesh corners")
    phi = np.zeros(n)
    phi[high] = 1.0
    fixed = np.zeros(n, dtype=bool)
    fixed[low] = fixed[high] = True
    free = ~fixed
    rhs = -K[free][:, fixed] @ phi[fixed]
    phi[free] = spsolve(K[free][:, free].tocsc(), rhs)
    return np.clip(phi, 0.0, 1.0)  # round-off only: the maximum principle holds


def _smoothed_directions(tets, cell_gradient, volumes, n) -> np.ndarray:
    """grad phi averaged (volume-weighted) to the corner nodes and back to each cell, normalized:
    the piecewise-constant gradient jumps from cell to cell; the fibres should not."""
    nodal = np.zeros((n, 3))
    weight = np.zeros(n)
    for k in range(4):
        np.add.at(nodal, tets[:, k], volumes[:, None] * cell_gradient)
        np.add.at(weight, tets[:, k], volumes)
    nodal /= weight[:, None]
    smooth = nodal[tets].mean(axis=1)
    norm = np.linalg.norm(smooth, axis=1)
    fallback = norm <= 1e-12 * max(norm.max(), 1e-300)
    smooth[fallback] = cell_gradient[fallback]  # a cell where the averages cancel keeps its own
    return smooth / np.linalg.norm(smooth, axis=1)[:, None]


def _centre_line(phi, centroids, volumes, ends) -> tuple[np.ndarray, np.ndarray]:
    """Centroids of the slabs of phi between the two end regions' centres, and their phi."""
    edges = np.linspace(0.0, 1.0, SLABS + 1)
    slab = np.clip(np.searchsorted(edges, phi, side="right") - 1, 0, SLABS - 1)
    weight = np.bincount(slab, volumes, SLABS)
    filled = weight > 0
    points = np.column_stack([np.bincount(slab, volumes * centroids[:, k], SLABS) for k in range(3)])[filled]
    points /= weight[filled, None]
    slab_phi = np.bincount(slab, volumes * phi, SLABS)[filled] / weight[filled]
    line = np.vstack([ends[0], points, ends[1]])
    # one (1, 2, 1) / 4 pass across the line only: a slab's centroid wanders across the section by
    # the cells it happens to hold, which lengthened a 330 mm spindle's line to 336 mm; along the
    # line the slabs are where they are (smoothing that too shifted positions by 6 mm)
    chord = line[2:] - line[:-2]
    chord /= np.linalg.norm(chord, axis=1)[:, None]
    shift = 0.25 * (line[:-2] - 2.0 * line[1:-1] + line[2:])
    line[1:-1] += shift - np.einsum("ij,ij->i", shift, chord)[:, None] * chord
    return line, np.concatenate([[0.0], slab_phi, [1.0]])
