"""gmsh tet10 volume mesh of a closed, repaired surface, keeping its vertices as nodes where possible.

Where the surface's triangles are about the profile's element size or coarser (median edge at
least ``KEEP_SHARE`` of it), the surface is handed to gmsh as a discrete surface and kept as it
is: every vertex becomes a mesh node at exactly its coordinates, so results map back onto the
user's surface one to one, and only the interior is meshed (3D Delaunay, sizes grown from the
boundary up to the profile's size). Mid-side nodes sit on the straight edges (the surface has
no parametrization to curve them onto). A surface much finer than the profile asks for (a
segmentation at 1 mm) would give a mesh far too fine to solve: it is reparametrized
(``classifySurfaces``, ``createGeometry``) and remeshed at the profile's size, refined where the
muscle is thin (an element no larger than the local section's radius: tendons keep two elements
across), and its vertices are no longer nodes. The section radius, not the surface's curvature,
sets the size: a segmentation's voxel noise is curvature everywhere and refined a noisy biceps to
20 000 surface nodes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from persival.model.anatomy.surface_repair import RepairedSurface
from persival.model.fe.mesh import MeshError, Tet10Mesh, from_gmsh

__all__ = ["VolumeMesh", "KEEP_SHARE", "volume_mesh"]

KEEP_SHARE = 0.5  # keep the user's triangles when their median edge is at least half the element size
MIN_SIZE_SHARE = 0.25  # the smallest element of a remeshed surface, in element sizes
CLASSIFY_ANGLES_DEG = (40.0, 60.0, 80.0, 25.0)  # feature angles of the reparametrization, tried in turn
SECTIONS = 60  # slabs along the surface's long axis for the section radius


@dataclass
class VolumeMesh:
    mesh: Tet10Mesh
    surface_kept: bool  # the surface's own triangles are the mesh's boundary
    vertices_kept: int  # surface vertices that are mesh nodes at exactly their coordinates
    seconds: float
    min_quality: float  # gmsh's gamma (inscribed / circumscribed radius, normalized; 1 = regular)
    straightened: int = 0  # elements whose curved mid-side nodes were put back on straight edges


def volume_mesh(surface: RepairedSurface, mesh_size: float, verbose: bool = False) -> VolumeMesh:
    """tet10 mesh of the solid the surface encloses (module docstring)."""
    import gmsh

    if mesh_size <= 0:
        raise MeshError("mesh_size must be positive")
    keep = float(np.median(surface.edge_lengths())) >= KEEP_SHARE * mesh_size
    t0 = time.perf_counter()
    initialized_here = not gmsh.isInitialized()
    if initialized_here:
        gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Verbosity", 5 if verbose else 0)
    try:
        patch = _add_surface(gmsh, surface)
        patches = [patch] if keep else _reparametrize(gmsh, surface)
        loop = gmsh.model.geo.addSurfaceLoop(patches)
        gmsh.model.geo.addVolume([loop])
        gmsh.model.geo.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", MIN_SIZE_SHARE * mesh_size)
        if not keep:
            # sizes from the section radius alone: the patches' boundary curves and corner points
            # of the reparametrization would otherwise pass their fine sizes inward (a noisy
            # biceps: median boundary edge 3.6 mm at a 10 mm profile; without: 5.8 mm)
            gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
            gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
            radius = section_radius(surface)
            gmsh.model.mesh.setSizeCallback(lambda dim, tag, x, y, z, lc: float(np.clip(
                radius(np.array([x, y, z])), MIN_SIZE_SHARE * mesh_size, mesh_size)))
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay: honours a given boundary mesh
        gmsh.option.setNumber("Mesh.Optimize", 1)
        # Netgen's optimizer on top: a segmentation's thin triangles leave slivers behind that
        # gmsh's own does not remove (spindle test surface: minimum gamma 0.001 -> 0.026)
        gmsh.option.setNumber("Mesh.OptimizeNetgen", 1)
        gmsh.option.setNumber("Mesh.ElementOrder", 2)
        # kept surface: straight edges (no parametrization to follow); remeshed: mid-side nodes on
        # the reparametrized surface (straight ones lost 4.8 % of a noisy biceps' volume)
        gmsh.option.setNumber("Mesh.SecondOrderLinear", 1 if keep else 0)
        gmsh.option.setNumber("Mesh.HighOrderOptimize", 0)
        try:
            gmsh.model.mesh.generate(3)
        except Exception as exc:
            raise MeshError(f"gmsh could not mesh the surface's volume: {exc}") from None
        _, element_tags, _ = gmsh.model.mesh.getElements(3)
        if not element_tags or len(element_tags[0]) == 0:
            raise MeshError("gmsh made no tetrahedra inside the surface (is it closed and free of self-intersections?)")
        quality = gmsh.model.mesh.getElementQualities(element_tags[0], "gamma")
        mesh = from_gmsh()
    finally:
        gmsh.model.remove()
        if initialized_here:
            gmsh.finalize()
    straightened = mesh.straighten_invalid_elements()  # a curved mid-side node that folded a thin element
    mesh.check()
    return VolumeMesh(mesh, keep, _vertices_kept(surface.vertices, mesh.points), time.perf_counter() - t0,
                      float(np.min(quality)), straightened)


def _add_surface(gmsh, surface: RepairedSurface) -> int:
    """A fresh gmsh model holding the surface as one discrete entity; its tag."""
    gmsh.model.add("muscle_surface")
    patch = gmsh.model.addDiscreteEntity(2)
    gmsh.model.mesh.addNodes(2, patch, np.arange(1, len(surface.vertices) + 1), surface.vertices.ravel())
    gmsh.model.mesh.addElementsByType(patch, 2, [], (surface.faces + 1).ravel())
    return patch


def _reparametrize(gmsh, surface: RepairedSurface) -> list[int]:
    """Split the discrete surface into patches that can be parametrized and build a geometry gmsh
    can remesh; the patches' tags. The split follows the angle between neighbouring triangles:
    on a noisy segmentation one threshold can leave a patch that is not a disk ("Wrong topology
    of boundary mesh for parametrization": a closed, manifold biceps-like surface failed at 20,
    30 and 40 deg and passed at 60), so the thresholds are tried in turn, each on a fresh model."""
    for k, angle in enumerate(CLASSIFY_ANGLES_DEG):
        if k:
            gmsh.model.remove()
            _add_surface(gmsh, surface)
        try:
            gmsh.model.mesh.classifySurfaces(np.radians(angle), True, True, np.pi)
            gmsh.model.mesh.createGeometry()
            return [tag for _, tag in gmsh.model.getEntities(2)]
        except Exception as exc:  # gmsh raises plain Exceptions
            error = exc
    raise MeshError(f"gmsh could not reparametrize the surface for remeshing at any of the feature angles "
                    f"{', '.join(f'{a:g}' for a in CLASSIFY_ANGLES_DEG)} deg ({error}); a surface with triangles about "
                    "the profile's element size is kept as it is instead (no remeshing)")


def section_radius(surface: RepairedSurface):
    """x -> the mean radius of the surface's cross section at x's position along its long axis
    (the first principal direction of its vertices; slabs of the surface's vertices, each one's
    mean distance from its centroid square to the axis), interpolated between slabs."""
    vertices = surface.vertices
    centre = vertices.mean(axis=0)
    axis = np.linalg.svd(vertices - centre, full_matrices=False)[2][0]
    t = (vertices - centre) @ axis
    edges = np.linspace(t.min(), t.max(), SECTIONS + 1)
    slab = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, SECTIONS - 1)
    count = np.bincount(slab, minlength=SECTIONS)
    filled = count > 0
    mid = np.column_stack([np.bincount(slab, vertices[:, k], SECTIONS) for k in range(3)])[filled] / count[filled, None]
    offset = vertices - mid[np.cumsum(filled)[slab] - 1]
    offset -= np.outer(offset @ axis, axis)
    radii = np.bincount(slab, np.linalg.norm(offset, axis=1), SECTIONS)[filled] / count[filled]
    where = 0.5 * (edges[:-1] + edges[1:])[filled]
    return lambda x: float(np.interp((x - centre) @ axis, where, radii))


def _vertices_kept(vertices: np.ndarray, points: np.ndarray) -> int:
    nodes = {p.tobytes() for p in np.ascontiguousarray(points)}
    return sum(v.tobytes() in nodes for v in np.ascontiguousarray(vertices))
