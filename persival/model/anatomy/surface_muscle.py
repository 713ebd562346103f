"""One muscle from its own surface: the placed surface meshed, its attachment faces and its fibres.

The steps (docs/own_anatomy.md): the repaired, placed surface
(persival.model.anatomy.surface_import) is meshed with tet10 (persival.model.anatomy.surface_mesh); the two
attachment faces are the patches of its boundary around the placed origin and insertion points;
they are the end regions of the Laplace problem that gives the fibres and the position along the
muscle (persival.model.anatomy.laplace_fibres), and they are tied exactly as the built-in muscles' end
caps are (origin face to the humerus, insertion face to the forearm: persival.model.arm.muscle_unit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from persival.model.anatomy.laplace_fibres import LaplaceFibres, laplace_fibres
from persival.model.anatomy.muscle_schema import Muscle
from persival.model.anatomy.surface_import import PlacedSurface, place_surface
from persival.model.anatomy.surface_mesh import VolumeMesh, volume_mesh
from persival.model.fe.mesh import MeshError, Tet10Mesh

__all__ = ["SurfaceMuscle", "attachment_face", "check_fibres", "place_muscle_surface", "surface_muscle", "MIN_FACE_CORNERS"]

# An attachment face needs a patch, not a point (a clamped point leaves the body free to spin
# about it): at least a vertex and its ring of neighbours on a coarse surface.
MIN_FACE_CORNERS = 7
NAMED_CELLS = 5  # cells a refusal lists by index


@dataclass
class SurfaceMuscle:
    """The mesh (node sets ``origin``, ``insertion``; cell data ``fibre``, ``arclength`` (position
    0..1 along the muscle), ``laplace`` (phi)) and what made it."""

    mesh: Tet10Mesh
    placed: PlacedSurface
    volume: VolumeMesh
    fibres: LaplaceFibres


def place_muscle_surface(muscle: Muscle, origin: np.ndarray, insertion: np.ndarray) -> PlacedSurface:
    """Read, repair and place the muscle's surface; ``insertion``: its insertion in the mesh pose."""
    return place_surface(muscle.surface, muscle.surface_units, muscle.origin_point, muscle.insertion_point,
                         muscle.scale_to_fit, origin, insertion, f"muscle {muscle.name!r}")


def surface_muscle(muscle: Muscle, placed: PlacedSurface, mesh_size: float) -> SurfaceMuscle:
    """Mesh a placed surface and give it attachment faces and Laplace fibres (module docstring)."""
    volume = volume_mesh(placed.surface, mesh_size)
    mesh = volume.mesh
    origin_nodes = attachment_face(mesh, placed.origin, muscle.tendon_radius[0])
    insertion_nodes = attachment_face(mesh, placed.insertion, muscle.tendon_radius[1])
    if np.intersect1d(origin_nodes, insertion_nodes).size:
        raise MeshError(f"muscle {muscle.name!r}: its origin and insertion faces touch; the surface is too short "
                        "or too coarse for its tendon radii")
    fibres = laplace_fibres(mesh, origin_nodes, insertion_nodes, ends=(placed.origin, placed.insertion))
    check_fibres(fibres.fibre, fibres.position, f"muscle {muscle.name!r}")
    mesh.node_sets = {"origin": origin_nodes, "insertion": insertion_nodes}
    mesh.cell_data = {"fibre": fibres.fibre, "arclength": fibres.position, "laplace": fibres.phi}
    return SurfaceMuscle(mesh, placed, volume, fibres)


def check_fibres(fibre: np.ndarray, position: np.ndarray, name: str) -> None:
    """Refuse (MeshError) a muscle whose cells lack a finite unit fibre or a finite position,
    naming the first cells and the count: the solver stops on them later with no word of where,
    and ``persival mesh`` would write them as NaN. The Laplace fibres give every cell one
    (persival.model.anatomy.laplace_fibres: its fallbacks), so this guards against what nothing foresaw."""
    fibre, position = np.asarray(fibre, dtype=float), np.asarray(position, dtype=float)
    unit = np.abs(np.linalg.norm(fibre, axis=1) - 1.0) < 1e-6  # NaN compares False: not unit
    bad = np.flatnonzero(~(unit & np.isfinite(position)))
    if len(bad):
        cells = ", ".join(str(c) for c in bad[:NAMED_CELLS]) + (", ..." if len(bad) > NAMED_CELLS else "")
        raise MeshError(f"{name}: no finite fibre direction or position for {len(bad)} of {len(fibre)} cells "
                        f"(cells {cells}); check its origin_point, insertion_point and tendon_radius, or simplify the "
                        "surface where those cells lie")


def attachment_face(mesh: Tet10Mesh, point: np.ndarray, radius: float) -> np.ndarray:
    """Nodes (mid-side included) of the boundary triangles whose corners all lie within ``radius``
    of ``point``, the radius grown to the ``MIN_FACE_CORNERS``-th nearest boundary corner where
    the surface is coarser than that."""
    faces = mesh.boundary_faces()
    corners = np.unique(faces[:, :3])
    distance = np.linalg.norm(mesh.points[corners] - np.asarray(point, dtype=float), axis=1)
    reach = max(float(radius), float(np.sort(distance)[min(MIN_FACE_CORNERS, len(distance)) - 1]))
    near = np.zeros(mesh.n_nodes, dtype=bool)
    near[corners[distance <= reach * (1 + 1e-9)]] = True
    patch = faces[near[faces[:, :3]].all(axis=1)]
    if len(patch) == 0:
        raise MeshError(f"no boundary triangle within {reach:.1f} mm of the end point {np.round(point, 1).tolist()}")
    return np.unique(patch)
