"""Points of SG++'s regular boundary sparse grid (docs/theory.md, 5.2), without the B-spline basis.

Two stages need them: a campaign solves the FE model at these points (persival.campaign.design)
and the surrogate interpolates there (persival.surrogate.sparse_grid). The enumeration lives
here, below both, so that the campaign stage does not import the surrogate stage.
"""

from __future__ import annotations

import numpy as np

__all__ = ["regular_levels_indices", "level_index_points"]


def _regular_level_vectors(dim: int, n: int) -> list[tuple[int, ...]]:
    """Level vectors of SG++'s regular boundary grid: sum_t max(l_t, 1) <= n + dim - 1.

    Boundary level 0 counts as 1 (SG++'s ``boundaryLevel = 1``), so the boundary points ride
    along with every subspace whose level is 1 in that direction (docs/theory.md, 5.2).
    Recursive enumeration instead of a product over (n+1)^dim candidates keeps large dim cheap.
    """
    out: list[tuple[int, ...]] = []

    def rec(prefix: tuple[int, ...], budget: int) -> None:
        remaining = dim - len(prefix)
        if remaining == 0:
            out.append(prefix)
            return
        for lev in range(0, n + 1):
            cost = max(lev, 1)
            if budget - cost >= remaining - 1:  # every later dim costs at least 1
                rec(prefix + (lev,), budget - cost)

    rec((), n + dim - 1)
    return out


def _indices_1d(level: int) -> np.ndarray:
    if level == 0:
        return np.array([0, 1], dtype=np.int64)
    return np.arange(1, 2**level, 2, dtype=np.int64)


def regular_levels_indices(dim: int, level: int) -> tuple[np.ndarray, np.ndarray]:
    """(levels, indices), both (N, dim) int64, of ``regular(level)`` in SG++'s point order."""
    if dim < 1:
        raise ValueError(f"dim must be >= 1, got {dim}")
    if level < 1:
        raise ValueError(f"level must be >= 1 (SG++ boundary grids start at 1), got {level}")
    blocks_l, blocks_i = [], []
    for lv in _regular_level_vectors(dim, level):
        grids = np.meshgrid(*[_indices_1d(lt) for lt in lv], indexing="ij")
        idx = np.stack([g.ravel() for g in grids], axis=1)
        blocks_i.append(idx)
        blocks_l.append(np.broadcast_to(np.array(lv, dtype=np.int64), idx.shape))
    return np.concatenate(blocks_l), np.concatenate(blocks_i)


def level_index_points(levels: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Coordinates x = i * 2^-l of grid points in [0, 1]^dim.

    Level 0 has h = 1 (SG++ shifts 1 << 0 = 1), so the formula holds for the boundary too.
    """
    return np.asarray(indices) * np.ldexp(1.0, -np.asarray(levels))
