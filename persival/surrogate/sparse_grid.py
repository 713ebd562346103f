"""Hierarchical B-spline sparse-grid interpolation with SG++'s boundary basis (docs/theory.md, section 5).

The grid, the basis and therefore the interpolant are those of SG++'s
``Grid.createBsplineBoundaryGrid(d, p, 1)`` with ``regular(n)``; the fixture
``sgpp_bspline_boundary_d5_p3_l2.npz`` pins this down to about 1e-10.

Evaluation is deliberately *not* SG++'s point-by-point loop over grid points: a batch of
evaluation points becomes one basis matrix ``B(x)`` (m x N) and the result is the single
matrix product ``B(x) @ C`` with the coefficient matrix C (N x n_out). All outputs (e.g. every
surface node of a muscle) then cost one streaming pass over C, which is what makes a whole
surface state sub-millisecond.

One module on purpose (a numerical kernel over 300 lines): the grid's index arithmetic, the
B-spline basis and the hierarchization share their level/index tables, and SG++ exactness is
checked on them together (tests/surrogate/test_sparse_grid*.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from persival.grid_points import level_index_points, regular_levels_indices
from persival.surrogate.bspline import cardinal_bspline, cardinal_bspline_dx

__all__ = ["SparseGrid", "cardinal_bspline", "cardinal_bspline_dx", "DOMAIN_TOL"]

#: Points this far outside [0, 1]^d are clipped silently (round-off from upstream scaling);
#: anything further out is an error, because a B-spline interpolant extrapolates badly.
DOMAIN_TOL = 1e-12

_FORMAT_VERSION = 1

# Up to this many grid points the interpolation matrix is built and factorized densely
# (8 N^2 bytes, 512 MB at the limit); above it, it is built sparse and factorized by SuperLU
# unless more than _SPARSE_MAX_DENSITY of it is nonzero.
_DENSE_MAX_POINTS = 8000
_SPARSE_MAX_DENSITY = 0.1

# Basis matrices are built in row blocks of at most this many entries (128 MB in float64).
_CHUNK_ENTRIES = 1 << 24

_SINGULAR_MSG = (
    "the interpolation matrix of this grid is (numerically) singular; an adaptive grid "
    "usually needs its hierarchical ancestors (see persival.surrogate.adaptive.consistent_closure)"
)


# --------------------------------------------------------------------------------------------
# Grid construction helpers
# --------------------------------------------------------------------------------------------
def _check_levels_indices(levels: np.ndarray, indices: np.ndarray) -> None:
    if levels.ndim != 2 or levels.shape != indices.shape or levels.shape[0] == 0:
        raise ValueError(
            f"levels and indices must be equal-shaped non-empty (N, dim) arrays, got "
            f"{levels.shape} and {indices.shape}"
        )
    if np.any(levels < 0) or np.any(levels > 60):
        raise ValueError("levels must lie in 0..60")
    lvl0 = levels == 0
    bad0 = lvl0 & (indices != 0) & (indices != 1)
    badl = ~lvl0 & ((indices % 2 == 0) | (indices < 1) | (indices >= (np.int64(1) << levels)))
    if np.any(bad0 | badl):
        r = int(np.argwhere(bad0 | badl)[0, 0])
        raise ValueError(
            f"invalid (level, index) in row {r}: levels {levels[r].tolist()}, indices "
            f"{indices[r].tolist()} (level 0 takes indices 0/1, level l>=1 odd 1..2^l-1)"
        )
    keys = np.concatenate([levels, indices], axis=1)
    if np.unique(keys, axis=0).shape[0] != keys.shape[0]:
        raise ValueError("duplicate grid points in (levels, indices)")


# --------------------------------------------------------------------------------------------
# The grid
# --------------------------------------------------------------------------------------------
class SparseGrid:
    """B-spline sparse grid with SG++'s boundary basis (docs/theory.md, section 5).

    Parameters
    ----------
    dim, level:
        Regular grid ``regular(level)`` in ``dim`` dimensions: a point with per-dimension
        levels l_t is in the grid iff ``sum_t max(l_t, 1) <= level + dim - 1``.
    degree:
        Odd B-spline degree p (1 = piecewise linear hats, 3 = the paper's cubic, 5, ...).

    After :meth:`fit`, :meth:`predict` and :meth:`gradient` evaluate the interpolant.

    >>> grid = SparseGrid(dim=5, level=2)  # the paper's grid: 3^5 + 5 * 2 * 3^4 points
    >>> grid.n_points
    1053
    >>> x = grid.points
    >>> grid = grid.fit(np.sin(x[:, 0]) + x[:, 1] * x[:, 2])
    >>> float(np.abs(grid.predict(x) - (np.sin(x[:, 0]) + x[:, 1] * x[:, 2])).max()) < 1e-12  # interpolates
    True
    >>> centre = np.full((1, 5), 0.5)
    >>> round(float(grid.predict(centre)[0]), 6), round(float(np.sin(0.5) + 0.25), 6)
    (0.729426, 0.729426)
    >>> grid.gradient(centre).round(3)  # d/dx of the interpolant, one row per point
    array([[0.845, 0.477, 0.477, 0.   , 0.   ]])
    """

    def __init__(self, dim: int, level: int, degree: int = 3) -> None:
        dim, level, degree = _as_int(dim, "dim"), _as_int(level, "level"), _check_degree(degree)
        levels, indices = regular_levels_indices(dim, level)
        self._init(levels, indices, degree, level)

    @classmethod
    def from_levels_indices(
        cls, levels: Any, indices: Any, degree: int = 3
    ) -> SparseGrid:
        """Grid from explicit SG++-convention (levels, indices) arrays, e.g. an adaptive grid.

        The rows define the point order. No consistency (presence of hierarchical ancestors)
        is required here, but without it the interpolation matrix may be singular, which
        :meth:`fit` reports.
        """
        levels = np.array(levels, dtype=np.int64, copy=True)
        indices = np.array(indices, dtype=np.int64, copy=True)
        _check_levels_indices(levels, indices)
        obj = cls.__new__(cls)
        obj._init(levels, indices, _check_degree(degree), None)
        return obj

    def _init(self, levels: np.ndarray, indices: np.ndarray, degree: int, level: int | None):
        self.levels = np.ascontiguousarray(levels, dtype=np.int64)
        self.indices = np.ascontiguousarray(indices, dtype=np.int64)
        self.levels.setflags(write=False)
        self.indices.setflags(write=False)
        self.degree = degree
        self.level = level
        self.dim = int(self.levels.shape[1])
        self.points = level_index_points(self.levels, self.indices)
        self.points.setflags(write=False)

        # Distinct 1-D functions over all dimensions: the evaluation table is built for these
        # only (5 functions at level 2), and every grid point picks its factors from it.
        pairs = np.stack([self.levels.ravel(), self.indices.ravel()], axis=1)
        uniq, inverse = np.unique(pairs, axis=0, return_inverse=True)
        self._u_scale = np.ldexp(1.0, uniq[:, 0])  # 1 / h_l
        self._u_shift = (degree + 1) / 2.0 - uniq[:, 1]
        n_u = uniq.shape[0]
        code = inverse.reshape(self.levels.shape)
        # Column t of a grid point lives at t * n_u + code in the flattened (dim * n_u) table.
        self._cols = [np.ascontiguousarray(code[:, t] + t * n_u, dtype=np.intp) for t in range(self.dim)]
        self._n_u = n_u

        self._solver = None
        self._coef: np.ndarray | None = None
        self._coef32: np.ndarray | None = None
        self._offset: np.ndarray | None = None  # per-output mean removed by fit(center=True)
        self._offset32: np.ndarray | None = None
        self._scalar_output = False

    # ---------------------------------------------------------------- properties
    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    def __len__(self) -> int:
        return self.n_points

    @property
    def is_fitted(self) -> bool:
        return self._coef is not None

    @property
    def surpluses(self) -> np.ndarray:
        """Hierarchical coefficients, (N,) or (N, n_out), in the order of ``.points``."""
        self._require_fit()
        c = self._coef[:, 0] if self._scalar_output else self._coef
        c = c.view()
        c.setflags(write=False)
        return c

    @property
    def offset(self) -> np.ndarray | None:
        """Per-output mean removed by ``fit(center=True)`` (None otherwise); ``.surpluses``
        then interpolate ``values - offset``."""
        return None if self._offset is None else self._offset.copy()

    @property
    def n_outputs(self) -> int:
        self._require_fit()
        return int(self._coef.shape[1])

    def __repr__(self) -> str:
        kind = f"level={self.level}" if self.level is not None else "adaptive"
        fit = f", n_out={self._coef.shape[1]}" if self._coef is not None else ", unfitted"
        return f"SparseGrid(dim={self.dim}, {kind}, degree={self.degree}, N={self.n_points}{fit})"

    # ---------------------------------------------------------------- basis
    def _table(self, x: np.ndarray, derivative: bool = False) -> np.ndarray:
        """1-D basis values phi_u(x_t) for every point, dim and distinct 1-D function u.

        phi_{l,i}(x) = b^p(x / h_l + (p+1)/2 - i), h_l = 2^-l, h_0 = 1 (docs/theory.md, 5.1).
        Returns (m, dim * n_u), flattened so a grid point's factor is a plain column take.
        """
        y = x[:, :, None] * self._u_scale + self._u_shift
        if derivative:
            # p = 1 has kinks at the knots; at x_t = 1 only the left side lies in the domain.
            left = (x == 1.0)[:, :, None] if self.degree == 1 else None
            t = cardinal_bspline_dx(y, self.degree, left) * self._u_scale  # d/dx = 1/h d/dy
        else:
            t = cardinal_bspline(y, self.degree)
        return t.reshape(x.shape[0], self.dim * self._n_u)

    def _basis_chunked(self, x: np.ndarray, dtype: np.dtype) -> np.ndarray:
        step = max(1, _CHUNK_ENTRIES // self.n_points)
        if x.shape[0] <= step:
            return self._basis(x, dtype)
        out = np.empty((x.shape[0], self.n_points), dtype=dtype)
        for r in range(0, x.shape[0], step):  # temporaries stay bounded
            out[r : r + step] = self._basis(x[r : r + step], dtype)
        return out

    def _basis(self, x: np.ndarray, dtype: np.dtype) -> np.ndarray:
        tab = self._table(x).astype(dtype, copy=False)
        out = np.take(tab, self._cols[0], axis=1)
        for cols in self._cols[1:]:  # loop over dimensions only
            out *= np.take(tab, cols, axis=1)
        return out

    def _basis_gradient(self, x: np.ndarray, dtype: np.dtype) -> np.ndarray:
        """dB/dx_s for every s, stacked as (dim * m, N) so that one matmul serves all s.

        Prefix/suffix products avoid dividing by factors that may be exactly zero.
        """
        tab = self._table(x).astype(dtype, copy=False)
        dtab = self._table(x, derivative=True).astype(dtype, copy=False)
        d, m = self.dim, x.shape[0]
        fac = [np.take(tab, c, axis=1) for c in self._cols]
        suffix: list[np.ndarray | None] = [None] * (d + 1)
        for t in range(d - 1, 0, -1):
            suffix[t] = fac[t] if suffix[t + 1] is None else fac[t] * suffix[t + 1]
        out = np.empty((d, m, self.n_points), dtype=dtype)
        prefix: np.ndarray | None = None
        for s in range(d):
            g = np.take(dtab, self._cols[s], axis=1)
            if prefix is not None:
                g *= prefix
            if suffix[s + 1] is not None:
                g *= suffix[s + 1]
            out[s] = g
            prefix = fac[s] if prefix is None else prefix * fac[s]
        return out.reshape(d * m, self.n_points)

    # ---------------------------------------------------------------- fitting
    def interpolation_matrix(self, sparse: bool = False):
        """A[r, j] = phi_j(x_r) over the grid points (B-splines are not nodal, docs/theory.md, 5.3).

        Dense (N, N) by default; ``sparse=True`` builds a CSC matrix row block by row block so
        that large grids never hold the dense matrix.
        """
        pts = np.asarray(self.points, dtype=np.float64)
        if not sparse:
            return self._basis_chunked(pts, np.dtype(np.float64))
        step = max(1, _CHUNK_ENTRIES // self.n_points)
        blocks = [
            scipy.sparse.csr_matrix(self._basis(pts[r : r + step], np.dtype(np.float64)))
            for r in range(0, self.n_points, step)  # row blocks, bounded memory
        ]
        return scipy.sparse.vstack(blocks, format="csc")

    def factorize(self) -> SparseGrid:
        """Factorize the interpolation matrix now (``fit`` does it on first use); returns self."""
        self._factorize()
        return self

    def _factorize(self):
        """Solver for A c = f, built once per grid and reused for every fit and output."""
        if self._solver is not None:
            return self._solver
        a_sparse = None
        if self.n_points > _DENSE_MAX_POINTS:
            a_sparse = self.interpolation_matrix(sparse=True)
        if a_sparse is None or a_sparse.nnz > _SPARSE_MAX_DENSITY * self.n_points**2:
            # Dense LAPACK LU: at the paper's grid (d=5, n=2, N=1053) A is 72 % nonzero;
            # measured 26 ms factorization + 0.41 s solve for 8428 outputs, vs 75 ms + 3.4 s
            # with SuperLU (docs/sparse_grid.md). Low-level grids in many dimensions stay
            # that dense at any size, where SuperLU's fill-in is worse than dense storage.
            a = self.interpolation_matrix() if a_sparse is None else a_sparse.toarray()
            del a_sparse
            lu, piv = scipy.linalg.lu_factor(a, overwrite_a=True, check_finite=False)
            _check_pivots(np.abs(np.diag(lu)), self.n_points)
            self._solver = lambda f: scipy.linalg.lu_solve((lu, piv), f, check_finite=False)
        else:
            # High levels in few dimensions: A is a few percent nonzero, SuperLU wins. The coarse
            # functions' wide supports make COLAMD fill in badly; minimum degree on A^T + A was
            # 5x faster at d=2, n=10 (N=13313).
            try:
                lu = scipy.sparse.linalg.splu(a_sparse, permc_spec="MMD_AT_PLUS_A")
            except MemoryError as exc:
                raise MemoryError(
                    f"SuperLU ran out of memory factorizing the {self.n_points}-point "
                    "interpolation matrix; use a smaller grid"
                ) from exc
            except RuntimeError as exc:  # SuperLU reports exact singularity this way
                raise RuntimeError(_SINGULAR_MSG) from exc
            _check_pivots(np.abs(lu.U.diagonal()), self.n_points)
            self._solver = lu.solve
        return self._solver

    def fit(self, values: Any, center: bool = False) -> SparseGrid:
        """Interpolate ``values`` (N,) or (N, n_out) given at ``.points``; returns self.

        Solves A c = f for all outputs with one LU factorization of A, kept for later fits
        on the same grid. Always float64: A's condition number grows with the level.

        ``center=True`` interpolates ``f - mean(f)`` per output and adds the mean back. SG++'s
        boundary B-splines of degree p >= 3 do not reproduce constants (docs/sparse_grid.md),
        so an output with a large offset and a small variation (an FE node position) carries
        an error proportional to the offset; centering makes it proportional to the
        variation. The default (False) is SG++'s interpolant exactly.
        """
        f = np.asarray(values)
        if f.dtype.kind not in "biuf":
            raise ValueError(f"values must be numeric, got dtype {f.dtype}")
        if f.ndim not in (1, 2):
            raise ValueError(f"values must be (N,) or (N, n_out), got shape {f.shape}")
        if f.shape[0] != self.n_points:
            raise ValueError(
                f"values has {f.shape[0]} rows but the grid has {self.n_points} points "
                "(give one row per grid point, in the order of .points)"
            )
        if f.ndim == 2 and f.shape[1] == 0:
            raise ValueError("values has zero output columns")
        if not np.all(np.isfinite(f)):
            raise ValueError("values contain NaN or inf")
        scalar = f.ndim == 1
        f2 = np.asarray(f, dtype=np.float64).reshape(self.n_points, -1)
        offset = f2.mean(axis=0) if center else None
        coef = self._factorize()(f2 - offset if center else f2)
        self._set_coefficients(coef, scalar, offset)
        return self

    def select_outputs(self, columns) -> SparseGrid:
        """The same grid interpolating only some outputs (no refit: their surpluses are copied).

        An int gives a scalar interpolant, a sequence a vector one. Evaluating one output of a
        wide fit this way reads one column of the coefficient matrix instead of all of them.
        """
        self._require_fit()
        scalar = np.ndim(columns) == 0
        cols = np.atleast_1d(np.asarray(columns, dtype=np.int64))
        sub = SparseGrid.from_levels_indices(self.levels, self.indices, self.degree)
        sub._set_coefficients(self._coef[:, cols], scalar, None if self._offset is None else self._offset[cols])
        return sub

    def _set_coefficients(self, coef: np.ndarray, scalar: bool, offset: np.ndarray | None) -> None:
        self._coef = np.ascontiguousarray(coef, dtype=np.float64)
        self._coef32 = None
        self._scalar_output = scalar
        self._offset = None if offset is None else np.asarray(offset, dtype=np.float64).reshape(-1)
        self._offset32 = None if offset is None else self._offset.astype(np.float32)

    def _coefficients(self, dtype: np.dtype) -> np.ndarray:
        if dtype == np.float64:
            return self._coef
        if self._coef32 is None:  # cast once, not per call: the cast costs more than the matmul
            self._coef32 = np.ascontiguousarray(self._coef, dtype=np.float32)
        return self._coef32

    # ---------------------------------------------------------------- evaluation
    def predict(self, x: Any, dtype: Any = np.float64) -> np.ndarray:
        """Interpolant at x (m, dim): (m,) for scalar fits, else (m, n_out).

        ``dtype=np.float32`` halves the memory traffic through the coefficient matrix (the
        bottleneck at batch 1) at ~1e-7 relative accuracy.
        """
        self._require_fit()
        dt = _check_dtype(dtype)
        x = self._check_x(x)
        c = self._coefficients(dt)
        step = max(1, _CHUNK_ENTRIES // self.n_points)
        if x.shape[0] <= step:
            out = self._basis(x, dt) @ c
        else:  # bound the (m, N) basis matrix for huge batches
            out = np.concatenate([self._basis(x[r : r + step], dt) @ c for r in range(0, x.shape[0], step)])
        if self._offset is not None:
            out += self._offset if dt == np.float64 else self._offset32
        return out[:, 0] if self._scalar_output else out

    def gradient(self, x: Any, dtype: Any = np.float64) -> np.ndarray:
        """Gradient w.r.t. x at x (m, dim): (m, dim) for scalar fits, else (m, n_out, dim)."""
        self._require_fit()
        dt = _check_dtype(dtype)
        x = self._check_x(x)
        c = self._coefficients(dt)
        step = max(1, _CHUNK_ENTRIES // (self.n_points * self.dim))
        parts = []
        for r in range(0, max(x.shape[0], 1), step):  # chunks of points, bounded memory
            xc = x[r : r + step]
            g = self._basis_gradient(xc, dt) @ c  # (dim * m, n_out): one matmul for all s
            parts.append(g.reshape(self.dim, xc.shape[0], c.shape[1]).transpose(1, 2, 0))
        g = parts[0] if len(parts) == 1 else np.concatenate(parts)  # (m, n_out, dim)
        return g[:, 0, :] if self._scalar_output else g

    __call__ = predict

    # ---------------------------------------------------------------- lookup
    def locate(self, points: Any) -> np.ndarray:
        """Row numbers of the given grid points in ``.points`` (order-independent matching).

        Useful to bring values computed in another order (e.g. SG++'s storage order) into
        this grid's order: ``values_ours = values_theirs[argsort(locate(points_theirs))]``.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != self.dim:
            raise ValueError(f"points must be (k, {self.dim}), got shape {p.shape}")
        scale = 2.0 ** int(self.levels.max())
        mine = np.rint(self.points * scale).astype(np.int64)
        theirs = np.rint(p * scale).astype(np.int64)
        if not np.allclose(theirs / scale, p, rtol=0, atol=1e-12):
            raise ValueError("some points are not on this grid's dyadic lattice")
        # Shared integer codes for both sets of rows; a grid row maps code -> its row number.
        _, inv = np.unique(np.concatenate([mine, theirs]), axis=0, return_inverse=True)
        inv = inv.ravel()
        lookup = np.full(inv.max() + 1, -1, dtype=np.intp)
        lookup[inv[: self.n_points]] = np.arange(self.n_points)
        rows = lookup[inv[self.n_points :]]
        if np.any(rows < 0):
            bad = int(np.argmax(rows < 0))
            raise ValueError(f"point {p[bad].tolist()} is not a point of this grid")
        return rows

    # ---------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> Path:
        """Write the fitted grid to one .npz (no pickles) and return its path."""
        self._require_fit()
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        np.savez(
            path,
            format_version=np.int64(_FORMAT_VERSION),
            kind=np.array("persival.SparseGrid"),
            dim=np.int64(self.dim),
            level=np.int64(-1 if self.level is None else self.level),
            degree=np.int64(self.degree),
            levels=self.levels,
            indices=self.indices,
            coefficients=self._coef,
            offset=np.zeros(0) if self._offset is None else self._offset,
            scalar_output=np.bool_(self._scalar_output),
        )
        return path

    @classmethod
    def load(cls, path: str | Path) -> SparseGrid:
        """Read a grid written by :meth:`save`; ready to predict (no refactorization)."""
        with np.load(Path(path), allow_pickle=False) as z:
            if "kind" not in z.files or str(z["kind"]) != "persival.SparseGrid":
                raise ValueError(f"{path} is not a saved persival SparseGrid")
            version = int(z["format_version"])
            if version > _FORMAT_VERSION:
                raise ValueError(f"{path} has format version {version}; this code reads <= {_FORMAT_VERSION}")
            obj = cls.from_levels_indices(z["levels"], z["indices"], int(z["degree"]))
            level = int(z["level"])
            obj.level = None if level < 0 else level
            coef = z["coefficients"]
            if coef.ndim != 2 or coef.shape[0] != obj.n_points:
                raise ValueError(f"{path}: coefficient array has shape {coef.shape}, expected ({obj.n_points}, n_out)")
            offset = z["offset"] if "offset" in z.files and z["offset"].size else None
            obj._set_coefficients(coef, bool(z["scalar_output"]), offset)
        return obj

    # ---------------------------------------------------------------- checks
    def _require_fit(self) -> None:
        if self._coef is None:
            raise RuntimeError("SparseGrid is not fitted: call .fit(values) first")

    def _check_x(self, x: Any) -> np.ndarray:
        x = np.asarray(x)
        if x.dtype.kind not in "biuf":
            raise ValueError(f"x must be numeric, got dtype {x.dtype}")
        if x.ndim != 2 or x.shape[1] != self.dim:
            hint = " (for one point use x[None, :])" if x.ndim == 1 and x.shape[0] == self.dim else ""
            raise ValueError(f"x must have shape (m, {self.dim}), got {x.shape}{hint}")
        x = np.asarray(x, dtype=np.float64)
        if x.size == 0:
            return x
        lo, hi = x.min(), x.max()
        if not (np.isfinite(lo) and np.isfinite(hi)):  # min/max propagate NaN; inf shows too
            raise ValueError("x contains NaN or inf")
        if lo < -DOMAIN_TOL or hi > 1.0 + DOMAIN_TOL:
            raise ValueError(
                f"x outside the domain [0, 1]^{self.dim} (min {lo:.6g}, max {hi:.6g}); scale "
                "inputs to the unit cube first"
            )
        if lo < 0.0 or hi > 1.0:
            x = np.clip(x, 0.0, 1.0)
        return x


def _check_pivots(diag: np.ndarray, n: int) -> None:
    if diag.size == 0 or not np.all(np.isfinite(diag)):
        raise RuntimeError(_SINGULAR_MSG)
    if diag.min() <= 1e3 * np.finfo(float).eps * n * max(diag.max(), 1.0):
        raise RuntimeError(_SINGULAR_MSG)


def _as_int(v: Any, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {v!r}")
    return int(v)


def _check_degree(p: Any) -> int:
    p = _as_int(p, "degree")
    if p < 1 or p % 2 == 0:
        # SG++ silently uses p - 1 for even p; an explicit error is less surprising.
        raise ValueError(f"degree must be a positive odd integer (1, 3, 5, ...), got {p}")
    return p


def _check_dtype(dtype: Any) -> np.dtype:
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype must be float32 or float64, got {dt}")
    return dt
