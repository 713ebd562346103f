"""The 1-D cardinal B-spline b^p and its derivative, exact piecewise polynomials evaluated by
Horner's scheme per piece (docs/theory.md 5.1): the building block of the sparse grid's basis."""

from __future__ import annotations

import math
from fractions import Fraction
from functools import cache

import numpy as np

__all__ = ["cardinal_bspline", "cardinal_bspline_dx"]


@cache
def _piece_coefficients(p: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of b^p on each unit interval [k, k+1] as polynomials in t = x - k.

    Derived once, exactly (rational arithmetic), from the truncated-power formula
    ``b^p(x) = 1/p! sum_j (-1)^j C(p+1, j) (x - j)_+^p``. Evaluating that formula directly
    would cancel digits for large p; per-piece Horner does not.
    Returns (values, derivatives), both (p+1, p+1) with column r = coefficient of t^r.
    """
    vals = np.zeros((p + 1, p + 1))
    ders = np.zeros((p + 1, p + 1))
    for k in range(p + 1):
        coef = [Fraction(0)] * (p + 1)
        for j in range(k + 1):
            w = Fraction((-1) ** j * math.comb(p + 1, j), math.factorial(p))
            for r in range(p + 1):
                coef[r] += w * math.comb(p, r) * Fraction(k - j) ** (p - r)
        vals[k] = [float(c) for c in coef]
        ders[k, : p] = [float(r * coef[r]) for r in range(1, p + 1)]
    return vals, ders


def _eval_pieces(y: np.ndarray, p: int, table: np.ndarray, left: np.ndarray | None = None) -> np.ndarray:
    # Support is [0, p+1]; outside it the spline is identically zero, which the mask enforces
    # (the clipped piece index would otherwise extrapolate the end polynomials).
    k = np.floor(y)
    if left is not None:  # left-sided pieces where asked (derivatives at the domain's right end)
        k = np.where(left, np.ceil(y) - 1, k)
    inside = (k >= 0) & (k <= p)
    k = np.clip(k, 0, p).astype(np.intp)
    t = y - k
    c = table[k]  # (..., p+1) coefficient rows, one per argument
    out = c[..., p].copy()
    for r in range(p - 1, -1, -1):  # Horner over the degree, not over points
        out *= t
        out += c[..., r]
    out[~inside] = 0.0
    return out


def cardinal_bspline(y: np.ndarray, p: int) -> np.ndarray:
    """Cardinal B-spline b^p (support [0, p+1]) at y, vectorized (docs/theory.md, 5.1)."""
    return _eval_pieces(np.asarray(y, dtype=np.float64), p, _piece_coefficients(p)[0])


def cardinal_bspline_dx(y: np.ndarray, p: int, left: np.ndarray | None = None) -> np.ndarray:
    """Derivative of b^p at y. At the knots, where only p = 1 has a jump, it is right-sided,
    or left-sided where the boolean mask ``left`` (broadcastable to y) is set."""
    return _eval_pieces(np.asarray(y, dtype=np.float64), p, _piece_coefficients(p)[1], left)
