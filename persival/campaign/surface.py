"""The outer surface of a selected part of a mesh, as linear display triangles.

Volume cells (tetrahedra, hexahedra, also their quadratic variants through their corner nodes)
contribute the faces that no other cell of the selection shares; surface cells (triangles,
quads) are taken as they are. Quads become two triangles. Node numbering follows VTK / meshio,
whose face tables below list every face counter-clockwise seen from outside, so the triangles
of a consistently oriented volume mesh point outward.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SurfaceError", "boundary_triangles", "compact", "VOLUME_FACES"]


class SurfaceError(ValueError):
    """Cells from which no surface can be extracted."""


_TET_FACES = [(0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)]
_HEX_FACES = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
#: meshio cell type -> (number of corner nodes, faces on those corners)
VOLUME_FACES = {
    "tetra": (4, _TET_FACES),
    "tetra10": (4, _TET_FACES),
    "hexahedron": (8, _HEX_FACES),
    "hexahedron20": (8, _HEX_FACES),
    "hexahedron27": (8, _HEX_FACES),
}
_SURFACE_CORNERS = {"triangle": 3, "triangle6": 3, "triangle7": 3, "quad": 4, "quad8": 4, "quad9": 4}


def _triangulate(faces: np.ndarray) -> np.ndarray:
    if faces.shape[1] == 3:
        return faces
    return np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])


def boundary_triangles(blocks: list[tuple[str, np.ndarray]]) -> np.ndarray:
    """Triangles (global node ids) of the surface of the given cell blocks.

    ``blocks``: (meshio cell type, connectivity) pairs of one part. Volume and surface blocks may
    not be mixed in one part (a part is either a solid or a shell).
    """
    volume = [(t, c) for t, c in blocks if t in VOLUME_FACES]
    surface = [(t, c) for t, c in blocks if t in _SURFACE_CORNERS]
    other = sorted({t for t, c in blocks if t not in VOLUME_FACES and t not in _SURFACE_CORNERS
                    and t not in ("vertex", "line", "line3")})
    if other:
        raise SurfaceError(f"cannot extract a surface from cells of type {', '.join(other)}; "
                           f"supported: {', '.join(sorted(VOLUME_FACES) + sorted(_SURFACE_CORNERS))}")
    if volume and surface:
        raise SurfaceError("the selection mixes volume and surface cells; select one part only")
    if surface:
        tris = [_triangulate(np.asarray(c)[:, :_SURFACE_CORNERS[t]]) for t, c in surface]
        return np.concatenate(tris).astype(np.int64)
    if not volume:
        raise SurfaceError("the selection contains no volume or surface cells")
    faces_by_size: dict[int, list[np.ndarray]] = {3: [], 4: []}
    for cell_type, conn in volume:
        n_corners, faces = VOLUME_FACES[cell_type]
        conn = np.asarray(conn)[:, :n_corners].astype(np.int64)
        for face in faces:
            faces_by_size[len(face)].append(conn[:, face])
    out = []
    for parts in faces_by_size.values():
        if not parts:
            continue
        faces = np.concatenate(parts)
        # A face shared by two cells appears twice (same node set): keep those seen once.
        _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True,
                                       return_counts=True)
        out.append(_triangulate(faces[counts[inverse.ravel()] == 1]))
    tris = np.concatenate(out) if out else np.zeros((0, 3), dtype=np.int64)
    if len(tris) == 0:
        raise SurfaceError("the selected cells have no boundary faces")
    return tris


def compact(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(node ids used, sorted) and the triangles renumbered into that list."""
    nodes, local = np.unique(triangles, return_inverse=True)
    return nodes, local.reshape(triangles.shape).astype(np.int64)
