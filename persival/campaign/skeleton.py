"""The rigid bones of a simulator's model, for display (the export's ``skeleton``, docs/deployment.md).

A campaign store keeps muscle surfaces only; a viewer also wants the humerus fixed and the
forearm bones turning about the elbow hinge. This module describes them per simulator kind:
the FE arm's from its model file (the bones with their shapes, persival.model.anatomy.bone_shapes, the
same surfaces the FE states are written and drawn with), the analytic stand-in's from its fixed
geometry (capped tubes), none for an external code. Bones are given at elbow angle 0; a forearm
point p sits at angle theta at ``centre + R(axis, theta)(p - centre)`` (right-handed).
"""

from __future__ import annotations

import numpy as np

__all__ = ["skeleton_for"]


def _bone(name: str, segment: str, points: np.ndarray, triangles: np.ndarray) -> dict:
    # 0.01 mm is far below what a viewer shows and keeps the metadata small
    return {"name": name, "segment": segment, "points": np.round(points, 2).tolist(), "triangles": triangles.tolist()}


def _tube(name: str, segment: str, start, end, radius: float) -> dict:
    from persival.model.anatomy.bone_shapes import tube_surface

    return _bone(name, segment, *tube_surface(np.asarray(start, float), np.asarray(end, float), radius))


def _arm_skeleton(model_file: str | None) -> dict:
    from persival.model.anatomy.bone_shapes import bone_shapes
    from persival.model.arm.model_file import load_model_file

    spec, _ = load_model_file(model_file)
    shapes = bone_shapes(spec)  # forearm bones at theta = 0, as the skeleton's format wants them
    return {"hinge": {"centre": list(spec.joint.centre), "axis": list(np.asarray(spec.joint.axis) /
                                                                      np.linalg.norm(spec.joint.axis))},
            "bones": [_bone(b.name, b.segment, *shapes[b.name]) for b in spec.bones]}


def _analytic_skeleton() -> dict:
    from persival.campaign.analytic import _ELBOW_Z

    # the analytic forearm turns x towards +z about y: a right-handed rotation about -y
    return {"hinge": {"centre": [0.0, 0.0, _ELBOW_Z], "axis": [0.0, -1.0, 0.0]},
            "bones": [_tube("humerus", "upper_arm", (0, 0, -10), (0, 0, _ELBOW_Z + 8), 9.0),
                      _tube("forearm", "forearm", (0, 0, _ELBOW_Z - 8), (0, 0, _ELBOW_Z - 250), 8.0)]}


def skeleton_for(simulator: str, options: dict | None = None) -> dict | None:
    """The display skeleton of a simulator kind (None where the kind has no bones to show)."""
    if simulator == "arm":
        return _arm_skeleton((options or {}).get("model_file"))
    if simulator == "analytic":
        return _analytic_skeleton()
    return None
