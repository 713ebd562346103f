"""A shaped bone as a contact obstacle: its signed distance, sampled once, interpolated smoothly.

The bones' shaped surfaces (persival.model.anatomy.bone_shapes: epicondyles, trochlea, coronoid,
olecranon, the radial head) are what `persival anatomy` measures penetration against, so a muscle
that should stay out of them has to touch them, not their capsules. Contact needs, at each
surface point of a muscle, the penetration g, its gradient and its Hessian (docs/theory.md,
3.5). The closed triangle surface gives only a piecewise-flat distance, whose normal jumps from
face to face; Newton would chatter on it. So the signed distance phi to the surface (VTK's
implicit poly-data distance, negative inside) is sampled once on a regular grid around the bone
and interpolated by a tricubic B-spline: phi is C2, and its gradient and Hessian are exact
derivatives of the interpolant. With g = -phi,

    n = -dg/dx = grad phi,   dn/dx = Hess phi,

so the contact tangent is the exact Hessian of the penalty energy even where |grad phi| departs
from 1 between samples. Building the grids costs about 10 s per model (three bones, 1.5 mm; 9.5 s measured), then it
sits in the cache folder next to the bones' surfaces.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from persival.model.fe.rotations import rotation_about

__all__ = ["DistanceField", "bone_fields"]

FIELDS_VERSION = 3  # bump when the sampling below changes: the cached grids are rebuilt
GRID_MM = 1.5
PAD_MM = 8.0  # the grid reaches this far beyond the bone's surface (contact happens within it)


def _cubic_weights(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Uniform cubic B-spline weights of the four samples around t in [0, 1), and their first
    and second derivatives (per sample spacing), each (k, 4)."""
    s = 1.0 - t
    w = np.stack([s**3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3], axis=1) / 6.0
    dw = np.stack([-0.5 * s**2, 1.5 * t**2 - 2 * t, -1.5 * t**2 + t + 0.5, 0.5 * t**2], axis=1)
    d2w = np.stack([s, 3 * t - 2, 1 - 3 * t, t], axis=1)
    return w, dw, d2w


@dataclass(frozen=True)
class DistanceField:
    """A rigid obstacle given by a sampled signed distance: the bone at ``placement``.

    ``coefficients`` are the B-spline coefficients of phi on the grid whose first sample sits at
    ``lower`` (bone frame), ``spacing`` apart. The bone is placed by x = offset + rotation y (y in
    the bone frame). Points outside the grid's interior are far from the bone: no contact.
    ``spares_ends``: contact points near a muscle's two ends (its attachments, which lie on this
    bone by design) are left out (persival.model.fe.contact.ObstacleContact).
    """

    coefficients: np.ndarray
    lower: np.ndarray
    spacing: float
    name: str = "bone"
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    spares_ends: bool = True

    def evaluate(self, y: np.ndarray, order: int = 2) -> tuple[np.ndarray, ...]:
        """phi (k,), grad (k, 3) and, for ``order`` 2, the Hessian (k, 3, 3) at bone-frame points y
        (k, 3); +inf and zeros outside the grid's interior."""
        u = (np.asarray(y, dtype=float) - self.lower) / self.spacing
        base = np.floor(u).astype(np.int64) - 1
        inside = np.all((base >= 0) & (base + 3 < np.array(self.coefficients.shape)), axis=1)
        k = len(u)
        phi, grad, hess = np.full(k, np.inf), np.zeros((k, 3)), np.zeros((k, 3, 3))
        if inside.any():
            b, t = base[inside], u[inside] - np.floor(u[inside])
            offsets = np.arange(4)
            c = self.coefficients[(b[:, 0, None] + offsets)[:, :, None, None], (b[:, 1, None] + offsets)[:, None, :, None],
                                  (b[:, 2, None] + offsets)[:, None, None, :]]  # (m, 4, 4, 4)
            w = [_cubic_weights(t[:, axis]) for axis in range(3)]  # per axis: (value, d, d2) weights

            def contract(orders) -> np.ndarray:
                return np.einsum("mabc,ma,mb,mc->m", c, w[0][orders[0]], w[1][orders[1]], w[2][orders[2]], optimize=True)

            h, unit = self.spacing, np.eye(3, dtype=int)
            phi[inside] = contract((0, 0, 0))
            grad[inside] = np.stack([contract(o) for o in unit], axis=1) / h
            if order == 2:
                hm = np.empty((len(b), 3, 3))
                for i in range(3):
                    for j in range(i, 3):
                        hm[:, i, j] = hm[:, j, i] = contract(unit[i] + unit[j]) / h**2
                hess[inside] = hm
        return (phi, grad, hess) if order == 2 else (phi, grad)

    def project(self, x: np.ndarray):
        """Penetration g = -phi (n,), n = -dg/dx = grad phi (n, 3) and ``dn_dx(mask)`` = Hess phi
        (k, 3, 3), in the frame of x (as the capsules of persival.model.anatomy.obstacles). The Hessian is
        evaluated only where asked for: the active points, a few of the surface's."""
        R = self.rotation
        y = (np.asarray(x, dtype=float) - self.offset) @ R
        phi, grad = self.evaluate(y, order=1)

        def dn_dx(mask: np.ndarray) -> np.ndarray:
            return np.einsum("ij,mjk,lk->mil", R, self.evaluate(y[mask])[2], R)

        return -phi, grad @ R.T, dn_dx

    def transformed(self, rotation: np.ndarray, centre) -> DistanceField:
        """The bone moved rigidly: p -> centre + rotation (p - centre)."""
        Q, c = np.asarray(rotation, dtype=float), np.asarray(centre, dtype=float).reshape(3)
        return DistanceField(self.coefficients, self.lower, self.spacing, self.name, Q @ self.rotation,
                             c + Q @ (self.offset - c), self.spares_ends)

    def rotated(self, axis, centre, theta_deg: float) -> DistanceField:
        """Turned by theta about an axis through centre (a forearm bone at elbow angle theta)."""
        return self.transformed(rotation_about(axis, theta_deg), centre)


def sampled_field(points: np.ndarray, triangles: np.ndarray, name: str, spacing: float = GRID_MM,
                  pad: float = PAD_MM) -> DistanceField:
    """The distance field of a closed triangle surface (points in the bone frame)."""
    import pyvista as pv
    from scipy.ndimage import spline_filter

    from persival.model.anatomy.overlap import _oriented_polydata

    lower = points.min(axis=0) - pad
    counts = np.ceil((points.max(axis=0) + pad - lower) / spacing).astype(int) + 1
    axes = [lower[i] + spacing * np.arange(counts[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    probe = pv.PolyData(grid).compute_implicit_distance(_oriented_polydata(points, triangles))
    phi = np.asarray(probe.point_data["implicit_distance"], dtype=float).reshape(*counts)
    coefficients = spline_filter(phi, order=3, mode="mirror")
    return DistanceField(coefficients, lower, float(spacing), name)


def bone_fields(spec) -> dict[str, DistanceField]:
    """Every bone of a model with a drawn shape (not a plain tube) as a :class:`DistanceField`
    in arm coordinates, forearm bones at theta = 0. Built once per model and kept in the cache
    folder next to the bones' surfaces (persival.model.anatomy.bone_shapes.cached_bone_arrays)."""
    from persival.model.anatomy.bone_shapes import SHAPES_VERSION, bone_shapes, cached_bone_arrays

    shaped = [b.name for b in spec.bones if b.drawn_shape().kind != "tube"]
    if not shaped:
        return {}

    def build() -> dict[str, np.ndarray]:
        surfaces = bone_shapes(spec)
        fields = [sampled_field(*surfaces[name], name) for name in shaped]
        return {f"{f.name}/{part}": np.asarray(value) for f in fields
                for part, value in (("coefficients", f.coefficients), ("lower", f.lower), ("spacing", f.spacing))}

    data = cached_bone_arrays(spec, "-fields", [SHAPES_VERSION, FIELDS_VERSION, GRID_MM, PAD_MM], build)
    return {name: DistanceField(data[f"{name}/coefficients"], data[f"{name}/lower"], float(data[f"{name}/spacing"]), name)
            for name in shaped}
