"""Fibres and the position along a muscle from a Laplace problem between its two end regions.

A muscle from a segmented surface has no centre line to take fibre directions and tendon
regions from. Solve instead, on its volume mesh (docs/own_anatomy.md, Laplace fibres; docs/theory.md 3.2)

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

Where no flux passes, grad phi gives no direction: beyond an attachment face (a tendon tip past
the end point, cut off by the face's fixed nodes: phi there is exactly 0 or 1, its gradient zero
or round-off, and 0 / 0 gave a segmented biceps NaN fibres) and in a lobe no face reaches (its
gradient decays to round-off). A cell whose smoothed gradient is below ``FLAT_SHARE`` of the
median cell gradient, or not finite, keeps its own gradient if that one is above it; else it
takes the centre line's direction at its position (the chord over ``TANGENT_SPAN`` of the line's
length either side), and the origin -> insertion chord where even that is not finite (phi not
finite). ``fallback`` names those cells. Cells whose own gradient is that flat stay out of the
slabs: they lie in no cross section, and a stub's centroid turned the line back past the end
point (25 mm stubs: a 309 mm line for 280 mm between the end points; 286 without them), which
pointed the stub's fibres backwards. The neighbours' gradients are no better a source: beside a
face that wraps a thin tendon they point across it (12 mm stubs: |cos| to the axis 0.38 to 0.63
on average in the stubs spread from their neighbours, 0.9999 from the centre line).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from persival.model.fe import tet10
from persival.model.fe.mesh import Tet10Mesh

__all__ = ["LaplaceFibres", "laplace_fibres"]

SLABS = 40  # level-set slabs of phi for the centre line
# A gradient under this share of the median cell gradient carries no flux: |grad phi| is the flux
# over the section's area, and no muscle's section is a thousand times its median one; below it
# lie the attachment faces' dead ends and unattached lobes, where only round-off or a leak is left.
FLAT_SHARE = 1e-3
TANGENT_SPAN = 0.05  # of the centre line's length, either side of a fallback cell's position


@dataclass
class LaplaceFibres:
    phi_nodes: np.ndarray  # (n_nodes,) phi at every node (mid-side nodes: the mean of their edge's ends)
    phi: np.ndarray  # (n_cells,) at the cell centroids
    fibre: np.ndarray  # (n_cells, 3) unit fibre direction, origin -> insertion
    position: np.ndarray  # (n_cells,) normalized arclength 0..1 along the centre line
    centre_line: np.ndarray  # (k, 3) the level sets' centroids, origin end to insertion end
    length: float  # mm, the centre line's length
    fallback: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # cells whose fibre is no gradient


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
    own, weights, flat = _cell_gradients(phi[tets], gradients, volumes)
    own_norm = np.linalg.norm(own, axis=1)
    fibre = _fibre_directions(tets, own, own_norm, weights, len(used), flat)
    phi_cells = phi[tets].mean(axis=1)
    phi_nodes = np.zeros(mesh.n_nodes)
    phi_nodes[used] = phi
    ends_of_edges = mesh.cells[:, tet10.EDGES]  # (m, 6, 2): the corners each mid-side node sits between
    phi_nodes[mesh.cells[:, 4:]] = phi_nodes[ends_of_edges].mean(axis=2)
    if ends is None:
        ends = (mesh.points[np.asarray(origin_nodes)].mean(axis=0), mesh.points[np.asarray(insertion_nodes)].mean(axis=0))
    centroids = mesh.points[corners].mean(axis=1)
    flux = own_norm > flat  # a cell no flux passes is in no cross section: a stub's would turn the line back
    line, line_phi = _centre_line(phi_cells[flux], centroids[flux], volumes[flux], ends)
    arclength = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    position = np.interp(phi_cells, line_phi, arclength / arclength[-1])
    fallback = np.flatnonzero(np.isnan(fibre[:, 0]))
    chord = np.asarray(ends[1], dtype=float) - np.asarray(ends[0], dtype=float)
    fibre[fallback] = _line_direction(line, arclength / arclength[-1], position[fallback], chord)
    return LaplaceFibres(phi_nodes, phi_cells, fibre, position, line, float(arclength[-1]), fallback)


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


def _cell_gradients(phi_corners, gradients, volumes) -> tuple[np.ndarray, np.ndarray, float]:
    """grad phi of every cell (zero where not finite, so that a NaN cannot spread through the node
    averages), the averages' weights (the volume; zero there too) and the flat threshold."""
    gradient = np.einsum("mi,mij->mj", phi_corners, gradients)
    finite = np.isfinite(gradient).all(axis=1)
    gradient[~finite] = 0.0
    norm = np.linalg.norm(gradient[finite], axis=1)
    flat = FLAT_SHARE * float(np.median(norm)) if len(norm) else np.inf
    return gradient, np.where(finite, volumes, 0.0), flat


def _fibre_directions(tets, gradient, norm, weights, n, flat) -> np.ndarray:
    """Unit fibre of every cell from its smoothed gradient, else its own; NaN where both are
    ``flat`` or less (module docstring: those take the centre line's direction)."""
    smooth = _node_average(tets, gradient, weights, n)
    smooth_norm = np.linalg.norm(smooth, axis=1)
    fibre = np.full_like(gradient, np.nan)
    ok = smooth_norm > flat
    fibre[ok] = smooth[ok] / smooth_norm[ok, None]
    keep = ~ok & (norm > flat)  # a cell where the averages cancel keeps its own
    fibre[keep] = gradient[keep] / norm[keep, None]
    return fibre


def _node_average(tets, values, weights, n) -> np.ndarray:
    """``values`` (m, 3) averaged (weighted) to the corner nodes and back to each cell: the
    piecewise-constant gradient jumps from cell to cell; the fibres should not."""
    nodal = np.zeros((n, 3))
    weight = np.zeros(n)
    for k in range(4):
        np.add.at(nodal, tets[:, k], weights[:, None] * values)
        np.add.at(weight, tets[:, k], weights)
    np.divide(nodal, weight[:, None], out=nodal, where=weight[:, None] > 0)
    return nodal[tets].mean(axis=1)


def _line_direction(line, s_line, position, chord) -> np.ndarray:
    """Unit direction of the centre line at each ``position`` (0..1): its chord from
    position - TANGENT_SPAN to position + TANGENT_SPAN, clipped to the line; ``chord`` (origin ->
    insertion) where that is not finite or has no length."""
    def at(s):
        return np.column_stack([np.interp(s, s_line, line[:, k]) for k in range(3)])

    direction = at(np.clip(position + TANGENT_SPAN, 0.0, 1.0)) - at(np.clip(position - TANGENT_SPAN, 0.0, 1.0))
    norm = np.linalg.norm(direction, axis=1)
    good = np.isfinite(norm) & (norm > 0)
    direction[good] /= norm[good, None]
    direction[~good] = chord / np.linalg.norm(chord)
    return direction


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
