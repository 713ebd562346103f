"""Spatially adaptive refinement of a B-spline boundary sparse grid (docs/theory.md, 5.5, "beyond
the paper").

Follows SG++'s surplus-based refinement for boundary grids (``HashRefinementBoundaries`` with
a ``SurplusRefinementFunctor``):

* a point is *refinable* if at least one of its hierarchical children is missing;
* the refinable points with the largest indicator |surplus| are refined;
* refining a point adds, in every dimension t, its children there: level 0 (boundary) ->
  the level-1 midpoint (l=1, i=1); level l >= 1 -> (l+1, 2i-1) and (l+1, 2i+1);
* every new point brings its missing hierarchical ancestors (level l >= 2 -> parent
  (l-1, (i >> 1) | 1); level 1 -> both boundary points (0,0), (0,1); level 0 -> its twin
  boundary point), recursively, so the grid stays consistent.

For vector outputs the indicator is a norm of the surplus row across outputs (``norm="l2"``
by default, ``"max"`` for the largest absolute entry). Outputs with very different scales
should be scaled by the caller (or via ``output_scale``) first, since the norm mixes them.

Only the new points are simulated; values of existing points are kept.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from persival.surrogate.sparse_grid import SparseGrid

__all__ = [
    "AdaptiveResult",
    "initial_grid",
    "RefinementStep",
    "consistent_closure",
    "refine_adaptive",
    "refine_step",
    "surplus_indicator",
]

Simulator = Callable[[np.ndarray], np.ndarray]

_Key = tuple  # (l_1..l_d, i_1..i_d)


def _keys(levels: np.ndarray, indices: np.ndarray) -> list[_Key]:
    return [tuple(r) for r in np.concatenate([levels, indices], axis=1).tolist()]


def _ancestors(key: _Key, dim: int) -> list[_Key]:
    """Direct hierarchical ancestors of one point, as SG++'s boundary refinement creates them."""
    out = []
    lv, ix = list(key[:dim]), list(key[dim:])
    for t in range(dim):
        l, i = lv[t], ix[t]
        if l >= 2:
            cand = [(l - 1, (i >> 1) | 1)]
        elif l == 1:
            cand = [(0, 0), (0, 1)]
        else:  # SG++ keeps both level-0 functions of a direction together
            cand = [(0, 1 - i)]
        for lp, ip in cand:
            lv2, ix2 = lv.copy(), ix.copy()
            lv2[t], ix2[t] = lp, ip
            out.append(tuple(lv2) + tuple(ix2))
    return out


def _children(key: _Key, dim: int) -> list[_Key]:
    out = []
    lv, ix = list(key[:dim]), list(key[dim:])
    for t in range(dim):
        l, i = lv[t], ix[t]
        cand = [(1, 1)] if l == 0 else [(l + 1, 2 * i - 1), (l + 1, 2 * i + 1)]
        for lc, ic in cand:
            lv2, ix2 = lv.copy(), ix.copy()
            lv2[t], ix2[t] = lc, ic
            out.append(tuple(lv2) + tuple(ix2))
    return out


def _close(new: list[_Key], present: set[_Key], dim: int) -> list[_Key]:
    """``new`` plus all their missing ancestors (recursively), none of them in ``present``."""
    added: list[_Key] = []
    seen = set(present)
    stack = list(new)
    while stack:
        k = stack.pop()
        if k in seen:
            continue
        seen.add(k)
        added.append(k)
        stack.extend(a for a in _ancestors(k, dim) if a not in seen)
    # Coarse points first: a stable, level-sorted order is easier to read and to debug.
    added.sort(key=lambda k: (sum(k[:dim]), k))
    return added


def consistent_closure(levels, indices) -> tuple[np.ndarray, np.ndarray]:
    """The given points plus every missing hierarchical ancestor (original rows first)."""
    levels = np.asarray(levels, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    dim = levels.shape[1]
    keys = _keys(levels, indices)
    present = set(keys)
    missing: set[_Key] = set()
    for k in keys:
        missing.update(a for a in _ancestors(k, dim) if a not in present)
    extra = _close(sorted(missing), present, dim)
    if not extra:
        return levels.copy(), indices.copy()
    arr = np.array(extra, dtype=np.int64)
    return (
        np.concatenate([levels, arr[:, :dim]]),
        np.concatenate([indices, arr[:, dim:]]),
    )


def surplus_indicator(grid: SparseGrid, norm: str = "l2", output_scale=None) -> np.ndarray:
    """|surplus| per grid point; for vector outputs a norm across outputs (see module doc)."""
    c = np.asarray(grid.surpluses, dtype=np.float64)
    if c.ndim == 1:
        return np.abs(c)
    if output_scale is not None:
        c = c / np.asarray(output_scale, dtype=np.float64)
    if _check_norm(norm) == "l2":
        return np.linalg.norm(c, axis=1)
    return np.abs(c).max(axis=1)


def _check_norm(norm: str) -> str:
    if norm not in ("l2", "max"):
        raise ValueError(f"norm must be 'l2' or 'max', got {norm!r}")
    return norm


def initial_grid(dim: int, level: int, degree: int = 3) -> SparseGrid:
    """Start of a refinement: ``regular(level)`` for level >= 1; level 0 is the 2^dim corners
    (all coordinates on the boundary), the coarsest consistent boundary grid."""
    if level >= 1:
        return SparseGrid(dim, level, degree)
    if level != 0:
        raise ValueError(f"initial level must be >= 0, got {level}")
    corners = np.array(np.meshgrid(*[[0, 1]] * dim, indexing="ij")).reshape(dim, -1).T
    return SparseGrid.from_levels_indices(np.zeros_like(corners), corners, degree)


@dataclass
class RefinementStep:
    n_points: int  # grid size after the step
    n_new: int  # points simulated in this step
    max_indicator: float  # largest indicator among refinable points before the step


@dataclass
class AdaptiveResult:
    grid: SparseGrid  # fitted on all points
    values: np.ndarray  # simulated values, rows in the order of grid.points
    history: list[RefinementStep] = field(default_factory=list)
    stop_reason: str = ""


def _simulate(simulate: Simulator, pts: np.ndarray, n_out_shape: tuple) -> np.ndarray:
    v = np.asarray(simulate(pts.copy()))
    if v.shape[:1] != (pts.shape[0],) or v.ndim not in (1, 2):
        raise ValueError(
            f"simulate returned shape {v.shape} for {pts.shape[0]} points; expected "
            f"({pts.shape[0]},) or ({pts.shape[0]}, n_out)"
        )
    if n_out_shape and v.shape[1:] != n_out_shape:
        raise ValueError(f"simulate returned outputs of shape {v.shape[1:]}, earlier {n_out_shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("simulate returned NaN or inf")
    return v.astype(np.float64, copy=False)


def refine_step(
    grid: SparseGrid,
    values: np.ndarray,
    simulate: Simulator,
    n_refine: int,
    *,
    max_points: int | None = None,
    tol: float = 0.0,
    norm: str = "l2",
    output_scale=None,
    center: bool = False,
) -> tuple[SparseGrid, np.ndarray, RefinementStep]:
    """One SG++-style refinement: refine up to ``n_refine`` refinable points by indicator.

    Candidates whose new points (children plus ancestors) would push the grid beyond
    ``max_points`` are skipped, so the budget is never exceeded. Returns the refitted grid
    (same point order, new points appended), the extended values and a step record.
    """
    if not grid.is_fitted:
        raise RuntimeError("refine_step needs a fitted grid")
    dim = grid.dim
    keys = _keys(grid.levels, grid.indices)
    present = set(keys)
    ind = surplus_indicator(grid, norm, output_scale)
    refinable = np.array(
        [any(c not in present for c in _children(k, dim)) for k in keys], dtype=bool
    )
    cand = np.flatnonzero(refinable & (ind >= tol))
    cand = cand[np.argsort(-ind[cand], kind="stable")]
    max_ind = float(ind[refinable].max()) if refinable.any() else 0.0

    budget = np.inf if max_points is None else max_points
    new: list[_Key] = []
    taken = set(present)
    n_done = 0
    for j in cand:  # refinement bookkeeping, not evaluation: a loop over candidates is fine
        if n_done >= n_refine:
            break
        add = _close([c for c in _children(keys[j], dim) if c not in taken], taken, dim)
        if not add or len(taken) + len(add) > budget:
            continue
        new.extend(add)
        taken.update(add)
        n_done += 1

    if not new:
        return grid, values, RefinementStep(grid.n_points, 0, max_ind)
    arr = np.array(new, dtype=np.int64)
    new_grid = SparseGrid.from_levels_indices(
        np.concatenate([grid.levels, arr[:, :dim]]),
        np.concatenate([grid.indices, arr[:, dim:]]),
        grid.degree,
    )
    new_pts = np.asarray(new_grid.points[grid.n_points :])
    new_vals = _simulate(simulate, new_pts, values.shape[1:])
    all_vals = np.concatenate([values, new_vals])
    new_grid.fit(all_vals, center=center)
    return new_grid, all_vals, RefinementStep(new_grid.n_points, len(new), max_ind)


def refine_adaptive(
    simulate: Simulator,
    dim: int,
    *,
    max_points: int,
    degree: int = 3,
    initial_level: int = 1,
    tol: float = 0.0,
    refinements_per_step: int | None = None,
    norm: str = "l2",
    output_scale=None,
    center: bool = False,
    initial: tuple[SparseGrid, np.ndarray] | None = None,
) -> AdaptiveResult:
    """Grow a grid from :func:`initial_grid` (or ``initial`` = (grid, values)) until
    ``max_points`` is reached, no refinable point has indicator >= ``tol``, or nothing fits.

    ``simulate(points (k, dim)) -> (k,) or (k, n_out)`` is called once on the initial grid
    (unless ``initial`` is given) and then only on the points each step adds.
    ``refinements_per_step`` defaults to ~5 % of the current grid (at least 1): SG++ refines
    a fixed number per call; a fraction keeps the number of refits logarithmic.
    """
    if max_points < 1:
        raise ValueError("max_points must be >= 1")
    _check_norm(norm)  # before the first (possibly hours of) simulation
    if initial is None:
        grid = initial_grid(dim, initial_level, degree)
        if grid.n_points > max_points:
            raise ValueError(
                f"the initial regular grid already has {grid.n_points} > max_points={max_points} points"
            )
        values = _simulate(simulate, np.asarray(grid.points), ())
        grid.fit(values, center=center)
    else:
        grid, values = initial
        values = np.asarray(values, dtype=np.float64)
        if grid.dim != dim:
            raise ValueError(f"initial grid has dim {grid.dim}, expected {dim}")
        if not grid.is_fitted:
            grid.fit(values, center=center)
    res = AdaptiveResult(grid, values)
    while True:
        if grid.n_points >= max_points:
            res.stop_reason = "budget"
            break
        k = refinements_per_step or max(1, grid.n_points // 20)
        grid, values, step = refine_step(
            grid, values, simulate, k, max_points=max_points, tol=tol, norm=norm,
            output_scale=output_scale, center=center,
        )
        res.history.append(step)
        if step.n_new == 0:
            res.stop_reason = "tolerance" if step.max_indicator < tol else "budget"
            break
    res.grid, res.values = grid, values
    return res
