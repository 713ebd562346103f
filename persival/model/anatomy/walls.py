"""Fascial walls: rigid surfaces a muscle keeps to its side of (docs/theory.md, 3.5).

The arm's muscles lie in compartments bounded by the deep fascia and the intermuscular septa,
which are tied to the bones. Here a wall is a rigid analytic surface that moves with its bone's
segment, with the same frictionless penalty contact and the same interface as the bones'
capsules (:mod:`persival.model.anatomy.obstacles`: penetration g, ``n = -dg/dx`` and ``dn/dx``), so each
muscle still depends on its own activation and the elbow angle only:

* :class:`Septum`: a plane, active over a band of heights (a window w(s) along a direction,
  quintic smoothstep ramps at both ends, so that a septum between two muscles of the upper arm
  lets both cross the elbow below it). g = w(s) (p - x).m for a muscle on the +m side; with
  dg/dx = -w m + ((p - x).m) w'(s) a,  n = -dg/dx,  dn/dx = -d2g/dx2
  = w' (a m^T + m a^T) - ((p - x).m) w'' a a^T.
* :class:`Sleeve`: the inside of a capsule (the deep fascia round the upper arm): g = d - R,
  d the distance to the axis segment, n = -(x - c)/d towards the axis, dn/dx = -(I - n n^T - t t^T)/d
  (without t t^T beyond the segment's ends).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from persival.model.anatomy.obstacles import Capsule, Faded, _as_vector
from persival.model.fe.rotations import rotation_about

__all__ = ["Septum", "Sleeve", "fade_share", "give_mm", "turn_deg", "wall_obstacles"]


def _smoothstep(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic smoothstep S(t) = 6t^5 - 15t^4 + 10t^3 on [0, 1] (0 before, 1 after), S', S''."""
    t = np.clip(t, 0.0, 1.0)
    return t**3 * (10 - 15 * t + 6 * t**2), 30 * t**2 * (1 - t) ** 2, 60 * t * (1 - t) * (1 - 2 * t)


@dataclass(frozen=True)
class Septum:
    """A plane through ``point`` that the body keeps to the ``normal`` side of, over the heights
    ``band`` = (lo, hi) mm along ``along`` from ``point`` (ramps of ``ramp`` mm inside them)."""

    point: np.ndarray
    normal: np.ndarray
    along: np.ndarray
    band: tuple[float, float]
    ramp: float
    name: str = "septum"

    def __post_init__(self) -> None:
        for key in ("point", "normal", "along"):
            object.__setattr__(self, key, _as_vector(getattr(self, key)))
        for key in ("normal", "along"):
            v = getattr(self, key)
            if np.linalg.norm(v) == 0:
                raise ValueError(f"wall {self.name!r}: {key} must be non-zero")
            object.__setattr__(self, key, v / np.linalg.norm(v))
        if not (self.ramp > 0 and self.band[1] - self.band[0] >= 2 * self.ramp):
            raise ValueError(f"wall {self.name!r}: its band must be at least two ramps long")

    def _window(self, x: np.ndarray):
        s = (x - self.point) @ self.along
        lo, hi = self.band
        a, da, dda = _smoothstep((s - lo) / self.ramp)
        b, db, ddb = _smoothstep((hi - s) / self.ramp)
        r = self.ramp
        return a * b, (da * b - a * db) / r, (dda * b - 2 * da * db + a * ddb) / r**2

    def project(self, x: np.ndarray):
        """Penetration g (n,), n = -dg/dx (n, 3) and ``dn_dx(mask)`` (as the bones' capsules)."""
        depth = (self.point - x) @ self.normal
        w, dw, ddw = self._window(x)
        g = w * depth
        n = w[:, None] * self.normal[None] - (depth * dw)[:, None] * self.along[None]
        cross = np.outer(self.along, self.normal) + np.outer(self.normal, self.along)
        a_a = np.outer(self.along, self.along)

        def dn_dx(mask: np.ndarray) -> np.ndarray:
            return dw[mask][:, None, None] * cross[None] - (depth[mask] * ddw[mask])[:, None, None] * a_a[None]

        return g, n, dn_dx

    def shifted(self, distance: float) -> Septum:
        """The same septum moved ``distance`` mm against its normal (it gives way to what it holds)."""
        return Septum(self.point - distance * self.normal, self.normal, self.along, self.band, self.ramp, self.name)

    def flipped(self) -> Septum:
        """The same plane, kept from the other side."""
        return Septum(self.point, -self.normal, self.along, self.band, self.ramp, self.name)

    def transformed(self, rotation: np.ndarray, centre) -> Septum:
        c, R = _as_vector(centre), np.asarray(rotation, dtype=float)
        return Septum(c + R @ (self.point - c), R @ self.normal, R @ self.along, self.band, self.ramp, self.name)


@dataclass(frozen=True)
class Sleeve:
    """The inside of ``capsule``: the body keeps within its radius of its axis segment. The
    capsule's penetration, normal and normal gradient with their signs turned."""

    capsule: Capsule

    @property
    def name(self) -> str:
        return self.capsule.name

    def project(self, x: np.ndarray):
        g, n, dn_dx = self.capsule.project(x)
        return -g, -n, lambda mask: -dn_dx(mask)

    def transformed(self, rotation: np.ndarray, centre) -> Sleeve:
        return Sleeve(self.capsule.transformed(rotation, centre))


def wall_of(spec_wall):
    """The obstacle of a model-file wall entry (persival.model.arm.model_file.Wall), at theta = 0."""
    if spec_wall.kind == "sleeve":
        return Sleeve(Capsule(spec_wall.start, spec_wall.end, spec_wall.radius, spec_wall.name))
    return Septum(spec_wall.point, spec_wall.normal, spec_wall.along, tuple(spec_wall.band), spec_wall.ramp,
                  spec_wall.name)


def septum_sides(walls, centre, axis, mesh_angle_deg: float, points: np.ndarray) -> dict[str, float]:
    """Per septum, +1 when a muscle's mesh nodes (in its mesh pose, ``mesh_angle_deg``) lie on its
    normal's side, -1 on the other (weighted by the septum's window): the side it is kept to."""
    placed = wall_obstacles(walls, centre, axis, mesh_angle_deg, {})
    sides = {}
    for wall in placed:
        if isinstance(wall, Septum):
            w, _, _ = wall._window(points)
            sides[wall.name] = 1.0 if float(np.sum(w * ((points - wall.point) @ wall.normal))) >= 0 else -1.0
    return sides


def turn_deg(wall, theta_deg: float, onset_deg: float = 10.0) -> float:
    """How far a wall with ``turns`` has turned at elbow angle theta (docs/theory.md 3.5): the
    fraction ``turns`` of the flexion beyond ``turns_from_deg``, its onset smoothed over
    ``onset_deg`` (a softplus, so the contact's angle rates stay smooth)."""
    return wall.turns * onset_deg * float(np.logaddexp(0.0, (theta_deg - wall.turns_from_deg) / onset_deg))


def _ramp(theta_deg: float, span: tuple[float, float]) -> float:
    """A quintic smoothstep in the angle: 0 up to span[0], 1 from span[1]."""
    a, b = span
    return float(_smoothstep(np.array((theta_deg - a) / (b - a)))[0])


def give_mm(wall, theta_deg: float) -> float:
    """How far a septum with ``gives_mm`` has moved away from the muscle it holds at elbow angle
    theta (docs/theory.md 3.5): none up to gives_deg[0], all of it from gives_deg[1]."""
    return 0.0 if wall.gives_mm == 0 else wall.gives_mm * _ramp(theta_deg, wall.gives_deg)


def fade_share(wall, theta_deg: float) -> float:
    """How much of a wall with ``fades_deg`` = (a, b) holds at elbow angle theta: 1 up to a, 0 from
    b, a quintic smoothstep between (docs/theory.md 3.5), so the contact's angle rates stay smooth."""
    return 1.0 if wall.fades_deg is None else 1.0 - _ramp(theta_deg, wall.fades_deg)


def wall_obstacles(walls, centre, axis, theta_deg: float, sides: dict[str, float]) -> list:
    """The walls at elbow angle theta (forearm walls turn about the hinge, a wall with ``turns``
    also about its pivot, one with ``fades_deg`` is scaled by its share), each septum kept from the
    side ``sides[name]`` (+1: its normal's side, -1: the other)."""
    out = []
    for wall in walls:
        obstacle = wall_of(wall)
        if isinstance(obstacle, Septum) and sides.get(wall.name, 1.0) < 0:
            obstacle = obstacle.flipped()
        if isinstance(obstacle, Septum) and wall.gives_mm:
            obstacle = obstacle.shifted(give_mm(wall, theta_deg))
        if wall.turns != 0:
            obstacle = obstacle.transformed(rotation_about(axis, turn_deg(wall, theta_deg)), wall.pivot)
        if wall.segment == "forearm":
            obstacle = obstacle.transformed(rotation_about(axis, theta_deg), centre)
        share = fade_share(wall, theta_deg)
        out.append(obstacle if share == 1.0 else Faded(obstacle, share))
    return out
