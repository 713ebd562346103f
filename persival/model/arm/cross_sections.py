"""The muscles' outlines across the upper arm, checked as polygons before meshing.

At levels along the humerus (fractions of its length from its distal end) every muscle's swept
solid, as the model file lays it out (its centre line in its mesh pose and its radius profile,
:mod:`persival.model.arm.body`), crosses the plane normal to the humerus in an ellipse: locally
a cylinder of the station's radius about the centre line's tangent, cut obliquely. Two outlines
overlap where a vertex of one lies inside the other; a muscle and the humerus where a vertex of
the muscle's outline lies inside the bone's surface (:mod:`persival.model.anatomy.bone_shapes`), or a
vertex of the bone's outline inside the muscle's. Reported per
level and pair: the vertices inside and the deepest of them (its distance to the other
outline, or to the bone's surface), as the 3D check of solved states does
(:mod:`persival.model.anatomy.overlap`). A model file that draws the upper arm's skin (its outline
at heights, interpolated between them) has every muscle vertex outside it reported too: a layout
that leaves the arm.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from persival.model.anatomy.bone_shapes import ElbowFrame, bone_shapes
from persival.model.anatomy.overlap import Body, signed_distance
from persival.model.anatomy.schema_base import ModelFileError

if TYPE_CHECKING:  # a type only: the kinematics check outlines with this module
    from persival.model.arm.kinematics import ArmKinematics

__all__ = ["LEVELS", "OutlineOverlapError", "check_outlines", "outline_overlaps", "outlines_at", "skin_at", "where"]

LEVELS = (0.1, 0.3, 0.5, 0.7, 0.9)
VERTICES = 72


class OutlineOverlapError(ModelFileError):
    """A model whose muscles' outlines overlap each other or a bone, or leave the skin, at some level."""


def outlines_at(kinematics: ArmKinematics, z: float) -> dict[str, list[np.ndarray]]:
    """Per muscle, its outlines (each (VERTICES, 3), elbow frame) where its solid crosses the plane
    at height z of the elbow frame: one per crossing of its centre line. The section there (a
    circle, or an outlined muscle's ellipse: persival.model.anatomy.muscle_sweep) is carried along the
    centre line's tangent into the plane: the oblique cut of the local cylinder, at most three
    semi-axes long."""
    frame = ElbowFrame.of(kinematics.spec)
    phi = np.linspace(0.0, 2.0 * np.pi, VERTICES, endpoint=False)
    out = {}
    for muscle in kinematics.spec.ordered_muscles():
        sweep = kinematics.sweep(muscle)
        line = frame.local(sweep.line)
        rings = []
        for i in np.flatnonzero((line[:-1, 2] - z) * (line[1:, 2] - z) <= 0.0):
            a, b = line[i], line[i + 1]
            if a[2] == b[2]:
                continue
            t = (z - a[2]) / (b[2] - a[2])
            centre = a + t * (b - a)
            semi = sweep.semi_axes[i] + t * (sweep.semi_axes[i + 1] - sweep.semi_axes[i])
            tangent = (b - a) / np.linalg.norm(b - a)
            major = _across(tangent, None if sweep.circular else sweep.major[i] @ frame.axes.T)
            minor = np.cross(tangent, major)
            ring = centre + semi[0] * np.cos(phi)[:, None] * major + semi[1] * np.sin(phi)[:, None] * minor
            rise = np.copysign(max(abs(tangent[2]), 1.0 / 3.0), tangent[2])
            ring = ring + ((z - ring[:, 2]) / rise)[:, None] * tangent
            ring[:, 2] = z
            rings.append(ring)
        out[muscle.name] = rings
    return out


def _across(tangent: np.ndarray, major: np.ndarray | None) -> np.ndarray:
    """A unit vector across the tangent: the ellipse's larger semi-axis, or for a circle the
    horizontal one (any will do)."""
    if major is None:
        major = np.cross([0.0, 0.0, 1.0], tangent)
        if np.linalg.norm(major) < 1e-9:
            major = np.array([1.0, 0.0, 0.0])
    major = major - (major @ tangent) * tangent
    return major / np.linalg.norm(major)


def _inside_polygon(points: np.ndarray, ring: np.ndarray) -> np.ndarray:
    from matplotlib.path import Path

    return Path(ring[:, :2]).contains_points(points[:, :2])


def _distance_to_ring(points: np.ndarray, ring: np.ndarray) -> np.ndarray:
    a, b = ring[:, :2], np.roll(ring[:, :2], -1, axis=0)
    d = b - a
    t = np.clip(np.einsum("nki,ki->nk", points[:, None, :2] - a[None], d) / np.einsum("ki,ki->k", d, d), 0.0, 1.0)
    return np.min(np.linalg.norm(points[:, None, :2] - (a[None] + t[..., None] * d[None]), axis=2), axis=1)


def outline_overlaps(kinematics: ArmKinematics, levels=LEVELS) -> list[dict]:
    """Overlaps at each level (fraction of the humerus from its distal end): muscle in muscle
    (both ways) and muscle in an upper-arm bone; each with the vertices inside and the deepest."""
    frame = ElbowFrame.of(kinematics.spec)
    shapes = bone_shapes(kinematics.spec)
    bones = [Body(b.name, *shapes[b.name]) for b in kinematics.spec.bones if b.segment == "upper_arm"]
    humerus = next((frame.local(shapes[b.name][0]) for b in kinematics.spec.bones if b.drawn_shape().kind == "humerus"),
                   None)
    z_lo, z_hi = (humerus[:, 2].min(), humerus[:, 2].max()) if humerus is not None else (0.0, 300.0)
    rows = []
    for level in levels:
        z = z_lo + level * (z_hi - z_lo)
        outlines = outlines_at(kinematics, z)
        skin = skin_at(kinematics.spec, z)
        for a, rings_a in outlines.items():
            for ring_a in rings_a:
                for b, rings_b in outlines.items():
                    for ring_b in rings_b if b != a else ():
                        inside = _inside_polygon(ring_a, ring_b)
                        if inside.any():
                            depth = _distance_to_ring(ring_a[inside], ring_b)
                            rows.append(_row(level, z, a, b, inside, depth))
                for bone in bones:
                    depth = -signed_distance(frame.world(ring_a), bone)
                    if (depth > 0).any():
                        rows.append(_row(level, z, a, bone.name, depth > 0, depth[depth > 0]))
                    section = _bone_section(bone, frame, z)  # a bone inside a muscle's outline
                    inside = _inside_polygon(section, ring_a) if len(section) else np.zeros(0, dtype=bool)
                    if inside.any():
                        rows.append(_row(level, z, bone.name, a, inside, _distance_to_ring(section[inside], ring_a)))
                if skin is not None:
                    outside = ~_inside_polygon(ring_a, skin)
                    if outside.any():
                        rows.append(_row(level, z, a, "skin", outside, _distance_to_ring(ring_a[outside], skin),
                                         relation="outside"))
    return rows


def skin_at(spec, z: float) -> np.ndarray | None:
    """The upper arm's skin at height z (VERTICES, 3): the model file's outlines interpolated
    linearly in z (centre, semi-axes, direction), the nearest one beyond them; None if it has none."""
    if not spec.skin:
        return None
    skin = sorted(spec.skin, key=lambda o: o.z)
    heights = [o.z for o in skin]
    table = np.array([[*o.centre, *o.semi_axes, o.angle_deg] for o in skin])
    cx, cy, a, b, angle = (np.interp(z, heights, column) for column in table.T)
    centre, angle = np.array([cx, cy]), np.radians(angle)
    phi = np.linspace(0.0, 2.0 * np.pi, VERTICES, endpoint=False)
    major, minor = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    ring = centre + a * np.cos(phi)[:, None] * major + b * np.sin(phi)[:, None] * minor
    return np.column_stack([ring, np.full(VERTICES, z)])


def _bone_section(bone: Body, frame: ElbowFrame, z: float) -> np.ndarray:
    """The vertices of a bone's outline at height z (elbow frame)."""
    cut = bone.surface.slice(normal=frame.axes[2], origin=frame.world(np.array([0.0, 0.0, z])))
    return frame.local(np.asarray(cut.points, dtype=float)) if cut.n_points else np.zeros((0, 3))


def _row(level: float, z: float, a: str, b: str, inside: np.ndarray, depth: np.ndarray, relation: str = "in") -> dict:
    """One finding: ``relation`` "in" (a's vertices inside b) or "outside" (a's vertices outside
    b, the skin), with how many and the deepest."""
    return {"level": level, "z_mm": round(float(z), 1), "outline": a, "relation": relation, "inside": b,
            "vertices": int(inside.sum()), "of": len(inside), "deepest_mm": round(float(depth.max()), 2)}


def where(row: dict) -> str:
    """Where a finding's outline lies: "in <body>" or "outside the skin"."""
    return f"{'in' if row['relation'] == 'in' else 'outside the'} {row['inside']}"


def check_outlines(kinematics: ArmKinematics, levels=LEVELS) -> None:
    """Refuse a model whose outlines overlap or leave the skin: one message naming the muscles and
    the levels."""
    rows = outline_overlaps(kinematics, levels)
    if rows:
        worst = sorted(rows, key=lambda r: -r["deepest_mm"])
        listed = "; ".join(f"{r['outline']} {where(r)} at {100 * r['level']:.0f} % of the humerus (z = {r['z_mm']:g} "
                           f"mm, {r['deepest_mm']:.1f} mm {'deep' if r['relation'] == 'in' else 'out'})" for r in worst)
        what = "overlap" if all(r["relation"] == "in" for r in rows) else "overlap or leave the skin"
        raise OutlineOverlapError(f"{kinematics.spec.name}: the muscles' outlines {what}: {listed}")
