"""The elbow's moment balance as a smooth function of (theta, alpha, load), and its stable root.

Each muscle's hinge moment ``M_m(theta, a_m)`` is interpolated from its FE response table:
cubic Hermite in theta through the tabulated values and slopes dM/dtheta (the FE path's own
interpolation, with slopes that disagree with the values replaced: :func:`consistent_slopes`),
an interpolating cubic spline in the activation. Gravity (forearm, hand and the
load in the hand) and the passive joint moment are analytic; they join the balance through
the same Hermite interpolation of their exact values and slopes at the table angles (its error,
below 1e-3 N mm on 5-degree steps, moves the root by less than 1e-5 deg), so that on every table
interval the whole balance is one cubic polynomial in theta. The elbow angle is its stable root
(the balance turns from flexing to extending) nearest the hanging arm's angle, as on the FE path
(docs/theory.md 3.7 and 7.7).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from persival.model.arm.external_moments import ExternalMoments
from persival.surrogate.structured.cardinal import hermite_weights, spline_weights
from persival.vocabulary import MUSCLES

__all__ = ["MomentModel", "consistent_slopes", "ROOT_GRID_DEG", "NEWTON_SLOPE_CAP", "NEWTON_STEPS"]

ROOT_GRID_DEG = 0.5  # largest spacing of the sign scan that brackets the stable root
# Newton steps on the bracket's cubic after regula falsi: the start is within 7e-3 deg, the
# first step brings it within 9e-6 deg, the second to 1e-11 (quadratic convergence; quick arm,
# 300 random activations, docs/theory.md 7.7)
NEWTON_STEPS = 2
# a Newton step divides by min(slope, this): where the balance does not descend (no Newton step
# towards the stable root) the step leaves the bracket and is cut back to its end on the root's side
NEWTON_SLOPE_CAP = -1e-12


class MomentModel:
    """``g(theta) = sum_m M_m(theta, a_m) + gravity(theta, load) + joint(theta)`` and its root.

    ``angles_deg`` (n_t,), ``levels`` (n_a,), ``moments`` and ``slopes`` (5, n_t, n_a): the
    tabulated M_m (N mm) and dM_m/dtheta (N mm per radian, as the tables store it).
    ``near_deg``: the hanging arm's angle (which stable root to take).
    """

    def __init__(self, angles_deg, levels, moments, slopes, external: ExternalMoments, near_deg: float):
        self.angles_deg = np.asarray(angles_deg, dtype=float)
        self.levels = np.asarray(levels, dtype=float)
        moments, slopes = np.asarray(moments, dtype=float), np.asarray(slopes, dtype=float)
        if not (np.isfinite(moments).all() and np.isfinite(slopes).all()):
            raise ValueError("the moment table has failed solves (NaN) inside the angles given: cut it to its finite range")
        # (5, 2 n_t, n_a): values, then slopes per degree, for the Hermite weights in theta
        self.data = np.concatenate([moments, slopes * (np.pi / 180.0)], axis=1)
        self.external = external
        t = self.angles_deg
        # the external moments' Hermite data: at no load, and per kg in the hand
        self.external_data = np.concatenate([external.value(t), external.slope(t)])
        self.load_data = np.concatenate([external.value(t, 1.0), external.slope(t, 1.0)]) - self.external_data
        self.near_deg = float(near_deg)
        self.theta_basis = hermite_weights(t)
        self.activation_basis = spline_weights(self.levels)
        self.scan_deg, self.scan_interval = _scan_grid(t, ROOT_GRID_DEG)
        self.scan_weights = self.theta_basis.weights(self.scan_deg)  # (n_g, 2 n_t): once, not per root search

    @classmethod
    def from_table(cls, table, spec, near_deg: float) -> MomentModel:
        """From a :class:`~persival.tables.moment_table.MomentTable`, cut to its finite range, its
        slopes checked against its values (:func:`consistent_slopes`)."""
        lo, hi = table.finite_range_deg()
        keep = (table.angles_deg >= lo) & (table.angles_deg <= hi)
        angles, moments = table.angles_deg[keep], table.moments[:, keep]
        slopes = consistent_slopes(np.radians(angles), moments, table.moment_slopes[:, keep])  # N mm per radian
        return cls(angles, table.levels, moments, slopes, ExternalMoments.of_arm(spec), near_deg)

    @property
    def range_deg(self) -> tuple[float, float]:
        return float(self.angles_deg[0]), float(self.angles_deg[-1])

    # ------------------------------------------------------------------ the balance
    def profile(self, activations, load_kg=0.0) -> np.ndarray:
        """(b, 2 n_t): the balance's Hermite data (values and slopes at the table angles) per state."""
        alpha = np.atleast_2d(np.asarray(activations, dtype=float))
        load = np.broadcast_to(np.asarray(load_kg, dtype=float), (len(alpha),))
        muscles = sum(self.activation_basis.weights(alpha[:, m]) @ self.data[m].T for m in range(len(MUSCLES)))
        return muscles + self.external_data + load[:, None] * self.load_data

    def muscle_moment(self, muscle: str, theta_deg, activation) -> np.ndarray:
        """M_m(theta, a) in N mm (broadcast over theta and a)."""
        theta, a = np.broadcast_arrays(np.atleast_1d(theta_deg).astype(float), np.atleast_1d(activation).astype(float))
        d = self.data[MUSCLES.index(muscle)]
        return np.einsum("bk,kj,bj->b", self.theta_basis.weights(theta), d, self.activation_basis.weights(a))

    def residual(self, theta_deg, activations, load_kg=0.0) -> np.ndarray:
        """g (N mm) at theta (b,) for activations (b, 5); > 0 turns the forearm towards flexion."""
        theta = np.atleast_1d(np.asarray(theta_deg, dtype=float))
        return np.einsum("bk,bk->b", self.theta_basis.weights(theta), self.profile(activations, load_kg))

    def slope(self, theta_deg, activations, load_kg=0.0) -> np.ndarray:
        """dg/dtheta (N mm per degree)."""
        theta = np.atleast_1d(np.asarray(theta_deg, dtype=float))
        return np.einsum("bk,bk->b", self.theta_basis.derivative_weights(theta), self.profile(activations, load_kg))

    # ------------------------------------------------------------------ the root
    def bracket(self, profile: np.ndarray) -> np.ndarray:
        """Per state the scan interval k holding the stable root nearest ``near_deg`` (g > 0 at
        its start, g <= 0 at its end); without one, the end interval the balance pushes to."""
        g = profile @ self.scan_weights.T
        down = (g[:, :-1] > 0) & (g[:, 1:] <= 0)
        distance = np.where(down, np.abs(self.scan_deg[:-1] - self.near_deg)[None, :], np.inf)
        k = np.argmin(distance, axis=1)
        none = ~down.any(axis=1)
        k[none & (g[:, 0] > 0)] = len(self.scan_deg) - 2  # flexes everywhere: pressed to the upper end
        k[none & (g[:, 0] <= 0)] = 0
        return k

    def equilibrium(self, activations, load_kg=0.0) -> np.ndarray:
        """The elbow angle (b,) deg: the bracketed stable root by regula falsi and Newton steps
        on the bracket's cubic, kept inside the bracket (the exported graph runs the same steps)."""
        profile = self.profile(activations, load_kg)
        k = self.bracket(profile)
        lo, hi = self.scan_deg[k], self.scan_deg[k + 1]
        g_lo, g_hi = (np.einsum("bk,bk->b", self.theta_basis.weights(t), profile) for t in (lo, hi))
        falls = g_lo > g_hi
        theta = np.where(falls, lo + (hi - lo) * g_lo / np.where(falls, g_lo - g_hi, 1.0), np.where(g_lo > 0, hi, lo))
        for _ in range(NEWTON_STEPS):
            g = np.einsum("bk,bk->b", self.theta_basis.weights(theta), profile)
            dg = np.einsum("bk,bk->b", self.theta_basis.derivative_weights(theta), profile)
            theta = np.clip(theta - g / np.minimum(dg, NEWTON_SLOPE_CAP), lo, hi)
        return theta

    def reference_root(self, activations, load_kg: float = 0.0) -> float:
        """One state's root by Brent's method inside the same bracket (for checks)."""
        alpha = np.atleast_2d(np.asarray(activations, dtype=float))
        k = int(self.bracket(self.profile(alpha, load_kg))[0])
        lo, hi = float(self.scan_deg[k]), float(self.scan_deg[k + 1])
        f = lambda t: float(self.residual(t, alpha, load_kg)[0])  # noqa: E731
        if f(lo) <= 0 or f(hi) > 0:  # no sign change: the balance pushes past this end
            return lo if f(lo) <= 0 else hi
        return brentq(f, lo, hi, xtol=1e-13, rtol=1e-15)

    # ------------------------------------------------------------------ folder
    def arrays(self) -> dict:
        return {"angles_deg": self.angles_deg, "levels": self.levels, "moment_data": self.data}

    def parameters(self) -> dict:
        return {"near_deg": self.near_deg, "external": self.external.as_dict()}

    @classmethod
    def from_arrays(cls, arrays: dict, parameters: dict) -> MomentModel:
        n_t = len(arrays["angles_deg"])
        data = arrays["moment_data"]
        external = ExternalMoments.from_dict(parameters["external"])
        return cls(arrays["angles_deg"], arrays["levels"], data[:, :n_t], data[:, n_t:] * (180.0 / np.pi), external,
                   parameters["near_deg"])


def consistent_slopes(angles: np.ndarray, values: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """The FE slopes (axis 1: the angles; per unit of ``angles``) where they agree with the
    tabulated values, else the monotone (PCHIP) slopes of those values (docs/theory.md 7.7, "Slopes").

    A slope agrees when the Hermite pieces on either side stay in the Fritsch-Carlson region of
    the neighbouring secants s_l and s_r: of their sign and at most 3 min(|s_l|, |s_r|) where they
    share one, at most max(|s_l|, |s_r|) where they do not (an extremum between them). Where a
    muscle slides along a wall its contact set changes between table angles and the moment has
    kinks: its slope at a table angle says little about the next 5 degrees, and a Hermite piece
    through it overshoots by hundreds of N mm.
    """
    from scipy.interpolate import PchipInterpolator

    h = np.diff(angles)[None, :, None]
    secant = np.diff(values, axis=1) / h
    left = np.concatenate([secant[:, :1], secant], axis=1)  # at the ends: the one secant twice
    right = np.concatenate([secant, secant[:, -1:]], axis=1)
    same_sign = left * right > 0
    agrees = np.where(same_sign, (slopes * left >= 0) & (np.abs(slopes) <= 3.0 * np.minimum(np.abs(left), np.abs(right))),
                      np.abs(slopes) <= np.maximum(np.abs(left), np.abs(right)))
    monotone = PchipInterpolator(angles, values, axis=1).derivative()(angles)
    return np.where(agrees, slopes, monotone)


def _scan_grid(knots: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The sign scan's angles (every table angle, each interval cut into equal steps of at most
    ``spacing``) and, per scan interval, the table interval it lies in."""
    grid, interval = [], []
    for i, (a, b) in enumerate(zip(knots[:-1], knots[1:])):
        n = int(np.ceil((b - a) / spacing - 1e-9))
        grid.append(a + (b - a) * np.arange(n) / n)
        interval.append(np.full(n, i))
    return np.concatenate(grid + [knots[-1:]]), np.concatenate(interval)
