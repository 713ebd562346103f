"""A built-in muscle's solid as a sweep: a centre line and a cross section at each station.

docs/theory.md 3.2. Two ways to lay a muscle out in the model file:

* a spindle: the centre line runs straight from origin to insertion (through via points, bowed
  away from the hinge by ``bow``), the sections are circles of :func:`muscle_profile`'s radius;
* outlines (:class:`persival.model.arm.model_file.Outline`): the ellipses where the belly crosses planes
  of the upper arm, as a cross-sectional atlas draws them. The centre line is a cubic spline
  through the origin, the outlines' centres and the insertion; the sections are ellipses whose
  semi-axes and orientation are interpolated (PCHIP, no overshoot) between the outlines and held
  beyond them, tapered into the tendons as the spindle's radius is.

Either way the muscle's line of action (its length and moment arm) is the origin-insertion path of
:mod:`persival.model.arm.body`; the sweep only shapes the FE body between its two end faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from persival.model.anatomy.muscle_schema import Muscle

__all__ = ["Sweep", "muscle_profile", "outlined_centre_line", "sweep_sections"]


def _taper(muscle: Muscle, s: np.ndarray, length: float):
    """The tissue layout along s: tendon radius, the smoothstep from tendon to belly, the belly's
    bulge and the muscle fraction gamma_M (docs/theory.md, 1.5 mixture)."""
    s_a = muscle.tendon_length[0] / length
    s_b = 1.0 - muscle.tendon_length[1] / length
    if s_b - s_a <= 3.0 * muscle.transition_length / length:
        raise ValueError(f"muscle {muscle.name!r}: tendons and transitions are longer than the muscle ({length:.0f} mm)")
    r_tendon = muscle.tendon_radius[0] + (muscle.tendon_radius[1] - muscle.tendon_radius[0]) * s
    ramp = muscle.transition_length / length
    depth = np.clip(np.minimum(s - s_a, s_b - s), 0.0, None)  # distance into the belly
    z = np.clip(depth / (1.5 * ramp), 0.0, 1.0)
    bulge = np.sin(np.pi * np.clip((s - s_a) / (s_b - s_a), 0.0, 1.0))
    return r_tendon, 3.0 * z**2 - 2.0 * z**3, bulge, np.clip(depth / ramp, 0.0, 1.0)


def muscle_profile(muscle: Muscle, s: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Radius and muscle fraction gamma_M along the normalized centre-line position s.

    Pure tendon over the tendon lengths, a linear muscle-tendon blend over
    ``transition_length`` (docs/theory.md, 1.5 mixture), then the belly. The radius rises from the
    tendon's to 90 % of the belly's over 1.5 transition lengths (smoothstep) and bulges to the
    full belly radius at the middle. Why so blunt: the muscle's sections are in series, so the
    thinnest pure-muscle section bounds the force the whole unit can pull (0.3 MPa times its
    area); a fusiform taper (sin(pi x)^(1/2) or ^(1/3)) left about 40 % of the belly's area
    there, and a full biceps stalled at 72 N, 108 deg.
    """
    r_tendon, smooth, bulge, gamma = _taper(muscle, s, length)
    shape = smooth * (0.9 + 0.1 * bulge)  # in this order: gmsh meshes a radius 1 ulp off differently
    radius = r_tendon + (muscle.belly_radius - r_tendon) * shape
    return radius, gamma


def outlined_centre_line(muscle: Muscle, origin: np.ndarray, end: np.ndarray, stations: int) -> np.ndarray:
    """``stations`` points, equally spaced in arclength, of the cubic spline (chord-length
    parameter) from ``origin`` through the outlines' centres, in the order the path meets them,
    to the body's ``end``. Every outline's plane must lie between the two ends."""
    from scipy.interpolate import CubicSpline

    lo, hi = sorted((origin[2], end[2]))
    outside = [o.z for o in muscle.outlines if not lo < o.z < hi]
    if outside:
        raise ValueError(f"muscle {muscle.name!r}: the outline at z = {outside[0]:g} mm does not lie between its ends "
                         f"(z = {origin[2]:.1f} and {end[2]:.1f} mm in its mesh pose)")
    ordered = sorted(muscle.outlines, key=lambda o: -abs(o.z - end[2]))
    knots = np.array([origin, *[(*o.centre, o.z) for o in ordered], end], dtype=float)
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))])
    if np.any(np.diff(chord) <= 0):
        raise ValueError(f"muscle {muscle.name!r}: an outline's centre coincides with the next point of its path")
    spline = CubicSpline(chord, knots)
    fine = spline(np.linspace(0.0, chord[-1], 40 * stations))
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(fine, axis=0), axis=1))])
    even = np.linspace(0.0, arc[-1], stations)
    return np.column_stack([np.interp(even, arc, fine[:, k]) for k in range(3)])


@dataclass(frozen=True)
class Sweep:
    """The stations of a muscle's solid: centre line (k, 3), semi-axes (k, 2), larger first, and the
    larger one's direction (k, 3), perpendicular to the centre line (None for circles)."""

    line: np.ndarray
    semi_axes: np.ndarray
    major: np.ndarray | None

    @property
    def circular(self) -> bool:
        return self.major is None

    def mesh(self, mesh_size: float):
        """The solid meshed by gmsh (persival.model.fe.geometry.swept_solid_mesh)."""
        from persival.model.fe.geometry import swept_solid_mesh

        if self.circular:
            return swept_solid_mesh(self.line, self.semi_axes[:, 0], mesh_size)
        return swept_solid_mesh(self.line, self.semi_axes, mesh_size, major_axes=self.major)


def sweep_sections(muscle: Muscle, line: np.ndarray, length: float) -> Sweep:
    """The muscle's sections along its centre line ``line`` of ``length`` mm (docs/theory.md 3.2)."""
    s = np.linspace(0.0, 1.0, len(line))
    if not muscle.outlines:
        radius, _ = muscle_profile(muscle, s, length)
        return Sweep(line, np.column_stack([radius, radius]), None)
    from scipy.interpolate import PchipInterpolator

    at = _outline_positions(muscle, line)
    order = np.argsort(at)
    at = at[order]
    axes = np.array([muscle.outlines[i].semi_axes for i in order], dtype=float)
    angle = np.radians([muscle.outlines[i].angle_deg for i in order])
    inner = np.clip(s, at[0], at[-1])  # held beyond the first and last outline
    if len(at) > 1:
        axes_s = PchipInterpolator(at, axes, axis=0)(inner)
        angle_s = PchipInterpolator(at, angle)(inner)
    else:
        axes_s, angle_s = np.repeat(axes, len(s), axis=0), np.full(len(s), angle[0])
    r_tendon, smooth, _, _ = _taper(muscle, s, length)
    semi = r_tendon[:, None] + (axes_s - r_tendon[:, None]) * smooth[:, None]
    tangent = np.gradient(line, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    direction = np.column_stack([np.cos(angle_s), np.sin(angle_s), np.zeros(len(s))])
    major = direction - np.einsum("ki,ki->k", direction, tangent)[:, None] * tangent
    norm = np.linalg.norm(major, axis=1)
    if np.any(norm < 0.2):
        raise ValueError(f"muscle {muscle.name!r}: its centre line runs along an outline's larger semi-axis "
                         "(the ellipse cannot be placed across it)")
    return Sweep(line, semi, major / norm[:, None])


def _outline_positions(muscle: Muscle, line: np.ndarray) -> np.ndarray:
    """Normalized arclength of the point where the centre line crosses each outline's plane."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    arc /= arc[-1]
    positions = []
    for outline in muscle.outlines:
        dz = line[:, 2] - outline.z
        i = int(np.flatnonzero(dz[:-1] * dz[1:] <= 0)[0])
        t = dz[i] / (dz[i] - dz[i + 1]) if dz[i] != dz[i + 1] else 0.0
        positions.append(arc[i] + t * (arc[i + 1] - arc[i]))
    return np.array(positions)
