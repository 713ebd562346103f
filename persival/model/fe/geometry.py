"""Meshes of simple bodies: a structured tet10 box (verification) and swept solids (muscles).

A muscle is a smooth closed solid swept along its centre line with a varying circular cross
section: gmsh lofts circles placed perpendicular to the centre line (``addThruSections``)
and meshes the solid with second-order tetrahedra.
"""

from __future__ import annotations

from itertools import permutations

import numpy as np

from persival.model.fe import tet10
from persival.model.fe.mesh import MeshError, Tet10Mesh, from_gmsh


def box_mesh(n: tuple[int, int, int], size: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Tet10Mesh:
    """A structured tet10 mesh of [0, Lx] x [0, Ly] x [0, Lz]: each hexahedron in 6 Kuhn tetrahedra.

    The mid-side nodes all lie on the lattice of half the spacing, so the mesh is built by
    index arithmetic alone. Node sets: ``x0, x1, y0, y1, z0, z1`` (the six faces).
    """
    nx, ny, nz = (int(v) for v in n)
    if min(nx, ny, nz) < 1:
        raise ValueError("box_mesh needs at least one hexahedron per direction")
    shape = np.array([2 * nx + 1, 2 * ny + 1, 2 * nz + 1])
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, s, m) for s, m in zip(size, shape)], indexing="ij"), axis=-1)
    points = grid.reshape(-1, 3)

    def lattice_id(ijk: np.ndarray) -> np.ndarray:
        return (ijk[..., 0] * shape[1] + ijk[..., 1]) * shape[2] + ijk[..., 2]

    hexes = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), axis=-1).reshape(-1, 3)
    tets = []
    for perm in permutations(range(3)):
        path = [np.zeros(3, dtype=int)]
        for axis in perm:
            step = path[-1].copy()
            step[axis] += 1
            path.append(step)
        tets.append(np.array(path))
    tets = np.array(tets)  # (6, 4, 3) corner offsets in the unit cube
    corners = 2 * (hexes[:, None, None, :] + tets[None])  # (nh, 6, 4, 3) on the doubled lattice
    corners = corners.reshape(-1, 4, 3)
    edges = (corners[:, tet10.EDGES[:, 0]] + corners[:, tet10.EDGES[:, 1]]) // 2
    cells = lattice_id(np.concatenate([corners, edges], axis=1))
    mesh_points = points
    # Half of the Kuhn tetrahedra are left-handed: swap two corners (and the affected edges).
    X = mesh_points[cells[:, :4]]
    vol = np.einsum("mi,mi->m", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0])
    flip = vol < 0
    # swapping corners 1 and 2 maps edges (0,1)<->(0,2), (1,3)<->(2,3), (1,2) stays
    swap = np.array([0, 2, 1, 3, 6, 5, 4, 7, 9, 8])
    cells[flip] = cells[flip][:, swap]
    used = np.unique(cells)
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    mesh_points = points[used]
    cells = renumber[cells]
    sets = {}
    for axis, name in enumerate("xyz"):
        sets[f"{name}0"] = np.flatnonzero(np.isclose(mesh_points[:, axis], 0.0))
        sets[f"{name}1"] = np.flatnonzero(np.isclose(mesh_points[:, axis], size[axis]))
    return Tet10Mesh(mesh_points, cells, node_sets=sets)


def _perpendicular_frame(tangent: np.ndarray) -> np.ndarray:
    helper = np.array([1.0, 0.0, 0.0]) if abs(tangent[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(tangent, helper)
    return e1 / np.linalg.norm(e1)


def swept_solid_mesh(
    centre_line: np.ndarray,
    radii: np.ndarray,
    mesh_size: float,
    *,
    major_axes: np.ndarray | None = None,
    verbose: bool = False,
) -> Tet10Mesh:
    """Loft circles of ``radii`` (k,) placed perpendicular to ``centre_line`` (k, 3) into a tet10 mesh;
    or ellipses: ``radii`` (k, 2) their semi-axes, the larger first, along ``major_axes`` (k, 3),
    unit vectors perpendicular to the centre line.

    Node sets ``origin`` and ``insertion``: the nodes of the first and last end cap.
    Cell data ``fibre`` (unit tangent of the centre line nearest the cell centroid) and
    ``arclength`` (normalized position 0..1 of that point along the centre line).
    """
    import gmsh

    centre_line = np.asarray(centre_line, dtype=float)
    radii = np.asarray(radii, dtype=float)
    if centre_line.ndim != 2 or centre_line.shape[1] != 3 or len(centre_line) < 2:
        raise MeshError("centre_line must be (k >= 2, 3)")
    elliptic = major_axes is not None
    if radii.shape != ((len(centre_line), 2) if elliptic else (len(centre_line),)):
        raise MeshError("one radius (two semi-axes for ellipses) per centre-line station is required")
    if elliptic and np.any(radii[:, 0] < radii[:, 1]):
        raise MeshError("an ellipse's larger semi-axis comes first")
    if np.any(radii <= 0) or not np.all(np.isfinite(radii)):
        raise MeshError("radii must be positive and finite")
    if mesh_size <= 0:
        raise MeshError("mesh_size must be positive")
    segment = np.diff(centre_line, axis=0)
    if np.any(np.linalg.norm(segment, axis=1) <= 0):
        raise MeshError("centre-line stations must be distinct")
    tangents = np.gradient(centre_line, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1)[:, None]

    initialized_here = not gmsh.isInitialized()
    if initialized_here:
        gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Verbosity", 5 if verbose else 0)
    gmsh.model.add("swept_solid")
    try:
        out = _loft(centre_line, tangents, radii, major_axes)
        gmsh.model.occ.synchronize()
        volumes = [tag for dim, tag in out if dim == 3]
        if len(volumes) != 1:
            raise MeshError(f"lofting produced {len(volumes)} volumes, expected 1")
        boundary = gmsh.model.getBoundary([(3, volumes[0])], oriented=False)
        caps = {}
        for dim, tag in boundary:
            com = np.array(gmsh.model.occ.getCenterOfMass(dim, tag))
            if gmsh.model.getType(dim, tag) == "Plane":
                end = "origin" if np.linalg.norm(com - centre_line[0]) < np.linalg.norm(com - centre_line[-1]) else "insertion"
                caps[end] = [(dim, tag)]
        if set(caps) != {"origin", "insertion"}:
            raise MeshError("could not identify the two end caps of the swept solid")
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.2 * mesh_size)
        if elliptic:
            # elements of about the section's smaller semi-axis (the circles' rule below, without
            # the tiny elements the curvature at a flat ellipse's ends would ask for)
            _size_from_sections(centre_line, radii[:, 1], mesh_size)
        else:
            # thin tendons need elements of about their radius: size from the circles' curvature
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 6)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay: robust for smooth lofts
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.option.setNumber("Mesh.ElementOrder", 2)
        gmsh.option.setNumber("Mesh.SecondOrderLinear", 0)  # mid-side nodes on the curved surface
        gmsh.option.setNumber("Mesh.HighOrderOptimize", 0)  # its optimizer can abort the process
        gmsh.model.mesh.generate(3)
        mesh = from_gmsh(caps)
    finally:
        gmsh.model.remove()
        if initialized_here:
            gmsh.finalize()

    centroids = mesh.points[mesh.cells[:, :4]].mean(axis=1)
    s, tangent = _project_on_polyline(centroids, centre_line)
    mesh.cell_data["fibre"] = tangent
    mesh.cell_data["arclength"] = s
    mesh.straighten_invalid_elements()
    mesh.check()
    return mesh


def _loft(centre_line, tangents, radii, major_axes):
    """gmsh OCC: a circle (or an ellipse along ``major_axes``) across the centre line at every
    station, lofted into one solid; returns addThruSections' entities."""
    import gmsh

    wires = []
    for k, (centre, tangent) in enumerate(zip(centre_line, tangents)):
        if major_axes is not None:  # the seam on the larger semi-axis at every station: the loft does not twist
            section = gmsh.model.occ.addEllipse(*centre, *radii[k], zAxis=list(tangent), xAxis=list(major_axes[k]))
        else:
            section = gmsh.model.occ.addCircle(*centre, radii[k], zAxis=list(tangent),
                                               xAxis=list(_perpendicular_frame(tangent)))
        wires.append(gmsh.model.occ.addCurveLoop([section]))
    return gmsh.model.occ.addThruSections(wires, makeSolid=True, makeRuled=False)


def _size_from_sections(centre_line: np.ndarray, semi_minor: np.ndarray, mesh_size: float) -> None:
    """gmsh's element size at a point: 1.05 times the smaller semi-axis of the nearest station
    (6 elements round a circle, as MeshSizeFromCurvature = 6 gives), at most ``mesh_size``."""
    import gmsh

    size = np.minimum(1.05 * semi_minor, mesh_size)

    def at(dim, tag, x, y, z, lc):
        return float(size[np.argmin(np.sum((centre_line - (x, y, z)) ** 2, axis=1))])

    gmsh.model.mesh.setSizeCallback(at)


def _project_on_polyline(x: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalized arclength (n,) and unit tangent (n, 3) of the closest point of a polyline."""
    a, b = line[:-1], line[1:]
    d = b - a
    length = np.linalg.norm(d, axis=1)
    t = np.clip(np.einsum("nsi,si->ns", x[:, None, :] - a[None], d) / (length**2)[None], 0.0, 1.0)
    closest = a[None] + t[..., None] * d[None]
    seg = np.argmin(np.linalg.norm(x[:, None, :] - closest, axis=2), axis=1)
    cumulative = np.concatenate([[0.0], np.cumsum(length)])
    rows = np.arange(len(x))
    s = (cumulative[seg] + t[rows, seg] * length[seg]) / cumulative[-1]
    return s, d[seg] / length[seg, None]


def spindle(
    length: float = 300.0,
    belly_radius: float = 20.0,
    tendon_radius: float = 5.0,
    mesh_size: float = 7.0,
    stations: int = 25,
) -> Tet10Mesh:
    """A fusiform muscle along z from 0 to ``length``: radius follows a smooth bump.

    r(s) = r_t + (r_b - r_t) sin(pi s)^2, the shape of the paper-size verification body
    (a 40 x 300 mm spindle at 7 mm gives about 3.5k tet10).
    """
    s = np.linspace(0.0, 1.0, stations)
    centre = np.column_stack([np.zeros_like(s), np.zeros_like(s), length * s])
    radii = tendon_radius + (belly_radius - tendon_radius) * np.sin(np.pi * s) ** 2
    return swept_solid_mesh(centre, radii, mesh_size)


def spindle_material(mesh: Tet10Mesh, prestretch: float = 1.0, transition: float = 0.1):
    """Material of a fusiform muscle-tendon unit along its ``arclength`` cell data (docs/theory.md, 1.5).

    Pure tendon over the first and last ``transition`` of the length, a linear muscle-tendon
    blend over the next ``transition``, pure muscle in the belly. Bulk moduli k = 100 MPa
    (muscle) and 1000 MPa (tendon), blended like the other parameters: about 1000 times the
    shear moduli, so |J - 1| stays below 1 % at full activation.
    """
    from persival.model.fe.assembly import MaterialField

    s = mesh.cell_data["arclength"]
    gamma_m = np.clip((np.minimum(s, 1 - s) - transition) / transition, 0.0, 1.0)
    k = gamma_m * 100.0 + (1 - gamma_m) * 1000.0
    return MaterialField.from_cells(4, mesh.cell_data["fibre"], gamma_m, k, prestretch)
