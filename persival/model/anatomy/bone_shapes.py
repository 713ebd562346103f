"""Bones with their shapes: the humerus, ulna and radius of a model file as closed triangle surfaces.

Each bone is a solid of :mod:`persival.model.anatomy.implicit_solids` built from a few parameters of
the model file (``[bones.shape]``, defaults from the anatomy literature cited in
docs/design/arm_model_record.md) and placed on the model's own bone lines and elbow hinge:

* humerus: its shaft on the bone's line, widening at its distal end to the medial and lateral
  epicondyles; the trochlea and the capitulum one body of revolution about the hinge axis (the
  capitulum a sphere centred on it, above the radius); the head at the top;
* ulna: its trochlear notch a ring around the hinge axis that follows the trochlea's profile
  at a cartilage clearance, from the olecranon's tip (posterior) to the coronoid (anterior); the
  shaft on the bone's line;
* radius: its head a disc on the bone's line whose dish fits the capitulum at the clearance; neck,
  tuberosity, shaft and the distal end.

Because the articular surfaces are bodies of revolution about the hinge, the forearm bones turn
about them without touching. The fossae of the humerus (olecranon, coronoid, radial) are cut
as the space the forearm bones sweep over the joint's range: where they go, the humerus gives
way. Coordinates: the elbow frame, origin at the hinge centre, x along the hinge axis
(lateral), z along the humerus (proximal), y = z x x (anterior); forearm bones at theta = 0.

One module on purpose (a geometric kernel over 300 lines): the three bones are implicit solids
cut by one another's sweep over the joint's range, so their shapes are built together.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from functools import lru_cache, partial

import numpy as np

from persival.cache_dir import cache_root
from persival.model.anatomy.implicit_solids import (
    arc_ring,
    ellipsoid,
    revolution,
    round_cone,
    smooth_difference,
    smooth_union,
    sphere,
    triangulate,
)
from persival.model.fe.rotations import rotation_about

__all__ = ["ElbowFrame", "articular_layout", "bone_shapes", "cached_bone_arrays", "tube_surface"]

SHAPES_VERSION = 1  # bump when the shapes below change: the cached surfaces are rebuilt
SPACING_MM = 1.0  # marching-cubes grid
SWEEP_STEP_DEG = 10.0
REACH_MM = 32.0  # the joint ends of the forearm bones: within this of the hinge axis
TRIANGLES = {"humerus": 9000, "ulna": 6000, "radius": 6000}


@dataclass(frozen=True)
class ElbowFrame:
    """The elbow frame (module docstring) of a model: origin, and rows x, y, z in arm coordinates."""

    origin: np.ndarray
    axes: np.ndarray  # (3, 3)

    @classmethod
    def of(cls, spec) -> ElbowFrame:
        x = np.asarray(spec.joint.axis, dtype=float)
        x /= np.linalg.norm(x)
        humerus = next((b for b in spec.bones if b.segment == "upper_arm"), None)
        up = np.subtract(humerus.end, humerus.start) if humerus is not None else np.array([0.0, 0.0, 1.0])
        z = up - (up @ x) * x
        z /= np.linalg.norm(z)
        return cls(np.asarray(spec.joint.centre, dtype=float), np.array([x, np.cross(z, x), z]))

    def local(self, p) -> np.ndarray:
        return (np.asarray(p, dtype=float) - self.origin) @ self.axes.T

    def world(self, q: np.ndarray) -> np.ndarray:
        return self.origin + q @ self.axes


@dataclass(frozen=True)
class ArticularLayout:
    """The distal humerus along the hinge axis (local x, mm): trochlea and capitulum profile."""

    xs: np.ndarray  # axial stations
    radii: np.ndarray  # radius of the articular body of revolution there
    trochlea: tuple[float, float]  # medial and lateral end
    capitulum_centre: float
    capitulum_radius: float
    lateral_edge: float  # the capitulum's lateral end


def articular_layout(humerus, capitulum_x: float) -> ArticularLayout:
    """Trochlea (medial lip larger than the lateral, a groove between) and capitulum (a sphere on
    the axis above the radius, at ``capitulum_x``), with the capitulotrochlear groove between them."""
    rc, rt, w = humerus.capitulum_radius, humerus.trochlea_radius, humerus.trochlea_width
    groove = capitulum_x - 0.75 * rc
    lateral_lip = groove - 2.0
    medial_lip = lateral_lip - w
    trochlea_x = [medial_lip - 1.5, medial_lip, lateral_lip - 0.45 * w, lateral_lip, groove]
    trochlea_r = [rt + 1.5, rt + 3.5, rt, rt + 1.5, rt - 1.0]
    cap_x = np.linspace(capitulum_x - 0.55 * rc, capitulum_x + 0.75 * rc, 12)
    cap_r = np.sqrt(rc**2 - (cap_x - capitulum_x) ** 2)
    return ArticularLayout(np.concatenate([trochlea_x, cap_x]), np.concatenate([trochlea_r, cap_r]),
                           (medial_lip - 1.5, groove), capitulum_x, rc, float(cap_x[-1]))


def tube_surface(start: np.ndarray, end: np.ndarray, radius: float, segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A capped cylinder as triangles: a bone without an anatomical shape."""
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


def _on_line(start: np.ndarray, end: np.ndarray, z: float) -> np.ndarray:
    """The point of the line start-end at local height z."""
    t = (z - start[2]) / (end[2] - start[2])
    return start + t * (end - start)


def _humerus_base(p, shape, line, layout: ArticularLayout, shaft_radius: float):
    """The humerus before its fossae are cut (module docstring)."""
    start, end = line
    bottom = -float(layout.radii.max())
    top = bottom + shape.length
    lateral = layout.lateral_edge + 5.0
    medial = lateral - shape.epicondylar_width
    joint = revolution(p, layout.xs, layout.radii)
    # the epicondyles' tips at medial and lateral (the smooth unions add about half a millimetre)
    epicondyles = np.minimum(ellipsoid(p, (medial + 7.0, -2.0, 10.0), (6.5, 7.0, 10.0)),
                             ellipsoid(p, (lateral - 5.0, -2.0, 8.0), (4.5, 6.0, 8.0)))
    flare = ellipsoid(p, (0.5 * (medial + lateral) + 2.0, -1.0, 16.0), (0.5 * shape.epicondylar_width - 7.0, 11.0, 18.0))
    shaft_low, shaft_high = _on_line(start, end, 30.0), _on_line(start, end, top - 45.0)
    ridges = np.minimum(round_cone(p, (medial + 7.0, -2.0, 10.0), shaft_low + [-6.0, 0.0, 45.0], 5.0, 0.7 * shaft_radius),
                        round_cone(p, (lateral - 5.0, -2.0, 8.0), shaft_low + [6.0, 0.0, 60.0], 4.0, 0.6 * shaft_radius))
    shaft = round_cone(p, shaft_low, _on_line(start, end, 200.0), shaft_radius, shaft_radius)
    shaft = np.minimum(shaft, round_cone(p, _on_line(start, end, 200.0), shaft_high, shaft_radius, 1.3 * shaft_radius))
    head_r = 0.5 * shape.head_diameter
    proximal = np.minimum(sphere(p, shaft_high + [-7.0, 0.0, top - head_r - shaft_high[2]], head_r),
                          ellipsoid(p, shaft_high + [12.0, 3.0, 18.0], (9.0, 10.0, 14.0)))
    distal = smooth_union(smooth_union(flare, epicondyles, 4.0), ridges, 6.0)
    body = smooth_union(smooth_union(distal, shaft, 12.0), proximal, 10.0)
    return smooth_union(body, joint, 3.0), (medial, lateral, bottom, top)


def _ulna(p, *, shape, line, layout: ArticularLayout, radius_head):
    """The ulna at theta = 0 (module docstring)."""
    start, end = line
    clearance = shape.joint_clearance

    def notch(x):
        return np.interp(x, layout.xs, layout.radii) + clearance

    x0, x1 = layout.trochlea[0], layout.trochlea[1] - 1.0
    middle = 0.5 * (x0 + x1)
    ring = arc_ring(p, (x0, x1), notch, 7.0, -shape.olecranon_angle_deg, shape.coronoid_angle_deg)
    rho = float(notch(middle)) + 7.0
    olecranon_phi = np.radians(-shape.olecranon_angle_deg + 40.0)
    olecranon = ellipsoid(p, (middle, rho * np.sin(olecranon_phi), -rho * np.cos(olecranon_phi)), (0.5 * (x1 - x0), 7.5, 10.0))
    coronoid = ellipsoid(p, (middle, 3.0, 1.0 - rho), (0.5 * (x1 - x0) - 1.0, 5.0, 5.0))
    length = start[2] - end[2]
    shaft_top = _on_line(start, end, -rho)
    upper = round_cone(p, (middle, shaft_top[1], -rho), _on_line(start, end, -rho - 0.25 * length), 9.0, 7.0)
    lower = round_cone(p, _on_line(start, end, -rho - 0.25 * length), end, 7.0, 5.0)
    head = sphere(p, end + [0.0, 0.0, 4.0], 8.0)
    body = smooth_union(smooth_union(smooth_union(ring, olecranon, 4.0), coronoid, 4.0), upper, 8.0)
    body = smooth_union(smooth_union(body, lower, 6.0), head, 6.0)
    cavity = revolution(p, np.concatenate([[layout.xs[0] - 3.0], layout.xs, [layout.xs[-1] + 3.0]]),
                        np.concatenate([[layout.radii[0]], layout.radii, [layout.radii[-1]]]) + clearance)
    body = smooth_difference(body, cavity, 1.0)
    return smooth_difference(body, radius_head(p) - clearance, 1.0)


def _radius_parts(shape, line, layout: ArticularLayout, clearance: float):
    """The radius at theta = 0 and its head alone (the ulna's radial notch), as two solids."""
    start, end = line
    d = (end - start) / np.linalg.norm(end - start)
    centre = np.array([layout.capitulum_centre, 0.0, 0.0])
    reach = layout.capitulum_radius + clearance
    # where the bone's line leaves the capitulum's sphere (at the clearance): the dish's bottom
    b = (start - centre) @ d
    s0 = -b + np.sqrt(max(b * b - ((start - centre) @ (start - centre) - reach**2), 0.0))
    top = start + (s0 - 2.5) * d
    head_end = top + shape.head_height * d
    neck_end = head_end + shape.neck_length * d
    head_r = 0.5 * shape.head_diameter

    def head(p):
        s = (p - top) @ d
        radial = np.linalg.norm(p - top - s[:, None] * d, axis=1) - (head_r - 1.5)
        axial = np.abs(s - 0.5 * shape.head_height) - (0.5 * shape.head_height - 1.5)
        return np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0)) + np.minimum(np.maximum(radial, axial), 0.0) - 1.5

    def radius(p):
        neck = round_cone(p, head_end, neck_end, 6.5, 6.5)
        tuberosity = ellipsoid(p, neck_end + 6.0 * d + [-5.0, 0.0, 0.0], (5.0, 5.0, 9.0))
        shaft = round_cone(p, neck_end, end, 6.5, 7.0)
        distal = ellipsoid(p, end + [0.0, 0.0, 8.0], (13.0, 9.0, 14.0))
        body = smooth_union(smooth_union(smooth_union(head(p), neck, 3.0), tuberosity, 4.0), shaft, 4.0)
        body = smooth_union(body, distal, 15.0)
        return smooth_difference(body, sphere(p, centre, reach), 1.0)

    return radius, head


def _swept(solid, limits_deg) -> callable:
    """The space the elbow end of a forearm solid (given at theta = 0; within ``REACH_MM`` of the
    hinge axis) sweeps over the joint's range: the humerus's fossae."""
    angles = np.arange(limits_deg[0], limits_deg[1] + 0.5 * SWEEP_STEP_DEG, SWEEP_STEP_DEG)

    def field(p):
        # the points turned back by theta about the hinge (local x) instead of the solid forward
        near_end = np.hypot(p[:, 1], p[:, 2]) - REACH_MM
        return np.min([np.maximum(solid(p @ rotation_about(np.array([1.0, 0.0, 0.0]), angle)), near_end)
                       for angle in angles], axis=0)

    return field


def _humerus_solid(shape, line, layout: ArticularLayout, shaft_radius: float, forearm: list, clearance: float):
    """The humerus with its fossae cut (module docstring) and the box that holds it."""
    _, (medial, lateral, bottom, top) = _humerus_base(np.zeros((1, 3)), shape, line, layout, shaft_radius)
    swept = _swept(lambda p: np.min([solid(p) for solid in forearm], axis=0), shape.fossae_deg) if forearm else None

    def solid(p):
        base, _ = _humerus_base(p, shape, line, layout, shaft_radius)
        if swept is None:
            return base
        near = (base < 2.0) & (np.hypot(p[:, 1], p[:, 2]) < REACH_MM + 2.0)
        cut = np.full(len(p), np.inf)
        cut[near] = swept(p[near]) - clearance
        return smooth_difference(base, cut, 1.0)

    return solid, (medial - 6.0, -35.0, bottom - 3.0), (lateral + 6.0, 35.0, top + 3.0)


def _solids(spec, frame: ElbowFrame) -> dict:
    """name -> (solid, box lower, box upper) in the elbow frame, for every bone with an anatomical shape."""
    from persival.model.anatomy.bone_schema import HumerusShape, UlnaShape

    shapes = {b.name: b.drawn_shape() for b in spec.bones}
    lines = {b.name: (frame.local(b.start), frame.local(b.end)) for b in spec.bones}
    of_kind = {shape.kind: name for name, shape in reversed(shapes.items())}  # the first bone of each kind
    capitulum_x = lines[of_kind["radius"]][0][0] if "radius" in of_kind else 12.0
    layout = articular_layout(shapes[of_kind["humerus"]] if "humerus" in of_kind else HumerusShape(), capitulum_x)
    clearance = (shapes[of_kind["ulna"]] if "ulna" in of_kind else UlnaShape()).joint_clearance
    solids = {}
    radius_head = lambda p: np.full(len(p), np.inf)  # noqa: E731 - no radius, no radial notch
    for name, shape in shapes.items():
        if shape.kind == "radius":
            solid, radius_head = _radius_parts(shape, lines[name], layout, clearance)
            solids[name] = solid
    for name, shape in shapes.items():
        if shape.kind == "ulna":
            solids[name] = partial(_ulna, shape=shape, line=lines[name], layout=layout, radius_head=radius_head)
    out = {}
    for name, solid in solids.items():
        start, end = lines[name]
        lower, upper = np.minimum(start, end) - [30.0, 30.0, 20.0], np.maximum(start, end) + [30.0, 30.0, 20.0]
        lower[2], upper[2] = min(lower[2], -45.0), max(upper[2], 40.0)
        out[name] = (solid, lower, upper)
    forearm = [solids[b.name] for b in spec.bones if b.segment == "forearm" and b.name in solids]
    for bone in spec.bones:
        if shapes[bone.name].kind == "humerus":
            out[bone.name] = _humerus_solid(shapes[bone.name], lines[bone.name], layout, bone.radius, forearm, clearance)
    return out


@lru_cache(maxsize=4)
def _shapes(spec_json: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    from persival.model.anatomy.schema import ArmModelFile

    spec = ArmModelFile.model_validate_json(spec_json)
    frame = ElbowFrame.of(spec)
    solids = _solids(spec, frame)
    out = {}
    for bone in spec.bones:
        if bone.name in solids:
            solid, lower, upper = solids[bone.name]
            points, triangles = triangulate(solid, lower, upper, SPACING_MM, TRIANGLES[bone.drawn_shape().kind])
        else:  # a tube
            points, triangles = tube_surface(frame.local(bone.start), frame.local(bone.end), bone.radius)
        out[bone.name] = (frame.world(points), triangles)
    return out


def cached_bone_arrays(spec, tag: str, versions, build) -> dict[str, np.ndarray]:
    """Arrays derived from a model's bones, built once by ``build() -> {name: array}`` and kept in
    the cache folder as ``{model}-{key}{tag}.npz``, keyed by the joint, the bones, VTK's version
    and ``versions`` (those of the code that builds them); an unreadable file is built again."""
    from vtkmodules.vtkCommonCore import vtkVersion

    key_text = json.dumps({"version": versions, "vtk": vtkVersion.GetVTKVersion(),
                           "joint": spec.joint.model_dump(), "bones": [b.model_dump() for b in spec.bones]},
                          sort_keys=True)
    key = hashlib.sha256(key_text.encode()).hexdigest()[:16]
    path = cache_root() / "bones" / f"{spec.name}-{key}{tag}.npz"
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as data:
                return {name: data[name] for name in data.files}
        except (OSError, ValueError):
            pass  # unreadable: built again and overwritten
    arrays = build()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.writing.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)
    return arrays


def bone_shapes(spec) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every bone of a model as (points (n, 3), triangles (k, 3)) in arm coordinates, forearm
    bones at theta = 0 (turn them with the forearm). Built once per model (a few seconds) and
    kept in the cache folder (:func:`cached_bone_arrays`)."""

    def build() -> dict[str, np.ndarray]:
        shapes = _shapes(spec.model_dump_json(exclude_unset=True))
        return {f"{n}/{part}": a.copy() for n, arrays in shapes.items() for part, a in zip(("points", "triangles"), arrays)}

    data = cached_bone_arrays(spec, "", SHAPES_VERSION, build)
    return {b.name: (data[f"{b.name}/points"], data[f"{b.name}/triangles"]) for b in spec.bones}
