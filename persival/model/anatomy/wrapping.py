"""A tendon over a wrap cylinder on the hinge axis: the muscle path's length and its derivatives.

docs/theory.md, 3.4, muscle paths. A muscle with ``wrap_radius`` r > 0 runs from its origin O (fixed to the
upper arm) to its insertion I(theta) (turning with the forearm) along the shortest path that
stays outside a cylinder of radius r about the hinge axis, fixed to the humerus: the trochlea
and olecranon that the triceps tendon slides over (the classic wrap cylinder of musculoskeletal
path models). While the straight segment O-I clears the cylinder the path is that segment; once
it would cut into it, the path is tangent segment + arc + tangent segment, and because the arc is
centred on the hinge its length grows by r per radian of elbow rotation: the moment arm is r.

The wrapped part of the path is an inextensible frictionless cable of length ``cable``: the
muscle's FE body spans the first ``L(theta) - cable`` of the path from O, along the path's first
segment, so the FE body only needs the path length L(theta) and its derivatives (its state stays
a function of theta and its activation) and the moment is -T dL/dtheta (virtual work of the
cable, whose pulley reaction acts on the humerus).

Only the side the muscle acts on is wrapped: an extensor (its path lengthens with flexion) wraps
the way the forearm turns, a flexor the other way. The axial offset along the hinge axis is
carried by unrolling the cylinder (the helical geodesic), exact for the tangent-arc-tangent path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WrapCylinder"]


@dataclass(frozen=True)
class WrapCylinder:
    """Cylinder of ``radius`` about the hinge (``centre``, unit ``axis``); ``turn`` = +1 for a path
    that lengthens as the forearm turns by +theta (an extensor), -1 for one that shortens."""

    centre: np.ndarray
    axis: np.ndarray
    radius: float
    turn: int

    def _frame(self) -> tuple[np.ndarray, np.ndarray]:
        k = self.axis
        e1 = np.cross(k, [1.0, 0.0, 0.0] if abs(k[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        return e1, np.cross(k, e1)

    def _polar(self, p: np.ndarray) -> tuple[float, float, float]:
        """(distance from the axis, polar angle about it, axial coordinate) of point p."""
        e1, e2 = self._frame()
        q = np.asarray(p, dtype=float) - self.centre
        x, y = float(q @ e1), float(q @ e2)
        return float(np.hypot(x, y)), float(np.arctan2(y, x)), float(q @ self.axis)

    def _wrap(self, origin: np.ndarray, insertion: np.ndarray):
        """The wrapped path's planar parts: (tangent lengths t_o, t_i, arc angle, polar angle of
        the origin-side tangent point, axial offset), or None when the straight segment clears."""
        r = self.radius
        if r == 0:
            return None
        (d_o, a_o, h_o), (d_i, a_i, h_i) = self._polar(origin), self._polar(insertion)
        if min(d_o, d_i) <= r:
            raise ValueError(f"a muscle end lies inside its wrap cylinder (radius {r} mm)")
        b_o, b_i = np.arccos(r / d_o), np.arccos(r / d_i)
        # tangent points: leaving O the contact point moves in the turning sense (docs/theory.md, 3.4)
        phi_o = a_o + self.turn * b_o
        phi_i = a_i - self.turn * b_i
        # in (-pi, pi]: a straight segment that clears the cylinder has a negative "arc"
        arc = np.pi - (np.pi - self.turn * (phi_i - phi_o)) % (2.0 * np.pi)
        if arc <= 0.0:
            return None
        return np.sqrt(d_o**2 - r**2), np.sqrt(d_i**2 - r**2), arc, phi_o, h_i - h_o

    def geometry(self, origin: np.ndarray, insertion: np.ndarray, insertion_rate: np.ndarray,
                 insertion_acceleration: np.ndarray) -> tuple[float, float, float]:
        """Path length L (mm) and dL/dtheta, d2L/dtheta2 (per radian) for an insertion turning
        about the hinge at rate I' (= k x (I - c)) and I''."""
        wrapped = self._wrap(origin, insertion)
        if wrapped is None:  # the straight segment
            chord = np.asarray(insertion, dtype=float) - origin
            L = float(np.linalg.norm(chord))
            e = chord / L
            dL = float(e @ insertion_rate)
            return L, dL, float((insertion_rate @ insertion_rate - dL**2) / L + e @ insertion_acceleration)
        t_o, t_i, arc, _, h = wrapped
        planar = t_o + t_i + self.radius * arc
        rate = self.turn * self.radius  # the arc grows by r per radian
        L = float(np.hypot(planar, h))
        return L, planar * rate / L, rate**2 * h**2 / L**3

    def wraps(self, origin: np.ndarray, insertion: np.ndarray) -> bool:
        """Whether the path from ``origin`` to ``insertion`` touches the cylinder."""
        return self._wrap(origin, insertion) is not None

    def first_direction(self, origin: np.ndarray, insertion: np.ndarray) -> np.ndarray:
        """Unit direction of the path's first segment at O (towards the tangent point when wrapped)."""
        wrapped = self._wrap(origin, insertion)
        if wrapped is None:
            chord = np.asarray(insertion, dtype=float) - origin
            return chord / np.linalg.norm(chord)
        t_o, t_i, arc, phi_o, h = wrapped
        e1, e2 = self._frame()
        planar = t_o + t_i + self.radius * arc
        h_o = self._polar(origin)[2]
        tangent_point = (self.centre + self.radius * (np.cos(phi_o) * e1 + np.sin(phi_o) * e2)
                         + (h_o + h * t_o / planar) * self.axis)
        d = tangent_point - origin
        return d / np.linalg.norm(d)
