"""Sparse direct solves of the tangent system: MKL PARDISO where available, SciPy otherwise.

The tangent keeps its sparsity pattern for a whole solve, so PARDISO's symbolic analysis
(fill-reducing ordering, the costly part of a first factorization) runs once per pattern and
every Newton iteration only refactorizes numerically (phase 22). pypardiso's public
``factorize`` repeats the analysis every time; we drive its phases directly for that reason.
The matrix is symmetric (hyperelastic tangent), so only the upper triangle is passed and
PARDISO's symmetric-indefinite LDL^T (mtype -2) is used: half the memory and about half the
flops of LU.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # pragma: no cover - depends on the platform
    import pypardiso as _pypardiso

    HAVE_PARDISO = True
except Exception:  # noqa: BLE001 - any import problem (no MKL) means: use SciPy
    _pypardiso = None
    HAVE_PARDISO = False


class SingularMatrixError(RuntimeError):
    """The tangent could not be factorized (a mechanism, or a singular tangent)."""


class SparseSymmetricSolver:
    """Factorize a symmetric sparse matrix given by its upper triangle (CSR), then solve.

    ``backend``: "pardiso", "scipy" or "auto" (PARDISO when importable).
    """

    def __init__(self, backend: str = "auto") -> None:
        if backend == "auto":
            backend = "pardiso" if HAVE_PARDISO else "scipy"
        if backend == "pardiso" and not HAVE_PARDISO:
            raise RuntimeError("pypardiso is not installed; use backend='scipy' or `pip install pypardiso`")
        if backend not in ("pardiso", "scipy"):
            raise ValueError(f"unknown sparse solver backend {backend!r}")
        self.backend = backend
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None
        self._upper: sp.csr_matrix | None = None
        self._lu = None
        if backend == "pardiso":
            self._pardiso = _pypardiso.PyPardisoSolver(mtype=-2)
            # iparm(11)/(13) (1-based): scaling and weighted matching help indefinite systems
            self._pardiso.set_iparm(11, 1)
            self._pardiso.set_iparm(13, 1)

    def factorize(self, upper: sp.csr_matrix) -> None:
        """Numerically factorize; the symbolic analysis is redone only when the pattern changes."""
        if not np.all(np.isfinite(upper.data)):
            raise SingularMatrixError("tangent matrix contains NaN or inf")
        self._upper = upper
        if self.backend == "pardiso":
            solver = self._pardiso
            solver._check_A(upper)
            b = np.zeros((upper.shape[0], 1))
            try:
                if not self._same_pattern(upper):
                    solver.set_phase(11)
                    solver._call_pardiso(upper, b)
                    self._pattern = (upper.indptr.copy(), upper.indices.copy())
                solver.set_phase(22)
                solver._call_pardiso(upper, b)
            except Exception as exc:  # PyPardisoError
                self._pattern = None
                raise SingularMatrixError(f"PARDISO factorization failed: {exc}") from exc
        else:
            full = upper + sp.triu(upper, k=1).T
            try:
                self._lu = spla.splu(full.tocsc(), permc_spec="COLAMD")
            except RuntimeError as exc:
                raise SingularMatrixError(f"SuperLU factorization failed: {exc}") from exc

    def _same_pattern(self, upper: sp.csr_matrix) -> bool:
        if self._pattern is None:
            return False
        indptr, indices = self._pattern
        return np.array_equal(indptr, upper.indptr) and np.array_equal(indices, upper.indices)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self._upper is None:
            raise RuntimeError("factorize() must be called before solve()")
        if self.backend == "pardiso":
            solver = self._pardiso
            solver.set_phase(33)
            x = solver._call_pardiso(self._upper, np.asfortranarray(rhs, dtype=float))
        else:
            x = self._lu.solve(np.asarray(rhs, dtype=float))
        if not np.all(np.isfinite(x)):
            raise SingularMatrixError("linear solve produced NaN or inf (singular tangent?)")
        return x
