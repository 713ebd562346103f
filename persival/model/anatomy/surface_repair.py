"""Repair of a segmented muscle surface before meshing: what is fixed, counted, and what is refused.

Segmented surfaces (MRI, CT, the Visible Human) come with duplicate vertices, degenerate and
repeated triangles, a few non-manifold edges, inconsistent orientation and small holes. Each is
repaired by a library made for it (trimesh for vertex merging, degenerate faces and winding;
pymeshfix for hole filling and self-intersections) and counted, in this order:

1. merge duplicate vertices, drop unreferenced ones;
2. remove degenerate (zero-area) and repeated triangles;
3. fix non-manifold edges (an edge of more than two triangles: the extra triangles are removed,
   the hole they leave is closed in step 5);
4. orient the triangles consistently (winding);
5. close small holes (triangles added); a hole whose area exceeds ``MAX_HOLE_AREA_SHARE`` of
   the surface is refused: a missing end or a cut-open belly is not a repair, it is missing anatomy;
6. turn the surface outward (positive enclosed volume);
7. remove self-intersections; any left are refused.

Several bodies are refused too (loose fragments below ``MAX_FRAGMENT_SHARE`` of the area are
removed and counted). The surface's original vertices keep their order and come first, so
results on the repaired surface map back onto the user's vertices (``source_vertex``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["SurfaceError", "RepairedSurface", "repair_surface", "MAX_HOLE_AREA_SHARE", "MAX_FRAGMENT_SHARE"]

MAX_HOLE_AREA_SHARE = 0.01  # a hole over 1 % of the surface's area is missing anatomy, not a defect
MAX_FRAGMENT_SHARE = 0.001  # a loose piece under 0.1 % of the area is segmentation debris


class SurfaceError(ValueError):
    """A surface that is not a mesh or cannot be repaired into one closed body."""


@dataclass
class RepairedSurface:
    """A closed, consistently outward-oriented triangle surface (vertices in mm).

    ``repairs``: each repair step and its count, in the order they ran. ``source_vertex``:
    for each vertex the index of the input vertex it came from (-1: added by a repair).
    """

    vertices: np.ndarray
    faces: np.ndarray
    repairs: dict[str, int] = field(default_factory=dict)
    source_vertex: np.ndarray | None = None

    @property
    def area(self) -> float:
        tri = self.vertices[self.faces]
        return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())

    @property
    def volume(self) -> float:
        tri = self.vertices[self.faces]
        return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)

    def edge_lengths(self) -> np.ndarray:
        tri = self.vertices[self.faces]
        return np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).ravel()


def repair_surface(vertices: np.ndarray, faces: np.ndarray, name: str = "surface") -> RepairedSurface:
    """Repair a triangle surface (module docstring); raise :class:`SurfaceError` for what cannot be.

    ``name`` prefixes every message (e.g. "muscle 'biceps': surface biceps.obj").
    """
    import trimesh

    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 4:
        raise SurfaceError(f"{name}: not a triangle surface ({len(vertices)} vertices, {len(faces)} triangles)")
    if not np.all(np.isfinite(vertices)) or faces.min() < 0 or faces.max() >= len(vertices):
        raise SurfaceError(f"{name}: not a valid triangle surface (non-finite coordinates or bad vertex indices)")
    repairs: dict[str, int] = {}
    mesh = trimesh.Trimesh(vertices, faces, process=False, validate=False)
    mesh.vertex_attributes["source"] = np.arange(len(vertices))

    n = len(mesh.vertices)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    repairs["merged duplicate vertices"] = n - len(mesh.vertices)
    n = len(mesh.vertices)
    mesh.remove_unreferenced_vertices()
    repairs["removed unreferenced vertices"] = n - len(mesh.vertices)

    keep = mesh.nondegenerate_faces(height=1e-9 * max(np.ptp(mesh.vertices, axis=0).max(), 1e-300))
    repairs["removed degenerate triangles"] = int((~keep).sum())
    mesh.update_faces(keep)
    n = len(mesh.faces)
    mesh.update_faces(mesh.unique_faces())
    repairs["removed repeated triangles"] = n - len(mesh.faces)

    extra = _non_manifold_extras(mesh.faces)
    repairs["fixed non-manifold edges (triangles removed)"] = len(extra)
    if len(extra):
        keep = np.ones(len(mesh.faces), dtype=bool)
        keep[extra] = False
        mesh.update_faces(keep)
    mesh.remove_unreferenced_vertices()

    mesh, repairs["removed loose fragments"] = _one_body(mesh, name)

    before = mesh.faces.copy()
    trimesh.repair.fix_winding(mesh)
    repairs["reoriented triangles"] = int((mesh.faces != before).any(axis=1).sum())

    vertices, faces, source = _close_small_holes(mesh, name, repairs)
    volume = RepairedSurface(vertices, faces).volume
    if volume < 0:  # consistently inward: turn every triangle
        faces = faces[:, ::-1].copy()
    repairs["turned outward (triangles)"] = len(faces) if volume < 0 else 0

    vertices, faces, source = _remove_self_intersections(vertices, faces, source, name, repairs)
    surface = RepairedSurface(vertices, faces, repairs, source)
    _check_closed(surface, name)
    return surface


def _non_manifold_extras(faces: np.ndarray) -> np.ndarray:
    """Triangles to remove so that no edge has more than two: on each such edge, those with the
    most open edges go first (a fin or a dangling sheet), then the later ones in the file."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(len(faces)), 3)
    _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    open_edges = (counts[inverse] == 1).reshape(-1, 3).sum(axis=1)
    extras: set[int] = set()
    for edge in np.flatnonzero(counts > 2):
        sharing = sorted((f for f in owner[inverse == edge] if f not in extras), key=lambda f: (-open_edges[f], f))
        extras.update(sharing[: max(0, len(sharing) - 2)])  # some may have gone for another edge already
    return np.array(sorted(extras), dtype=np.int64)


def _one_body(mesh, name: str):
    """The mesh without loose debris, and the number of fragments removed; several bodies refused."""
    import trimesh

    parts = trimesh.graph.connected_components(mesh.face_adjacency, nodes=np.arange(len(mesh.faces)), min_len=1)
    if len(parts) == 1:
        return mesh, 0
    areas = np.array([mesh.area_faces[p].sum() for p in parts])
    share = areas / areas.sum()
    big = np.flatnonzero(share >= MAX_FRAGMENT_SHARE)
    if len(big) > 1:
        sizes = ", ".join(f"{100 * s:.1f} %" for s in sorted(share[big], reverse=True))
        raise SurfaceError(f"{name}: {len(big)} disconnected bodies (shares of the area: {sizes}); a muscle is one "
                           "closed body: keep one, or join them in the segmentation")
    keep = np.zeros(len(mesh.faces), dtype=bool)
    keep[parts[big[0]]] = True
    mesh.update_faces(keep)
    mesh.remove_unreferenced_vertices()
    return mesh, len(parts) - 1


def _boundary_loops(faces: np.ndarray, vertices: np.ndarray) -> list[tuple[int, float]]:
    """(number of edges, area) of each hole: the edges of one triangle only, grouped by connection.

    The area is the norm of the loop's vector area 0.5 sum(p_a x p_b) over its directed edges,
    which needs no ordering of the loop (the winding is consistent by now)."""
    import trimesh

    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    open_edges = directed[counts[inverse.ravel()] == 1]
    if len(open_edges) == 0:
        return []
    loops = trimesh.graph.connected_components(open_edges, min_len=1)
    result = []
    for members in loops:
        inside = np.isin(open_edges[:, 0], members)
        e = open_edges[inside]
        vector_area = 0.5 * np.cross(vertices[e[:, 0]], vertices[e[:, 1]]).sum(axis=0)
        result.append((len(e), float(np.linalg.norm(vector_area))))
    return result


def _close_small_holes(mesh, name: str, repairs: dict):
    """Fill every hole with pymeshfix after refusing the large ones; (vertices, faces, source)."""
    vertices, faces = np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)
    source = np.asarray(mesh.vertex_attributes["source"], dtype=np.int64)
    loops = _boundary_loops(faces, vertices)
    repairs["closed small holes"] = len(loops)
    repairs["triangles added (holes)"] = 0
    if not loops:
        return vertices, faces, source
    area = float(mesh.area)
    largest = max(loops, key=lambda loop: loop[1])
    if largest[1] > MAX_HOLE_AREA_SHARE * area:
        raise SurfaceError(f"{name}: open surface with a hole of {largest[0]} edges and about {largest[1]:.0f} mm^2 "
                           f"({100 * largest[1] / area:.1f} % of its area; holes up to {100 * MAX_HOLE_AREA_SHARE:g} % are "
                           "closed): close it in the segmentation")
    fixer = _meshfix()
    fixer.load_array(vertices, faces.astype(np.int32))
    fixer.fill_small_boundaries(nbe=max(n for n, _ in loops), refine=True)
    new_vertices, new_faces = fixer.return_arrays()
    repairs["triangles added (holes)"] = len(new_faces) - len(faces)
    return _keep_vertex_order(vertices, source, new_vertices, new_faces)


def _keep_vertex_order(vertices, source, new_vertices, new_faces):
    """pymeshfix's result renumbered so that the vertices it kept (same coordinates, bit for bit)
    come first in their old order and the ones it added follow: (vertices, faces, source)."""
    new_vertices = np.asarray(new_vertices, dtype=float)
    old = {p.tobytes(): k for k, p in enumerate(vertices)}
    position = np.array([old.get(p.tobytes(), -1) for p in new_vertices], dtype=np.int64)
    kept = position >= 0
    order = np.empty(len(new_vertices), dtype=np.int64)
    # kept vertices by their old index (gaps where pymeshfix dropped one are closed), added ones after
    ranked = np.argsort(np.where(kept, position, len(vertices) + np.arange(len(new_vertices))), kind="stable")
    order[ranked] = np.arange(len(new_vertices))
    out_source = np.full(len(new_vertices), -1, dtype=np.int64)
    out_source[order[kept]] = source[position[kept]]
    out_vertices = np.empty_like(new_vertices)
    out_vertices[order] = new_vertices
    return out_vertices, order[np.asarray(new_faces, dtype=np.int64)], out_source


def _meshfix():
    import pymeshfix

    fixer = pymeshfix.PyTMesh()
    fixer.set_quiet(1)  # its progress lines would break the command line's output
    return fixer


def _intersecting(vertices: np.ndarray, faces: np.ndarray) -> int:
    fixer = _meshfix()
    fixer.load_array(vertices, faces.astype(np.int32))
    return len(fixer.select_intersecting_triangles(justproper=True))


def _remove_self_intersections(vertices, faces, source, name: str, repairs: dict):
    """pymeshfix's cleaning where triangles cross each other; refused if any remain."""
    crossing = _intersecting(vertices, faces)
    repairs["removed self-intersections (triangles)"] = crossing
    if crossing == 0:
        return vertices, faces, source
    fixer = _meshfix()
    fixer.load_array(vertices, faces.astype(np.int32))
    fixer.clean(max_iters=10, inner_loops=3)
    new_vertices, new_faces = (np.asarray(a) for a in fixer.return_arrays())
    left = _intersecting(new_vertices, new_faces)
    if left:
        raise SurfaceError(f"{name}: {left} self-intersecting triangles remain after repair (of {crossing}); "
                           "the surface folds through itself: fix it in the segmentation")
    return _keep_vertex_order(vertices, source, new_vertices, new_faces)


def _check_closed(surface: RepairedSurface, name: str) -> None:
    faces = surface.faces
    key = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(key, axis=0, return_counts=True)
    if np.any(counts != 2):
        raise SurfaceError(f"{name}: still not closed after repair ({int((counts == 1).sum())} open and "
                           f"{int((counts > 2).sum())} non-manifold edges)")
    if surface.volume <= 0:
        raise SurfaceError(f"{name}: encloses no volume after repair")
