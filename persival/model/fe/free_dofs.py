"""The tangent on the free degrees of freedom: its sparse factorization and what is solved with it.

A body's tangent K comes from the assembler as the upper triangle in one fixed sparsity pattern.
Newton needs ``K_ff`` (the rows and columns of the DOFs no constraint holds) factorized once per
iteration; a response to a motion of the constrained DOFs (a moment slope, du/dtheta) needs one
more solve with it. This module holds that linear algebra, apart from the Newton iteration and
the load stepping that use it (persival.model.fe.solver):

* ``K_ff`` as one persistent CSR object whose data is refreshed in place (the pattern is fixed,
  so the sparse solver's symbolic analysis and scipy's format checks run once);
* extra terms' tangents (contact) added into the fixed pattern, or beside it for contact between
  two bodies (``K.outside``);
* iterative refinement on a nearby factorization instead of a new one, where it contracts;
* the condensed response (Schur complement) to a motion of the constrained DOFs.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from persival.model.fe.assembly import symmetric_matvec
from persival.model.fe.linear_solver import SingularMatrixError, SparseSymmetricSolver

__all__ = ["FreeDofs"]


class FreeDofs:
    """The free DOFs of a body with pattern (rows, cols) of its upper-triangle tangent."""

    def __init__(self, pattern_rows: np.ndarray, pattern_cols: np.ndarray, constrained: np.ndarray,
                 backend: str = "auto") -> None:
        n = len(constrained)
        self.n_dofs = n
        self.free = np.flatnonzero(~constrained)
        free_index = np.full(n, -1, dtype=np.int64)
        free_index[self.free] = np.arange(len(self.free))
        r, c = pattern_rows, pattern_cols
        self._pattern_keys = r * n + c  # sorted (row-major): the position of each entry in K.data
        keep = (free_index[r] >= 0) & (free_index[c] >= 0)
        self._ff_take = np.flatnonzero(keep)
        rows_ff, cols_ff = free_index[r[keep]], free_index[c[keep]]
        nf = len(self.free)
        self._ff_indptr = np.concatenate([[0], np.cumsum(np.bincount(rows_ff, minlength=nf))]).astype(np.int32)
        self._ff_indices = cols_ff.astype(np.int32)
        self.linear_solver = SparseSymmetricSolver(backend)
        self._K_ff: sp.csr_matrix | None = None
        self.factor_is_recent = False  # the factorization is of a tangent of the current solve

    def free_upper(self, K: sp.csr_matrix) -> sp.csr_matrix:
        """K_ff (upper triangle) as one persistent CSR object whose data is refreshed in place:
        the pattern is fixed, so scipy's format checks run once."""
        if self._K_ff is None:
            n = len(self.free)
            self._K_ff = sp.csr_matrix((K.data[self._ff_take], self._ff_indices, self._ff_indptr), shape=(n, n))
        else:
            np.take(K.data, self._ff_take, out=self._K_ff.data)
        outside = getattr(K, "outside", None)
        if outside is None:
            return self._K_ff
        # couplings between bodies in contact (persival.model.arm.muscle_contact): a new pattern
        # whenever the contact pairs change (the sparse solver redoes its analysis then)
        merged = (self._K_ff + outside[self.free][:, self.free]).tocsr()
        merged.sort_indices()
        return merged

    def add_into(self, K: sp.csr_matrix, K_term, name: str, couples_bodies: bool = False) -> None:
        """Add the upper triangle of a term's tangent (n_dofs x n_dofs) into K.data in place;
        entries beside the FE pattern only for a term that ``couples_bodies`` (into ``K.outside``)."""
        C = sp.coo_matrix(K_term)
        upper = C.row <= C.col
        key = C.row[upper].astype(np.int64) * self.n_dofs + C.col[upper]
        pos = np.minimum(np.searchsorted(self._pattern_keys, key), len(self._pattern_keys) - 1)
        inside = self._pattern_keys[pos] == key
        if not inside.all() and not couples_bodies:
            raise ValueError(f"extra term {name} couples DOFs outside the finite-element pattern")
        np.add.at(K.data, pos[inside], C.data[upper][inside])
        if not inside.all():  # contact between two bodies: kept beside the FE pattern
            outside = sp.csr_matrix((C.data[upper][~inside], (C.row[upper][~inside], C.col[upper][~inside])),
                                    shape=K.shape)
            K.outside = outside if getattr(K, "outside", None) is None else K.outside + outside

    @staticmethod
    def matvec(K, x: np.ndarray) -> np.ndarray:
        """K x for the upper-triangle tangent, with any entries beside the FE pattern (``K.outside``)."""
        y = symmetric_matvec(K, x)
        outside = getattr(K, "outside", None)
        return y if outside is None else y + symmetric_matvec(outside, x)

    def factorize_and_solve(self, K, rhs, stats):
        """K_ff^-1 rhs by a fresh factorization; its time and count go to ``stats`` (NewtonStatistics)."""
        t0 = time.perf_counter()
        self.linear_solver.factorize(self.free_upper(K))
        t1 = time.perf_counter()
        x = self.linear_solver.solve(rhs)
        stats.time_factorization += t1 - t0
        stats.time_solve += time.perf_counter() - t1
        stats.n_factorizations += 1
        self.factor_is_recent = True
        return x

    def refined_solve(self, K: sp.csr_matrix, b: np.ndarray, rtol: float = 1e-10, steps: int = 4) -> np.ndarray | None:
        """K_ff x = b by iterative refinement on the current (nearby) factorization; None if it
        does not reach ``rtol`` within ``steps`` corrections or a correction does not halve the
        residual (the factorization is of a tangent too far from K: factorize instead)."""
        if not self.linear_solver.factorized:
            return None
        A = self.free_upper(K)  # only the matrix data: the factorization stays as it was
        try:
            x = self.linear_solver.solve(b)
            target = rtol * float(np.linalg.norm(b))
            previous = float(np.linalg.norm(b))
            for _ in range(steps):
                r = b - symmetric_matvec(A, x)
                size = float(np.linalg.norm(r))
                if size <= target:
                    return x
                if size > 0.5 * previous:
                    return None
                previous = size
                x = x + self.linear_solver.solve(r)
        except SingularMatrixError:
            return None
        return None

    def newton_direction(self, K, rhs, stats, rtol: float, reuse: bool) -> np.ndarray:
        """K_ff^-1 rhs: with ``reuse``, from the held factorization to ``rtol`` where the
        refinement contracts (an inexact Newton step, Dembo-Eisenstat-Steihaug: a relative linear
        residual below 1e-3 keeps the convergence superlinear), else factorized."""
        if reuse:
            t0 = time.perf_counter()
            x = self.refined_solve(K, rhs, rtol=rtol, steps=8)
            stats.time_solve += time.perf_counter() - t0
            if x is not None:
                stats.n_reused += 1
                self.factor_is_recent = True  # near enough for condensed_response to try it too
                return x
        return self.factorize_and_solve(K, rhs, stats)

    def condensed_response(self, K: sp.csr_matrix, g: np.ndarray, reuse_factorization: bool = False,
                           force_rate: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Stiffness along a motion ``s g`` of the constrained DOFs with the free DOFs
        re-equilibrated, the Schur complement ``g.K.g - (K g)_f . K_ff^-1 (K g)_f``, and the
        equilibrium's sensitivity du/ds (n_dofs,): g on the constrained DOFs, ``-K_ff^-1 (K g)_f``
        on the free ones (the same solve, so it comes free; a first-order predictor of the next
        state). K: the upper-triangle tangent of ``QuasiStaticSolver.tangent``, or of
        :meth:`Tet10Assembler.tangent` when there are no extra terms.

        ``reuse_factorization``: K is the ``tangent`` of the solution the solver just returned,
        so its last factorization is of the tangent one converged Newton step earlier; that one
        preconditions a few steps of iterative refinement against K instead of a factorization
        of its own (the biceps of the quick mesh: 0.10 s per factorization, 0.03 s per solve).
        Falls back to factorizing when the refinement stalls.

        ``force_rate``: the residual's own rate ds of change at fixed u (n_dofs,; e.g. obstacles
        moving with s, docs/theory.md, 3.5): the free DOFs then solve ``K_ff du_f = -(K g + df/ds)_f``,
        and the first value is still ``g . K du`` (the rate of the constrained DOFs' reaction
        along g)."""
        Kg = self.matvec(K, g)
        k_f = Kg[self.free]
        b = k_f if force_rate is None else k_f + np.asarray(force_rate, dtype=float)[self.free]
        x = self.refined_solve(K, b) if reuse_factorization and self.factor_is_recent else None
        if x is None:
            self.linear_solver.factorize(self.free_upper(K))
            x = self.linear_solver.solve(b)
        du = np.asarray(g, dtype=float).copy()
        du[self.free] = -x
        return float(g @ Kg - k_f @ x), du
