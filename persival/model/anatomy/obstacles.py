"""Rigid obstacles of muscle-bone contact: what a surface point's penetration g, the outward
normal n = -dg/dx and its gradient dn/dx are for each kind (docs/theory.md, 3.5).

* ``Capsule``: all points within a radius of a segment (a model file's ``[[bones]]`` entry):
  g = r - dist(x, segment), n along the closest-point offset, ``dn/dx = (I - n n^T - t t^T)/d``
  where the closest point lies inside the segment (t: unit axis), ``(I - n n^T)/d`` on the caps;
* ``HalfSpace``: behind a plane (verification tests), dn/dx = 0;
* ``Faded``: any obstacle with its penetration scaled by a share in [0, 1] (contact switched on
  gradually); the bones' shaped surfaces (persival.model.anatomy.bone_fields.DistanceField) and the
  fascial walls (persival.model.anatomy.walls) have the same interface.

Each moves rigidly (``transformed``, ``rotated``): forearm bones turn with the elbow angle
(``bone_obstacles``), and a muscle solved in its own frame sees them turned into it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from persival.model.fe.rotations import rotation_about

__all__ = ["Capsule", "Faded", "HalfSpace", "bone_obstacles"]


def _as_vector(v) -> np.ndarray:
    v = np.asarray(v, dtype=float).reshape(3)
    if not np.all(np.isfinite(v)):
        raise ValueError("obstacle coordinates must be finite")
    return v


@dataclass(frozen=True)
class Capsule:
    """All points within ``radius`` of the segment start-end (a bone's shaft with rounded ends)."""

    start: np.ndarray
    end: np.ndarray
    radius: float
    name: str = "capsule"

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", _as_vector(self.start))
        object.__setattr__(self, "end", _as_vector(self.end))
        if not self.radius > 0:
            raise ValueError(f"obstacle {self.name!r}: radius must be positive")

    @classmethod
    def from_bone(cls, bone) -> Capsule:
        """From a model-file bone entry (anything with start, end, radius and name)."""
        return cls(bone.start, bone.end, float(bone.radius), bone.name)

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """Penetration g (n,), outward normal n (n, 3) and ``dn_dx(mask) -> (k, 3, 3)`` (docs/theory.md, 3.5)."""
        axis = self.end - self.start
        length = float(np.linalg.norm(axis))
        t = axis / length if length > 0 else np.zeros(3)
        s = (x - self.start) @ t
        inside = (s > 0.0) & (s < length)  # closest point slides along the axis (else: a fixed end)
        v = x - (self.start + np.clip(s, 0.0, length)[:, None] * t)
        d = np.linalg.norm(v, axis=1)
        # a node exactly on the axis has no normal: it gets none (zero force), a degenerate case
        d_safe = np.where(d > 0.0, d, np.inf)
        n = v / d_safe[:, None]

        def dn_dx(mask: np.ndarray) -> np.ndarray:
            nm = n[mask]
            P = np.eye(3) - nm[:, :, None] * nm[:, None, :]
            P -= inside[mask][:, None, None] * np.outer(t, t)[None]
            return P / d_safe[mask][:, None, None]

        return self.radius - d, n, dn_dx

    def transformed(self, rotation: np.ndarray, centre) -> Capsule:
        """The capsule moved rigidly: p -> centre + rotation (p - centre)."""
        c, R = _as_vector(centre), np.asarray(rotation, dtype=float)
        return Capsule(c + R @ (self.start - c), c + R @ (self.end - c), self.radius, self.name)

    def rotated(self, axis, centre, theta_deg: float) -> Capsule:
        """Turned by theta about an axis through centre (a forearm bone at elbow angle theta)."""
        return self.transformed(rotation_about(axis, theta_deg), centre)


@dataclass(frozen=True)
class HalfSpace:
    """The rigid half-space behind the plane through ``point`` with outward unit ``normal``."""

    point: np.ndarray
    normal: np.ndarray
    name: str = "half-space"

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _as_vector(self.point))
        n = _as_vector(self.normal)
        if np.linalg.norm(n) == 0:
            raise ValueError(f"obstacle {self.name!r}: normal must be non-zero")
        object.__setattr__(self, "normal", n / np.linalg.norm(n))

    def project(self, x: np.ndarray):
        """As :meth:`Capsule.project`; a plane's normal does not turn (dn/dx = 0)."""
        g = (self.point - x) @ self.normal
        return g, np.broadcast_to(self.normal, x.shape), lambda mask: np.zeros((int(np.count_nonzero(mask)), 3, 3))

    def transformed(self, rotation: np.ndarray, centre) -> HalfSpace:
        c, R = _as_vector(centre), np.asarray(rotation, dtype=float)
        return HalfSpace(c + R @ (self.point - c), R @ self.normal, self.name)

    def rotated(self, axis, centre, theta_deg: float) -> HalfSpace:
        return self.transformed(rotation_about(axis, theta_deg), centre)


@dataclass(frozen=True)
class Faded:
    """An obstacle whose penetration is scaled by ``share`` in [0, 1], so its penalty energy by
    share^2: contact switched on gradually where a mesh starts inside a bone (force and tangent
    stay the exact derivatives of that energy)."""

    obstacle: object
    share: float

    @property
    def name(self) -> str:
        return self.obstacle.name

    @property
    def spares_ends(self) -> bool:
        return getattr(self.obstacle, "spares_ends", False)

    def project(self, x: np.ndarray):
        g, n, dn_dx = self.obstacle.project(x)
        s = self.share
        return s * g, s * n, (lambda mask: s * dn_dx(mask))

    def transformed(self, rotation: np.ndarray, centre) -> Faded:
        return Faded(self.obstacle.transformed(rotation, centre), self.share)


def bone_obstacles(bones, centre, axis, theta_deg: float, fields: dict | None = None) -> list:
    """Obstacles of model-file bones at elbow angle theta: their shaped surfaces where ``fields``
    (name -> persival.model.anatomy.bone_fields.DistanceField) has them, else their capsules;
    ``forearm`` bones (given at theta = 0) turn about the hinge, ``upper_arm`` bones stay
    (docs/theory.md, 3.5)."""
    out = []
    for bone in bones:
        obstacle = (fields or {}).get(bone.name) or Capsule.from_bone(bone)
        out.append(obstacle.rotated(axis, centre, theta_deg) if bone.segment == "forearm" else obstacle)
    return out
