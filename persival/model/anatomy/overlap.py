"""Does the arm hold together? Overlap between bodies and the gap between a muscle and its bed.

Every body (muscle or bone) is a closed triangle surface at its current position. Two measures
(docs/design/arm_model_record.md, "Overlap between bodies"):

* overlap, per ordered pair (A, B): the surface nodes of A that lie inside B and the deepest of
  them (its distance to B's surface). Inside/outside and depth come from one signed distance to
  B's surface (VTK's implicit poly-data distance, negative inside; the surface is oriented
  outward first). Nodes within ``attachment_mm`` of a muscle's two ends (its origin and the end
  of its FE body: where it is tied to the bones) are left out, of A and of B: a tendon meets its
  bone there by design.
* bed gap, per muscle: along its belly (the middle of the line between its two ends) the
  muscle is cut into stations; at each, the gap is the distance from the station's nodes
  nearest the bed to the bed (the union of the bodies it should lie on: a bone or the neighbour
  beneath it), 0 where it touches or enters it. The largest gap along the belly says how far a
  slack muscle bows off its bed.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["BEDS", "Body", "bed_gaps", "overlaps", "signed_distance"]

#: What each built-in muscle lies on (cross-sectional anatomy of the arm): the brachialis and
#: the triceps on the humerus, the biceps on the brachialis (proximally on the humerus), the
#: brachioradialis on the lateral supracondylar ridge and the brachialis, the anconeus on the ulna.
BEDS = {
    "biceps": ("brachialis", "humerus"),
    "brachialis": ("humerus",),
    "brachioradialis": ("brachialis", "humerus", "radius"),
    "triceps": ("humerus",),
    "anconeus": ("ulna", "humerus"),
}


@dataclass
class Body:
    """A closed triangle surface at its current position; a muscle also has its two ends."""

    name: str
    points: np.ndarray  # (n, 3) mm
    triangles: np.ndarray  # (k, 3) indices into points
    ends: np.ndarray | None = None  # (2, 3) origin and insertion end (muscles only)

    @property
    def is_muscle(self) -> bool:
        return self.ends is not None

    @cached_property
    def surface(self):
        """The outward-oriented pyvista surface."""
        return _oriented_polydata(self.points, self.triangles)

    def near_ends(self, x: np.ndarray, distance_mm: float) -> np.ndarray:
        """Points of x within ``distance_mm`` of this body's ends (all False for a bone)."""
        if self.ends is None:
            return np.zeros(len(x), dtype=bool)
        return np.min(np.linalg.norm(x[:, None, :] - self.ends[None], axis=2), axis=1) < distance_mm


def _oriented_polydata(points: np.ndarray, triangles: np.ndarray):
    """A pyvista PolyData of the triangles, wound so that the enclosed volume is positive."""
    import pyvista as pv

    points = np.asarray(points, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    p = points[triangles]
    volume = np.einsum("ki,ki->k", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    if volume < 0:
        triangles = triangles[:, ::-1]
    faces = np.column_stack([np.full(len(triangles), 3), triangles]).ravel()
    return pv.PolyData(points, faces)


def signed_distance(x: np.ndarray, body: Body) -> np.ndarray:
    """Signed distance (mm) of points x (n, 3) to the body's surface: negative inside."""
    import pyvista as pv

    if len(x) == 0:
        return np.zeros(0)
    probe = pv.PolyData(np.asarray(x, dtype=float)).compute_implicit_distance(body.surface)
    return np.asarray(probe.point_data["implicit_distance"], dtype=float)


def _in_box(x: np.ndarray, points: np.ndarray, pad: float = 0.0) -> np.ndarray:
    lo, hi = points.min(axis=0) - pad, points.max(axis=0) + pad
    return np.all((x >= lo) & (x <= hi), axis=1)


def overlaps(bodies: list[Body], attachment_mm: float = 10.0) -> list[dict]:
    """Per ordered pair (A, B) with a surface node of A inside B: the count of such nodes (of
    A's surface nodes), the deepest penetration (mm) and where it is. Nodes near a muscle's ends
    (A's or B's) are excluded (module docstring)."""
    rows = []
    for a in bodies:
        for b in bodies:
            if a is b:
                continue
            candidates = np.flatnonzero(_in_box(a.points, b.points))
            x = a.points[candidates]
            keep = ~(a.near_ends(x, attachment_mm) | b.near_ends(x, attachment_mm))
            candidates, x = candidates[keep], x[keep]
            depth = -signed_distance(x, b)
            inside = depth > 0.0
            if not inside.any():
                continue
            deepest = int(np.argmax(depth))
            rows.append({"body": a.name, "inside": b.name, "nodes": int(inside.sum()), "of": len(a.points),
                         "deepest_mm": float(depth[deepest]), "at": x[deepest].round(2).tolist()})
    return rows


def _belly_position(muscle: Body) -> np.ndarray:
    """Each node's position along the line between the muscle's two ends (0 origin, 1 insertion)."""
    origin, insertion = muscle.ends
    chord = insertion - origin
    return (muscle.points - origin) @ chord / (chord @ chord)


def bed_gaps(bodies: list[Body], beds: dict[str, tuple[str, ...]] | None = None, belly=(0.2, 0.8),
             stations: int = 12) -> list[dict]:
    """Per muscle with a bed among ``bodies``: the largest gap (mm) between its belly and its bed.

    The belly (``belly``: fractions of the line between the ends) is cut into ``stations``
    slabs; a slab's gap is the least signed distance of its nodes to any bed body, clipped at 0
    (touching or entering). Reported: the largest slab gap, its position along the line, and the
    closest node there (the point of the deep surface that is farthest off its bed)."""
    beds = BEDS if beds is None else beds
    by_name = {b.name: b for b in bodies}
    rows = []
    for muscle in bodies:
        bed = [by_name[n] for n in beds.get(muscle.name, ()) if n in by_name]
        if not muscle.is_muscle or not bed:
            continue
        s = _belly_position(muscle)
        in_belly = (s >= belly[0]) & (s <= belly[1])
        if not in_belly.any():
            continue
        x = muscle.points[in_belly]
        distance = np.min([signed_distance(x, b) for b in bed], axis=0)
        slab = np.minimum(((s[in_belly] - belly[0]) / (belly[1] - belly[0]) * stations).astype(int), stations - 1)
        gaps = np.full(stations, np.nan)
        nearest = np.zeros(stations, dtype=int)
        for k in np.unique(slab):
            members = np.flatnonzero(slab == k)
            nearest[k] = members[np.argmin(distance[members])]
            gaps[k] = max(0.0, float(distance[nearest[k]]))
        worst = int(np.nanargmax(gaps))
        rows.append({"muscle": muscle.name, "bed": [b.name for b in bed], "largest_gap_mm": float(gaps[worst]),
                     "at_fraction": float(belly[0] + (worst + 0.5) / stations * (belly[1] - belly[0])),
                     "at": x[nearest[worst]].round(2).tolist(),
                     "gaps_mm": [None if np.isnan(g) else round(float(g), 2) for g in gaps]})
    return rows
