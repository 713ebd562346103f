"""Piecewise-cubic interpolation written as weights: ``f(x) = w(x) . data``.

An interpolant that is linear in its data (a cubic Hermite spline in its values and slopes, an
interpolating cubic spline in its values) is a sum of *cardinal* functions, one per datum, each a
piecewise cubic on the same breakpoints. Storing their power-form coefficients per interval turns
evaluation into one dense product, ``[indicator(x) * (t^3, t^2, t, 1)] @ C`` with ``t = x - x_i``:
no gather and no data-dependent control flow, so the same arithmetic runs in numpy, in PyTorch
and in an exported ONNX graph (docs/theory.md 7.7).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.interpolate import CubicHermiteSpline, CubicSpline

__all__ = ["PiecewiseCubic", "hermite_weights", "spline_weights"]


class PiecewiseCubic:
    """Cardinal functions on ``breaks`` (n_b,): ``coefficients`` (4, n_b - 1, n_data), the
    power-form coefficients of each datum's cardinal function on each interval (highest power
    first, in ``x - breaks[i]``; scipy's PPoly layout). Outside the breaks x is clamped."""

    def __init__(self, breaks: np.ndarray, coefficients: np.ndarray):
        self.breaks = np.asarray(breaks, dtype=float)
        self.coefficients = np.asarray(coefficients, dtype=float)
        if self.coefficients.shape[:2] != (4, len(self.breaks) - 1):
            raise ValueError(f"coefficients {self.coefficients.shape} do not fit {len(self.breaks)} breakpoints")

    @property
    def n_data(self) -> int:
        return self.coefficients.shape[2]

    def _locate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.clip(np.asarray(x, dtype=float), self.breaks[0], self.breaks[-1])
        i = np.clip(np.searchsorted(self.breaks, x, side="right") - 1, 0, len(self.breaks) - 2)
        return i, x - self.breaks[i]

    def weights(self, x) -> np.ndarray:
        """(n, n_data): f(x) = weights(x) @ data."""
        i, t = self._locate(np.atleast_1d(x))
        c = self.coefficients[:, i, :]  # (4, n, n_data)
        return ((c[0] * t[:, None] + c[1]) * t[:, None] + c[2]) * t[:, None] + c[3]

    def derivative_weights(self, x) -> np.ndarray:
        """(n, n_data): f'(x) = derivative_weights(x) @ data."""
        i, t = self._locate(np.atleast_1d(x))
        c = self.coefficients[:, i, :]
        return (3 * c[0] * t[:, None] + 2 * c[1]) * t[:, None] + c[2]

    # ------------------------------------------------------------------ the same in torch (exportable)
    def torch_tables(self, dtype=torch.float32) -> dict:
        """Constant tensors of :func:`torch_weights`: interval starts and ends and the coefficient
        rows (4 n_int, n_data) of the values and of the slopes, ordered power-major (row
        p * n_int + i: power 3 - p on interval i)."""
        c = self.coefficients  # (4, n_int, n_data)
        slope = np.stack([np.zeros_like(c[0]), 3 * c[0], 2 * c[1], c[2]])
        # half-open intervals, the last one closed (x is clamped to the breaks first): exactly one holds x
        hi = np.concatenate([self.breaks[1:-1], [np.inf]])
        return {"lo": torch.as_tensor(self.breaks[:-1], dtype=dtype), "hi": torch.as_tensor(hi, dtype=dtype),
                "first": float(self.breaks[0]), "last": float(self.breaks[-1]),
                "values": torch.as_tensor(c.reshape(-1, c.shape[2]), dtype=dtype),
                "slopes": torch.as_tensor(slope.reshape(-1, c.shape[2]), dtype=dtype)}


def torch_weights(tables: dict, x: torch.Tensor, slopes: bool = False) -> torch.Tensor:
    """Weights (b, n_data) at x (b, 1) (or their x-derivative with ``slopes``), by one product."""
    x = x.clamp(tables["first"], tables["last"])
    one = ((x >= tables["lo"]) & (x < tables["hi"])).to(x.dtype)
    t = (x - tables["lo"]) * one  # zero outside x's interval
    t2 = t * t
    return torch.cat([t2 * t, t2, t, one], dim=1) @ tables["slopes" if slopes else "values"]


def hermite_weights(knots) -> PiecewiseCubic:
    """Cubic Hermite interpolation: data = (values at the knots, slopes d/dx at the knots)."""
    knots = np.asarray(knots, dtype=float)
    n = len(knots)
    eye, zero = np.eye(n), np.zeros((n, n))
    values = CubicHermiteSpline(knots, eye, zero).c
    slopes = CubicHermiteSpline(knots, zero, eye).c
    return PiecewiseCubic(knots, np.concatenate([values, slopes], axis=2))


def spline_weights(knots) -> PiecewiseCubic:
    """The not-a-knot cubic spline through values at the knots (linear for two knots)."""
    knots = np.asarray(knots, dtype=float)
    n = len(knots)
    if n == 2:  # a line: its cardinal functions are the two hats
        h = knots[1] - knots[0]
        c = np.zeros((4, 1, 2))
        c[2, 0] = [-1 / h, 1 / h]
        c[3, 0] = [1.0, 0.0]
        return PiecewiseCubic(knots, c)
    spline = CubicSpline(knots, np.eye(n), bc_type="not-a-knot" if n > 3 else "natural")
    return PiecewiseCubic(knots, spline.c)
