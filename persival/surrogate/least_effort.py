"""Least effort over five muscles whose moments are piecewise linear in their activations:
``min sum a^2`` subject to ``sum_m M_m(a_m) = required``, ``a`` in [0, 1]^5, for many rows at once
(docs/theory.md, 6.4). The motion-and-load model solves it on its grid of (angle, required moment)."""

from __future__ import annotations

import numpy as np

__all__ = ["least_effort"]


def _response(V, levels, lam):
    """Per-muscle argmin over [0, 1] of a^2 - lam M(a), M piecewise linear through the levels.

    V: (n, 5, J) moments at the levels. Each segment's quadratic has its minimum at the clipped
    stationary point lam s / 2; the muscle's minimum is the best segment (exact, also where M is
    not concave). Returns activations (n, 5) and moments (n, 5).
    """
    a0, a1 = levels[:-1], levels[1:]
    slope = np.diff(V, axis=2) / np.diff(levels)
    cand = np.clip(lam[:, None, None] * slope / 2.0, a0, a1)
    moment = V[:, :, :-1] + slope * (cand - a0)
    k = np.argmin(cand**2 - lam[:, None, None] * moment, axis=2)[:, :, None]
    return np.take_along_axis(cand, k, 2)[:, :, 0], np.take_along_axis(moment, k, 2)[:, :, 0]


def _moments_at(V, levels, a):
    """sum_m M_m(a_m) for activations a (n, 5), linear between the levels."""
    j = np.clip(np.searchsorted(levels, a, side="right") - 1, 0, len(levels) - 2)
    a0, a1 = levels[j], levels[j + 1]
    v0, v1 = np.take_along_axis(V, j[:, :, None], 2)[..., 0], np.take_along_axis(V, j[:, :, None] + 1, 2)[..., 0]
    return (v0 + (v1 - v0) * (a - a0) / (a1 - a0)).sum(axis=1)


def least_effort(V, levels, required, iterations: int = 90):
    """min sum a^2 s.t. sum_m M_m(a_m) = required, a in [0, 1]^5, vectorized (docs/theory.md, 6.4).

    Dual bisection on the multiplier lam (the per-muscle response is monotone in lam), then a
    bisection along the segment between the two last responses, which closes any duality gap
    left where a muscle's moment is not concave in a. Returns activations (n, 5) and feasible (n,):
    required in [sum_m min_a M_m, sum_m max_a M_m]; infeasible rows get the saturated best effort.
    """
    V, levels, R = np.asarray(V, float), np.asarray(levels, float), np.asarray(required, float)
    passive = V[:, :, 0].sum(axis=1)
    sign = np.where(R >= passive, 1.0, -1.0)
    lo, hi = np.full(len(R), -25.0), np.full(len(R), 25.0)  # lam = sign exp(t)
    for _ in range(iterations):
        t = 0.5 * (lo + hi)
        _, M = _response(V, levels, sign * np.exp(t))
        short = sign * (M.sum(axis=1) - R) < 0
        lo, hi = np.where(short, t, lo), np.where(short, hi, t)
    a_lo = _response(V, levels, sign * np.exp(lo))[0]
    a_hi = _response(V, levels, sign * np.exp(hi))[0]
    a_lo = np.where((sign * (passive - R) >= 0)[:, None], 0.0, a_lo)  # exactly at the passive moment
    w_lo, w_hi = np.zeros(len(R)), np.ones(len(R))
    for _ in range(50):
        w = 0.5 * (w_lo + w_hi)
        short = sign * (_moments_at(V, levels, a_lo + w[:, None] * (a_hi - a_lo)) - R) < 0
        w_lo, w_hi = np.where(short, w, w_lo), np.where(short, w_hi, w)
    a = a_lo + w_hi[:, None] * (a_hi - a_lo)
    feasible = (R >= V.min(axis=2).sum(axis=1) - 1e-9) & (R <= V.max(axis=2).sum(axis=1) + 1e-9)
    return a, feasible
