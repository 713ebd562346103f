"""``persival mesh``: a model's muscles meshed one by one, written for inspection with a report.

For each chosen muscle: ``<muscle>.vtu`` (tet10; cell data fibre, region, laplace, position,
muscle_fraction; point data laplace), ``<muscle>_surface.vtp`` (the mesh's boundary; point data
laplace, attachment: 0 none / 1 origin / 2 insertion, source_vertex: the index of the surface
file's vertex at that node, -1 for none), ``<muscle>.png`` (the fibre field,
persival.model.anatomy.fibre_picture) and one ``mesh_report.json`` for all of them: vertices in, nodes
out, each repair with its count, volume, area, tetrahedra, minimum quality, scale, meshing time,
the cells whose fibre is the centre line's (no Laplace gradient there) and the line of action's
moment arm. A built-in muscle (no surface) is meshed as the arm meshes
it (a swept solid with centre-line fibres) and reported the same way, without the surface's rows.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from persival.model.anatomy.muscle_schema import Muscle
from persival.model.anatomy.muscle_sweep import muscle_profile
from persival.model.anatomy.surface_muscle import surface_muscle
from persival.model.arm.body import ArmBody
from persival.model.fe.mesh import Tet10Mesh

__all__ = ["REGIONS", "mesh_muscles", "tissue_regions"]

REGIONS = {0: "tendon", 1: "muscle-tendon blend", 2: "belly"}


def tissue_regions(muscle: Muscle, position: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Muscle fraction gamma_M and region code (REGIONS) of cells at ``position`` (0..1) along the
    muscle's ``length`` mm: the built-in tissue layout (docs/theory.md 1.5 mixture, tendon and transition lengths)."""
    _, gamma = muscle_profile(muscle, np.asarray(position, dtype=float), length)
    region = np.where(gamma <= 0.0, 0, np.where(gamma >= 1.0, 2, 1))
    return gamma, region


def mesh_muscles(body: ArmBody, muscles: tuple[str, ...], out: Path, progress=None) -> dict:
    """Mesh ``muscles`` of a model's frame (ArmBody.frame) and write their files into ``out``;
    returns the report (also written as mesh_report.json). Every muscle is meshed before anything
    is written: one that is refused (a MeshError) leaves no files of the others behind either."""
    out = Path(out)
    report = {"model": body.spec.name, "model_hash": body.model_hash, "profile": body.profile, "muscles": {}}
    writers = []
    for name in muscles:
        if progress is not None:
            progress(name)
        muscle = body.spec.muscle(name)
        report["muscles"][name], write = _mesh_one(body, muscle)
        writers.append(write)
    out.mkdir(parents=True, exist_ok=True)
    for write in writers:
        write(out)
    (out / "mesh_report.json").write_text(json.dumps(report, indent=2))
    return report


def _mesh_one(body: ArmBody, muscle: Muscle):
    """The muscle's report entry and the function that writes its files into a folder."""
    size = body.spec.mesh_size(body.profile, muscle.name)
    t0 = time.perf_counter()
    entry: dict = {}
    source = None
    if muscle.name in body.surfaces:
        own = surface_muscle(muscle, body.surfaces[muscle.name], size)
        mesh, length, phi_nodes, line = own.mesh, own.fibres.length, own.fibres.phi_nodes, own.fibres.centre_line
        placed, volume = own.placed, own.volume
        source = _node_sources(mesh, placed.surface.vertices, placed.surface.source_vertex)
        entry.update(surface=muscle.surface, surface_units=muscle.surface_units, vertices_in=placed.vertices_in,
                     triangles_in=placed.triangles_in, repairs=placed.surface.repairs,
                     vertices_repaired=len(placed.surface.vertices), triangles_repaired=len(placed.surface.faces),
                     surface_kept=volume.surface_kept, vertices_kept_as_nodes=volume.vertices_kept,
                     area_mm2=placed.surface.area, surface_volume_mm3=placed.surface.volume,
                     scale=placed.scale, end_point_distance_mm=list(placed.end_distance_mm),
                     length_between_points_mm=float(np.linalg.norm(placed.insertion - placed.origin)),
                     origin_insertion_mm=float(np.linalg.norm(placed.target_insertion - placed.origin)),
                     min_quality=volume.min_quality, straightened_elements=volume.straightened,
                     fibre_fallback_cells=len(own.fibres.fallback))
    else:
        line = body.centre_line(muscle)
        length = body.centre_line_length(muscle)
        mesh = body.sweep(muscle).mesh(size)
        phi_nodes = None
        entry.update(surface=None, area_mm2=_boundary_area(mesh))
    seconds = time.perf_counter() - t0
    gamma, region = tissue_regions(muscle, mesh.cell_data["arclength"], length)
    entry.update(
        nodes_out=mesh.n_nodes, surface_nodes_out=len(mesh.surface_nodes()), tetrahedra=mesh.n_cells,
        volume_mm3=mesh.volume(), mesh_size_mm=size, meshing_s=seconds, fibre_length_mm=length,
        attachment_nodes={"origin": len(mesh.node_sets["origin"]), "insertion": len(mesh.node_sets["insertion"])},
        region_volume_mm3={REGIONS[k]: float(_cell_volumes(mesh)[region == k].sum()) for k in REGIONS},
        moment_arm_mm={f"{theta:g} deg": body.line_moment_arm(muscle, theta) for theta in (muscle.mesh_angle_deg, 90.0)},
    )

    def write(out: Path) -> None:
        from persival.model.anatomy.fibre_picture import draw_fibres

        _write_vtu(mesh, gamma, region, phi_nodes, out / f"{muscle.name}.vtu")
        _write_surface(mesh, phi_nodes, source, out / f"{muscle.name}_surface.vtp")
        draw_fibres(mesh, line, muscle.name, out / f"{muscle.name}.png", body.axis)

    return entry, write


def _cell_volumes(mesh: Tet10Mesh) -> np.ndarray:
    X = mesh.points[mesh.cells[:, :4]]
    return np.abs(np.einsum("mi,mi->m", X[:, 1] - X[:, 0], np.cross(X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]))) / 6.0


def _boundary_area(mesh: Tet10Mesh) -> float:
    tri = mesh.points[mesh.boundary_faces()[:, :3]]
    return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


def _node_sources(mesh: Tet10Mesh, vertices: np.ndarray, source: np.ndarray) -> np.ndarray:
    """For each node the index of the surface file's vertex at exactly its place, else -1."""
    where = {p.tobytes(): int(s) for p, s in zip(np.ascontiguousarray(vertices), source)}
    return np.array([where.get(p.tobytes(), -1) for p in np.ascontiguousarray(mesh.points)], dtype=np.int64)


def _write_vtu(mesh: Tet10Mesh, gamma, region, phi_nodes, path: Path) -> None:
    import meshio

    cell_data = {"fibre": [mesh.cell_data["fibre"]], "region": [region.astype(np.int32)],
                 "position": [mesh.cell_data["arclength"]], "muscle_fraction": [gamma]}
    if "laplace" in mesh.cell_data:
        cell_data["laplace"] = [mesh.cell_data["laplace"]]
    point_data = {} if phi_nodes is None else {"laplace": phi_nodes}
    meshio.Mesh(mesh.points, [("tetra10", mesh.cells)], point_data=point_data, cell_data=cell_data).write(path)


def _write_surface(mesh: Tet10Mesh, phi_nodes, source, path: Path) -> None:
    import pyvista

    triangles = mesh.boundary_faces()[:, :3]
    nodes = np.unique(triangles)
    local = np.full(mesh.n_nodes, -1, dtype=np.int64)
    local[nodes] = np.arange(len(nodes))
    faces = np.column_stack([np.full(len(triangles), 3), local[triangles]]).ravel()
    surface = pyvista.PolyData(mesh.points[nodes], faces)
    attachment = np.zeros(mesh.n_nodes, dtype=np.int32)
    attachment[mesh.node_sets["origin"]] = 1
    attachment[mesh.node_sets["insertion"]] = 2
    surface.point_data["attachment"] = attachment[nodes]
    if phi_nodes is not None:
        surface.point_data["laplace"] = phi_nodes[nodes]
    if source is not None:
        surface.point_data["source_vertex"] = source[nodes]
    surface.save(str(path))
