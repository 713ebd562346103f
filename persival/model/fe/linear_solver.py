"""Sparse direct solves of the tangent system: MKL PARDISO where available, SciPy otherwise.

The tangent keeps its sparsity pattern for a whole solve, so PARDISO's symbolic analysis
(fill-reducing ordering, the costly part of a first factorization) runs once per pattern and
every Newton iteration only refactorizes numerically (phase 22). pypardiso's public
``factorize`` repeats the analysis every time and re-converts the index arrays on every call;
we call MKL's pardiso through pypardiso's handle with index arrays converted once. That uses
pypardiso's private internals (``_mkl_pardiso``, ``_pt_type``, ``_check_A``, ``libmkl._name``,
``pardiso_wrapper.PyPardisoError``), so pyproject.toml pins pypardiso exactly; check them before
raising the pin (tests/model/test_linear_solver.py exercises each).
The matrix is symmetric (hyperelastic tangent), so only the upper triangle is passed. A
tangent at or near a stable equilibrium is positive definite, so Cholesky (mtype 2) is tried
first: on the quick biceps (13632 DOF) 37 ms per factorization and 3.4 ms per solve against
55 and 5.9 ms for the symmetric-indefinite LDL^T (mtype -2), same residual (2.5e-9). PARDISO
reports a non-positive pivot (error -4, checked on a tangent shifted past its lowest
eigenvalue), and the solver then takes LDL^T with Bunch-Kaufman pivoting for that tangent and
the next few (slack, bowed muscles stay indefinite for a while).
"""

from __future__ import annotations

import logging
import os
import warnings

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

log = logging.getLogger(__name__)


def _name_mkl_runtime() -> None:
    """Point pypardiso at MKL's runtime in this environment's lib/ when it is there.

    pypardiso finds it with ctypes' find_library (a compiler subprocess) and a recursive glob
    over sys.prefix, once at import and again for the first solver (2.6 s in the profile of a
    warm ``persival simulate``; naming it took the command from 8.3 to 6.9 s wall), in every
    process and dask worker. PYPARDISO_MKL_RT is its documented override; a path set by the
    user wins.
    """
    import glob
    import sys

    if "PYPARDISO_MKL_RT" not in os.environ:
        found = sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")), key=len)
        if found:
            os.environ["PYPARDISO_MKL_RT"] = found[0]


def _import_pardiso():
    """(the pypardiso module or None, why it is not there: None, "not installed" or the error).

    Not installed (the `fast` extra left out, or a platform without MKL) is an expected setup;
    installed but failing to import (MKL's runtime missing or broken: pypardiso loads it at
    import) is a fault, and its reason is kept for the warning instead of being swallowed.
    """
    try:
        import pypardiso
    except ModuleNotFoundError as exc:
        if exc.name == "pypardiso":
            return None, None
        return None, f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 - ImportError, OSError from ctypes (MKL), anything raised inside
        return None, f"{type(exc).__name__}: {exc}"
    return pypardiso, None


_name_mkl_runtime()
_pypardiso, PARDISO_IMPORT_ERROR = _import_pardiso()
HAVE_PARDISO = _pypardiso is not None
_fallback_reported = False


def _report_scipy_fallback() -> None:
    """Say once per process why backend="auto" takes SciPy: a log line when pypardiso is not
    installed, a RuntimeWarning with the reason when it is installed but broken."""
    global _fallback_reported
    if _fallback_reported:
        return
    _fallback_reported = True
    if PARDISO_IMPORT_ERROR is None:
        log.warning("pypardiso is not installed (pip install 'persival[fast]'): sparse solves use SciPy's SuperLU, "
                    "slower than MKL PARDISO")
    else:
        warnings.warn(f"pypardiso is installed but failed to import ({PARDISO_IMPORT_ERROR}): sparse solves use "
                      "SciPy's SuperLU, slower than MKL PARDISO", RuntimeWarning, stacklevel=3)


class SingularMatrixError(RuntimeError):
    """The tangent could not be factorized (a mechanism, or a singular tangent)."""


class _PardisoHandle:
    """One PARDISO handle of one matrix type; its symbolic analysis is kept per pattern."""

    def __init__(self, mtype: int) -> None:
        self.pardiso = _pypardiso.PyPardisoSolver(mtype=mtype)
        # pypardiso looks for MKL with a recursive glob over sys.prefix on every solver it
        # makes (0.8 s each, five per arm, profiled); the library it found is named once
        os.environ.setdefault("PYPARDISO_MKL_RT", self.pardiso.libmkl._name)
        # PARDISO reads iparm only when iparm[0] = 1; with pypardiso's 0 it fills in its own
        # defaults, which (measured with MKL 2025 on the quick biceps, 13632 DOF) refine every
        # solution twice even when no pivot was perturbed: a solve cost 60 ms beside a 115 ms
        # factorization, 8 ms without the refinement at the same relative residual (1e-10).
        # Set: the documented defaults of mtype -2 (its pivoting flags are ignored by Cholesky),
        # with refinement only where pivots were perturbed (iparm[7] = 0); callers that need
        # more refine themselves (_refined_solve).
        iparm = self.pardiso.iparm
        iparm[:] = 0
        iparm[0] = 1   # use these values
        iparm[1] = 2   # METIS nested-dissection ordering
        iparm[7] = 0   # iterative refinement: two steps only after perturbed pivots
        iparm[9] = 8   # pivot perturbation 1e-8 (symmetric indefinite)
        iparm[20] = 1  # Bunch-Kaufman 1x1 and 2x2 pivoting (symmetric indefinite)
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None
        self._pattern_arrays: tuple = (None, None)
        self.data: np.ndarray | None = None

    def factorize(self, upper: sp.csr_matrix) -> None:
        """Numerically factorize (raises pypardiso's PyPardisoError); the symbolic analysis is
        redone only when the pattern changes."""
        self.data = None
        if not self._same_pattern(upper):
            self._pattern = None
            self.pardiso._check_A(upper)  # sorted indices, no empty rows
            # PARDISO wants 1-based int32 index arrays: converted once per pattern
            self._ia = (upper.indptr + 1).astype(np.int32)
            self._ja = (upper.indices + 1).astype(np.int32)
            self._call(11, upper.data, np.zeros((upper.shape[0], 1)))
            self._pattern = (upper.indptr.copy(), upper.indices.copy())
            self._pattern_arrays = (upper.indptr, upper.indices)
        # a failed numerical factorization (a Cholesky meeting a negative pivot) keeps the
        # analysis: the next tangent of this pattern refactorizes without redoing it
        self._call(22, upper.data, np.zeros((upper.shape[0], 1)))
        self.data = upper.data

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._call(33, self.data, rhs)

    def _call(self, phase: int, data: np.ndarray, b: np.ndarray) -> np.ndarray:
        """One PARDISO call on the cached pattern (what pypardiso's _call_pardiso does, minus
        re-converting the index arrays on every call)."""
        import ctypes

        solver = self.pardiso
        b = np.asfortranarray(b, dtype=np.float64)
        x = np.zeros_like(b)
        error = ctypes.c_int32(0)
        int_p, double_p = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
        data = np.ascontiguousarray(data, dtype=np.float64)
        solver._mkl_pardiso(
            solver.pt.ctypes.data_as(ctypes.POINTER(solver._pt_type[0])),
            ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(solver.mtype)), ctypes.byref(ctypes.c_int32(phase)),
            ctypes.byref(ctypes.c_int32(len(self._ia) - 1)),
            data.ctypes.data_as(double_p), self._ia.ctypes.data_as(int_p), self._ja.ctypes.data_as(int_p),
            solver.perm.ctypes.data_as(int_p),
            ctypes.byref(ctypes.c_int32(1 if b.ndim == 1 else b.shape[1])),
            solver.iparm.ctypes.data_as(int_p), ctypes.byref(ctypes.c_int32(solver.msglvl)),
            b.ctypes.data_as(double_p), x.ctypes.data_as(double_p), ctypes.byref(error),
        )
        if error.value != 0:
            raise _pypardiso.pardiso_wrapper.PyPardisoError(error.value)
        return np.ascontiguousarray(x)

    def _same_pattern(self, upper: sp.csr_matrix) -> bool:
        if self._pattern is None:
            return False
        if upper.indptr is self._pattern_arrays[0] and upper.indices is self._pattern_arrays[1]:
            return True  # the same CSR object refreshed in place: no need to compare
        indptr, indices = self._pattern
        return np.array_equal(indptr, upper.indptr) and np.array_equal(indices, upper.indices)


class SparseSymmetricSolver:
    """Factorize a symmetric sparse matrix given by its upper triangle (CSR), then solve.

    ``backend``: "pardiso", "scipy" or "auto" (PARDISO when importable). PARDISO tries Cholesky
    first and falls back to LDL^T for indefinite matrices (module docstring); ``definite``
    says which one holds the current factorization.
    """

    indefinite_spell = 8  # factorizations that go straight to LDL^T after a failed Cholesky

    def __init__(self, backend: str = "auto") -> None:
        if backend == "auto":
            backend = "pardiso" if HAVE_PARDISO else "scipy"
            if not HAVE_PARDISO:
                _report_scipy_fallback()
        if backend == "pardiso" and not HAVE_PARDISO:
            why = "is not installed" if PARDISO_IMPORT_ERROR is None else f"failed to import ({PARDISO_IMPORT_ERROR})"
            raise RuntimeError(f"pypardiso {why}; use backend='scipy' or `pip install 'persival[fast]'`")
        if backend not in ("pardiso", "scipy"):
            raise ValueError(f"unknown sparse solver backend {backend!r}")
        self.backend = backend
        self._lu = None
        self._handles: dict[bool, _PardisoHandle] = {}
        self._active: _PardisoHandle | None = None
        self.definite = False
        self._skip_cholesky = 0

    def _handle(self, definite: bool) -> _PardisoHandle:
        if definite not in self._handles:
            self._handles[definite] = _PardisoHandle(2 if definite else -2)
        return self._handles[definite]

    def factorize(self, upper: sp.csr_matrix) -> None:
        """Numerically factorize; the symbolic analysis is redone only when the pattern changes."""
        self._active = self._lu = None
        if not np.all(np.isfinite(upper.data)):
            raise SingularMatrixError("tangent matrix contains NaN or inf")
        if self.backend == "pardiso":
            if self._skip_cholesky > 0:
                self._skip_cholesky -= 1
            else:
                try:
                    self._handle(True).factorize(upper)
                    self._active, self.definite = self._handles[True], True
                    return
                except _pypardiso.pardiso_wrapper.PyPardisoError as exc:
                    if exc.value != -4:  # -4: a non-positive pivot, the matrix is not definite
                        raise SingularMatrixError(f"PARDISO factorization failed: {exc}") from exc
                    self._skip_cholesky = self.indefinite_spell
            try:
                self._handle(False).factorize(upper)
            except Exception as exc:  # PyPardisoError
                raise SingularMatrixError(f"PARDISO factorization failed: {exc}") from exc
            self._active, self.definite = self._handles[False], False
        else:
            full = upper + sp.triu(upper, k=1).T
            try:
                self._lu = spla.splu(full.tocsc(), permc_spec="COLAMD")
            except RuntimeError as exc:
                raise SingularMatrixError(f"SuperLU factorization failed: {exc}") from exc

    @property
    def factorized(self) -> bool:
        """Whether a factorization is held (the last factorize() succeeded)."""
        return self._active is not None or self._lu is not None

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if not self.factorized:
            raise RuntimeError("factorize() must be called before solve()")
        if self.backend == "pardiso":
            rhs = np.asarray(rhs, dtype=float)
            x = self._active.solve(rhs if rhs.ndim == 2 else rhs[:, None])
            x = x if rhs.ndim == 2 else x[:, 0]
        else:
            x = self._lu.solve(np.asarray(rhs, dtype=float))
        if not np.all(np.isfinite(x)):
            raise SingularMatrixError("linear solve produced NaN or inf (singular tangent?)")
        return x
