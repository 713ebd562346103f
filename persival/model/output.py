"""Writing solved arm states: state.json plus VTU files of every muscle and bone (ParaView).

A state directory is written into a temporary sibling and renamed into place, so a failed
or interrupted write leaves nothing half-done.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from persival.model.arm import ArmModel, ArmState
from persival.vocabulary import MUSCLES


def tube_surface(start: np.ndarray, end: np.ndarray, radius: float, segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A capped cylinder as triangles: the display shape of a rigid bone."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    axis = end - start
    length = np.linalg.norm(axis)
    axis /= length
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = radius * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    points = np.vstack([start + ring, end + ring, start, end])
    i = np.arange(segments)
    j = (i + 1) % segments
    sides = np.vstack([np.column_stack([i, j, segments + i]), np.column_stack([j, segments + j, segments + i])])
    caps = np.vstack([np.column_stack([np.full(segments, 2 * segments), j, i]),
                      np.column_stack([np.full(segments, 2 * segments + 1), segments + i, segments + j])])
    return points, np.vstack([sides, caps])


def bone_surfaces(arm: ArmModel, theta_deg: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Triangulated bones at elbow angle theta (forearm bones rotated about the hinge)."""
    out = {}
    for bone in arm.spec.bones:
        points, triangles = tube_surface(np.array(bone.start), np.array(bone.end), bone.radius)
        if bone.segment == "forearm":
            points = arm.forearm_point(points, theta_deg)
        out[bone.name] = (points, triangles)
    return out


def muscle_submesh(arm: ArmModel, name: str):
    """Cells of one muscle renumbered to its own nodes (for per-muscle files)."""
    nodes = arm.muscle_nodes[name]
    cells = arm.mesh.cells[arm.muscle_cells[name]] - nodes[0]
    return nodes, cells


def write_state(arm: ArmModel, state: ArmState, out_dir: str | Path, extra: dict | None = None) -> Path:
    """Write ``state.json`` and VTU files of the five muscles and the bones into ``out_dir``."""
    import meshio

    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}-", dir=out_dir.parent))
    try:
        summary = {"model": arm.spec.name, "model_hash": arm.model_hash, "profile": arm.profile, **state.summary()}
        if extra:
            summary.update(extra)
        (tmp / "state.json").write_text(json.dumps(summary, indent=2))
        u = state.displacement
        for name in MUSCLES:
            nodes, cells = muscle_submesh(arm, name)
            cell_ids = arm.muscle_cells[name]
            meshio.Mesh(
                arm.mesh.points[nodes] + u[nodes],
                [("tetra10", cells)],
                point_data={"displacement": u[nodes], "displacement_magnitude": np.linalg.norm(u[nodes], axis=1)},
                cell_data={"muscle_fraction": [arm.mesh.cell_data["muscle_fraction"][cell_ids]]},
            ).write(tmp / f"{name}.vtu")
        for name, (points, triangles) in bone_surfaces(arm, state.elbow_angle_deg).items():
            meshio.Mesh(points, [("triangle", triangles)]).write(tmp / f"bone_{name}.vtu")
        if out_dir.exists():
            shutil.rmtree(out_dir)
        os.replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir
