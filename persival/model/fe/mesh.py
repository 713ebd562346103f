"""Quadratic tetrahedral meshes: the container, checks, surface extraction, gmsh and meshio I/O.

gmsh makes the meshes (docs/theory.md, 2.1), meshio writes them (VTU for ParaView); this module only
converts between their conventions and ours and refuses meshes the solver cannot use.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from persival.model.fe import tet10


class MeshError(ValueError):
    """A mesh the finite-element solver cannot use (inverted, degenerate, malformed)."""


@dataclass
class Tet10Mesh:
    """Nodes (n, 3) in mm and cells (m, 10) in VTK tetra10 order.

    ``node_sets`` name groups of node indices (boundary faces, ties); ``cell_data`` holds
    per-cell fields such as ``fibre`` (m, 3), ``muscle_fraction`` (m,), ``body`` (m,) ids.
    """

    points: np.ndarray
    cells: np.ndarray
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)
    cell_data: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=float)
        self.cells = np.ascontiguousarray(self.cells, dtype=np.int64)
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise MeshError(f"points must have shape (n, 3), got {self.points.shape}")
        if self.cells.ndim != 2 or self.cells.shape[1] != 10:
            raise MeshError(f"cells must be quadratic tetrahedra with 10 nodes, got shape {self.cells.shape}")
        if len(self.cells) == 0:
            raise MeshError("mesh has no cells")
        if self.cells.min() < 0 or self.cells.max() >= len(self.points):
            raise MeshError("cells reference nodes that do not exist")
        if not np.all(np.isfinite(self.points)):
            raise MeshError("node coordinates contain NaN or inf")

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def jacobian_determinants(self, order: int = 2) -> np.ndarray:
        """det(dX/dxi) at the quadrature points and corners, (m, nq + 4)."""
        qp, _ = tet10.quadrature(order)
        corners = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        dN = tet10.shape_gradients(np.vstack([qp, corners]))  # (nq+4, 10, 3)
        X = self.points[self.cells]  # (m, 10, 3)
        jac = np.einsum("mai,qaj->mqij", X, dN)
        return np.linalg.det(jac)

    def check(self, relative_tolerance: float = 1e-8) -> None:
        """Raise :class:`MeshError` for inverted or degenerate elements and unused nodes."""
        det = self.jacobian_determinants()
        scale = np.ptp(self.points, axis=0).max() ** 3 / max(self.n_cells, 1)
        bad_inverted = np.flatnonzero((det <= 0).any(axis=1) & (det.max(axis=1) > 0))
        bad_negative = np.flatnonzero((det <= 0).all(axis=1))
        bad_degenerate = np.flatnonzero(np.abs(det).min(axis=1) < relative_tolerance * scale)
        if len(bad_negative):
            raise MeshError(
                f"{len(bad_negative)} inverted element(s) (negative volume), e.g. cell {bad_negative[0]}; "
                "check the node order (VTK tetra10 expected)"
            )
        if len(bad_inverted):
            raise MeshError(
                f"{len(bad_inverted)} distorted element(s) with a sign change of the Jacobian, "
                f"e.g. cell {bad_inverted[0]}; mid-side nodes are misplaced"
            )
        if len(bad_degenerate):
            raise MeshError(f"{len(bad_degenerate)} degenerate (flat) element(s), e.g. cell {bad_degenerate[0]}")
        used = np.zeros(self.n_nodes, dtype=bool)
        used[self.cells.ravel()] = True
        if not used.all():
            raise MeshError(f"{(~used).sum()} node(s) belong to no element; the stiffness would be singular")

    def straighten_invalid_elements(self, max_rounds: int = 5) -> int:
        """Move the mid-side nodes of elements with a non-positive Jacobian to their edge midpoints.

        Snapping mid-side nodes onto a curved boundary can fold thin boundary elements on
        coarse meshes; straight edges are valid whenever the corner tetrahedron is. Returns the
        number of elements that were straightened.
        """
        total = 0
        for _ in range(max_rounds):
            bad = np.flatnonzero((self.jacobian_determinants() <= 0).any(axis=1))
            if len(bad) == 0:
                break
            cells = self.cells[bad]
            mid = 0.5 * (self.points[cells[:, tet10.EDGES[:, 0]]] + self.points[cells[:, tet10.EDGES[:, 1]]])
            self.points[cells[:, 4:].ravel()] = mid.reshape(-1, 3)
            total += len(bad)
        return total

    def boundary_faces(self) -> np.ndarray:
        """Outward-oriented 6-node boundary triangles (k, 6): faces that belong to one cell only."""
        faces = self.cells[:, tet10.FACES].reshape(-1, 6)
        key = np.sort(faces[:, :3], axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        once = counts[inverse.ravel()] == 1
        if np.any(counts > 2):
            raise MeshError("non-manifold mesh: a face is shared by more than two elements")
        return faces[once]

    def surface_nodes(self) -> np.ndarray:
        """Sorted indices of all nodes on the boundary (mid-side nodes included)."""
        return np.unique(self.boundary_faces())

    def volume(self) -> float:
        qp, w = tet10.quadrature(2)
        dN = tet10.shape_gradients(qp)
        jac = np.einsum("mai,qaj->mqij", self.points[self.cells], dN)
        return float((np.linalg.det(jac) * w).sum())

    def to_meshio(self, displacement: np.ndarray | None = None, point_data: dict | None = None):
        import meshio

        data = dict(point_data or {})
        if displacement is not None:
            data["displacement"] = np.asarray(displacement, dtype=float)
        cell_data = {name: [np.asarray(v)] for name, v in self.cell_data.items()}
        return meshio.Mesh(self.points, [("tetra10", self.cells)], point_data=data, cell_data=cell_data)

    @classmethod
    def read(cls, path: str | Path) -> Tet10Mesh:
        """Read any meshio format holding tetra10 cells."""
        import meshio

        m = meshio.read(str(path))
        blocks = [c.data for c in m.cells if c.type == "tetra10"]
        if not blocks:
            types = sorted({c.type for c in m.cells})
            raise MeshError(f"{path}: no quadratic tetrahedra (tetra10) found, only {types}")
        cells = np.vstack(blocks)
        mesh = cls(m.points[:, :3], cells)
        return mesh


def from_gmsh(dim_tags_for_sets: dict[str, list[tuple[int, int]]] | None = None) -> Tet10Mesh:
    """Convert the current gmsh model's second-order tetrahedra into a :class:`Tet10Mesh`.

    ``dim_tags_for_sets`` maps a node-set name to gmsh entities whose nodes (boundary
    included) form that set. Only nodes used by tetrahedra are kept.
    """
    import gmsh

    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = coords.reshape(-1, 3)
    lookup = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    lookup[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    types, _, elem_nodes = gmsh.model.mesh.getElements(3)
    cells = []
    for etype, nodes in zip(types, elem_nodes):
        if etype != 11:  # 11 = 10-node second-order tetrahedron
            raise MeshError(f"gmsh produced volume elements of type {etype}; expected tet10 (type 11)")
        cells.append(lookup[nodes.astype(np.int64)].reshape(-1, 10)[:, tet10.GMSH_TO_VTK])
    if not cells:
        raise MeshError("gmsh model has no volume elements")
    cells = np.vstack(cells)
    used = np.unique(cells)
    renumber = np.full(len(coords), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    node_sets = {}
    for name, dim_tags in (dim_tags_for_sets or {}).items():
        members = []
        for dim, tag in dim_tags:
            tags, _, _ = gmsh.model.mesh.getNodes(dim, tag, includeBoundary=True)
            members.append(renumber[lookup[tags.astype(np.int64)]])
        ids = np.unique(np.concatenate(members))
        node_sets[name] = ids[ids >= 0]
    return Tet10Mesh(coords[used], renumber[cells], node_sets=node_sets)
