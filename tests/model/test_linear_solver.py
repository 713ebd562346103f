"""The sparse direct solver: Cholesky for definite tangents, LDL^T where a pivot is not positive."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from persival.model.linear_solver import HAVE_PARDISO, SparseSymmetricSolver

pytestmark = pytest.mark.skipif(not HAVE_PARDISO, reason="MKL PARDISO is not installed")


def laplacian(n: int, shift: float = 0.0) -> sp.csr_matrix:
    """Upper triangle of the 1-D Dirichlet Laplacian minus shift * I (eigenvalues 2 - 2 cos(k pi / (n + 1)) - shift)."""
    full = sp.diags([-np.ones(n - 1), 2.0 * np.ones(n) - shift, -np.ones(n - 1)], [-1, 0, 1], format="csr")
    upper = sp.triu(full, format="csr")
    upper.sort_indices()
    return upper


def residual(upper: sp.csr_matrix, x: np.ndarray, b: np.ndarray) -> float:
    full = upper + sp.triu(upper, k=1).T
    return float(np.linalg.norm(full @ x - b) / np.linalg.norm(b))


def test_definite_matrices_take_cholesky_and_indefinite_ones_ldlt():
    n = 200
    b = np.random.default_rng(0).normal(size=n)
    solver = SparseSymmetricSolver("pardiso")
    definite = laplacian(n)
    solver.factorize(definite)
    assert solver.definite and residual(definite, solver.solve(b), b) < 1e-10
    indefinite = laplacian(n, shift=1.01)  # a third of its eigenvalues are negative
    solver.factorize(indefinite)
    assert not solver.definite and residual(indefinite, solver.solve(b), b) < 1e-10
    # a spell of LDL^T after a failed Cholesky, then Cholesky again
    for _ in range(solver.indefinite_spell):
        solver.factorize(definite)
        assert not solver.definite
    solver.factorize(definite)
    assert solver.definite and residual(definite, solver.solve(b), b) < 1e-10
    assert np.allclose(solver.solve(np.column_stack([b, 2 * b]))[:, 1], 2 * solver.solve(b))
