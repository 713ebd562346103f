"""Writing solved arm states: state.json plus VTU files of every muscle and bone (ParaView).

The bones are written with their shapes (persival.model.anatomy.bone_shapes), whatever the muscles touch
(their capsules, or these shapes with ``[contact] bone_surfaces``).

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

from persival.model.anatomy.bone_shapes import bone_shapes
from persival.model.arm.arm_model import ArmModel, ArmState
from persival.vocabulary import MUSCLES


def bone_surfaces(arm, theta_deg: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Triangulated bones with their shapes (persival.model.anatomy.bone_shapes) at elbow angle theta:
    forearm bones turned about the hinge. ``arm``: anything with the model's ``spec`` and
    ``forearm_point`` (an ArmModel, or ArmKinematics without a mesh)."""
    out = {}
    for name, (points, triangles) in bone_shapes(arm.spec).items():
        if arm.spec.bone(name).segment == "forearm":
            points = arm.forearm_point(points, theta_deg)
        out[name] = (points, triangles)
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
