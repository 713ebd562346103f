"""A muscle's own surface: read, converted to mm, repaired and placed in the arm frame (docs/own_anatomy.md).

The model file names the surface (STL, OBJ, PLY, VTK or VTP), its units and two points in the
surface's own coordinates near its ends, ``origin_point`` and ``insertion_point``. The surface
is placed by the rigid motion, times an optional uniform scale (``scale_to_fit``), that takes
``origin_point`` to the muscle's ``origin`` and turns the line ``origin_point -> insertion_point``
onto the line to the muscle's insertion in its mesh pose by the smallest rotation (no twist
about that line):

    x' = O + s Q (x - p_O),   Q = the minimal rotation of (p_I - p_O) onto (I - O),
    s = |I - O| / |p_I - p_O| with scale_to_fit, else 1.

Without ``scale_to_fit`` the insertion face sits at ``|p_I - p_O|`` along the line; the rest of
the way to the insertion point rides rigidly with it (the insertion tie moves the face by the
change of ``|I - O|``). Refused, with the reason: a file that is no triangle surface, what the
repair refuses (persival.model.anatomy.surface_repair), an end point far from the surface, and a size
that does not fit the model (the message names the units that would fit).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from persival.model.anatomy.surface_repair import RepairedSurface, SurfaceError, repair_surface
from persival.model.fe.rotations import line_rotation

__all__ = ["PlacedSurface", "SurfaceError", "UNITS", "SURFACE_FORMATS", "read_surface", "place_surface"]

UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
SURFACE_FORMATS = (".stl", ".obj", ".ply", ".vtk", ".vtp")
# After the conversion to mm the coordinates are rounded to 1 nm: the same surface written in
# metres or millimetres is then the same surface bit for bit, and gmsh meshes it identically.
ROUND_DECIMALS = 6
FIT_RANGE = (0.5, 2.0)  # model length / surface length outside this: wrong units, not anatomy
FAR_SHARE, FAR_FLOOR_MM = 0.05, 5.0  # an end point farther from the surface than max(5 % of the length, 5 mm)


@dataclass
class PlacedSurface:
    """The repaired surface in the arm frame (mm) and how it got there."""

    surface: RepairedSurface  # vertices placed in the arm frame
    vertices_in: int  # vertices of the file as read
    triangles_in: int
    scale: float  # the uniform scale of the placement (1 without scale_to_fit)
    rotation: np.ndarray  # Q
    origin: np.ndarray  # where origin_point went: the muscle's origin
    insertion: np.ndarray  # where insertion_point went (= the insertion with scale_to_fit)
    target_insertion: np.ndarray  # the muscle's insertion in its mesh pose
    end_distance_mm: tuple[float, float]  # origin_point's and insertion_point's distance to the surface


def read_surface(path: str | Path, label: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and triangles (m, 3) of a surface file, as written (no merging, no repair).
    ``label`` heads every message (default: the path)."""
    path = Path(path)
    label = label or str(path)
    suffix = path.suffix.lower()
    if suffix not in SURFACE_FORMATS:
        raise SurfaceError(f"{label}: unknown surface format {suffix!r}; use one of {', '.join(SURFACE_FORMATS)}")
    if not path.is_file():
        raise FileNotFoundError(f"{label}: no such surface file")
    try:
        vertices, faces = _read_vtk(path) if suffix in (".vtk", ".vtp") else _read_trimesh(path)
    except SurfaceError:
        raise
    except Exception as exc:  # every reader fails its own way on a file that is no mesh
        raise SurfaceError(f"{label}: not a readable {suffix[1:].upper()} triangle surface ({type(exc).__name__}: "
                           f"{str(exc).splitlines()[0] if str(exc) else 'unreadable'})") from None
    if len(faces) < 4 or len(vertices) < 4:
        raise SurfaceError(f"{label}: not a triangle surface ({len(vertices)} vertices, {len(faces)} triangles)")
    return vertices, faces


def _read_trimesh(path: Path):
    import trimesh

    mesh = trimesh.load(str(path), force="mesh", process=False)
    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError("holds no triangles")  # reported with the label by read_surface
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def _read_vtk(path: Path):
    import pyvista

    data = pyvista.read(str(path))
    surface = data.extract_surface(algorithm=None) if not isinstance(data, pyvista.PolyData) else data
    surface = surface.triangulate()
    faces = np.asarray(surface.faces).reshape(-1, 4)
    if len(faces) and not np.all(faces[:, 0] == 3):
        raise SurfaceError(f"{path}: holds cells that are not triangles")
    return np.asarray(surface.points, dtype=float), faces[:, 1:].astype(np.int64)


def place_surface(path: str | Path, units: str, origin_point, insertion_point, scale_to_fit: bool,
                  origin, insertion, name: str) -> PlacedSurface:
    """Read, repair and place a muscle's surface (module docstring). ``origin``, ``insertion``:
    the muscle's origin and its insertion in the mesh pose, arm frame (mm). ``name`` heads every
    message (e.g. "muscle 'biceps'")."""
    if units not in UNITS:
        raise SurfaceError(f"{name}: surface_units must be one of {', '.join(UNITS)}, got {units!r}")
    label = f"{name}: surface {Path(path).name}"
    raw_vertices, raw_faces = read_surface(path, label)
    factor = UNITS[units]
    p_origin = np.round(np.asarray(origin_point, dtype=float) * factor, ROUND_DECIMALS)
    p_insertion = np.round(np.asarray(insertion_point, dtype=float) * factor, ROUND_DECIMALS)
    origin, target = np.asarray(origin, dtype=float), np.asarray(insertion, dtype=float)
    surface_length = float(np.linalg.norm(p_insertion - p_origin))
    model_length = float(np.linalg.norm(target - origin))
    if surface_length == 0:
        raise SurfaceError(f"{name}: origin_point and insertion_point coincide")
    _check_size(name, units, surface_length / factor, model_length)
    surface = repair_surface(np.round(raw_vertices * factor, ROUND_DECIMALS), raw_faces, label)
    distances = _distances(surface, np.array([p_origin, p_insertion]))
    tolerance = max(FAR_SHARE * surface_length, FAR_FLOOR_MM)
    for which, d, p in zip(("origin_point", "insertion_point"), distances, (origin_point, insertion_point)):
        if d > tolerance:
            raise SurfaceError(f"{label}: {which} {list(p)} lies {d:.1f} mm from the surface (at most {tolerance:.1f} mm: "
                               "a point near that end of the muscle, in the surface's coordinates and units)")
    scale = model_length / surface_length if scale_to_fit else 1.0
    rotation = _minimal_rotation((p_insertion - p_origin) / surface_length, (target - origin) / model_length)
    placed = origin + scale * (surface.vertices - p_origin) @ rotation.T
    surface.vertices = placed
    insertion_at = origin + scale * rotation @ (p_insertion - p_origin)
    return PlacedSurface(surface, len(raw_vertices), len(raw_faces), scale, rotation, origin, insertion_at, target,
                         (float(distances[0]), float(distances[1])))


def _check_size(name: str, units: str, raw_length: float, model_length: float) -> None:
    """Refuse a surface whose end points are implausibly far apart for the model, naming the units
    that would fit (a surface in metres read as millimetres spans 0.3 mm)."""
    ratio = model_length / (raw_length * UNITS[units])
    if FIT_RANGE[0] <= ratio <= FIT_RANGE[1]:
        return
    likely = min(UNITS, key=lambda u: abs(np.log(model_length / (raw_length * UNITS[u]))))
    hint = (f"the surface is likely in {likely} (surface_units = \"{likely}\")" if likely != units else
            "no unit fits: check origin_point and insertion_point (surface coordinates) and the muscle's origin and "
            "insertion")
    raise SurfaceError(f"{name}: implausible size: origin_point to insertion_point spans {raw_length * UNITS[units]:.4g} mm "
                       f"as {units}, the model's origin to insertion {model_length:.1f} mm (ratio {ratio:.3g}); {hint}")


def _minimal_rotation(d_from: np.ndarray, d_to: np.ndarray) -> np.ndarray:
    if float(d_from @ d_to) > -1.0 + 1e-9:
        return line_rotation(d_from, d_to)
    # opposite directions: half a turn about an axis square to them (every such axis is minimal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d_from[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    k = np.cross(d_from, helper)
    k /= np.linalg.norm(k)
    return 2.0 * np.outer(k, k) - np.eye(3)


def _distances(surface: RepairedSurface, points: np.ndarray) -> np.ndarray:
    """Exact distance of each point to the triangle surface."""
    import trimesh

    triangles = surface.vertices[surface.faces]
    out = []
    for p in points:
        closest = trimesh.triangles.closest_point(triangles, np.broadcast_to(p, (len(triangles), 3)))
        out.append(float(np.linalg.norm(closest - p, axis=1).min()))
    return np.array(out)
