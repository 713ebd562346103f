"""The sparse direct solver: Cholesky for definite tangents, LDL^T where a pivot is not positive;
SciPy when pypardiso is missing (said once) or broken (warned, with the reason)."""

from __future__ import annotations

import logging
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from persival.model.fe import linear_solver
from persival.model.fe.linear_solver import HAVE_PARDISO, PARDISO_IMPORT_ERROR, SparseSymmetricSolver

needs_pardiso = pytest.mark.skipif(not HAVE_PARDISO, reason=f"MKL PARDISO: {PARDISO_IMPORT_ERROR or 'not installed'}")


def laplacian(n: int, shift: float = 0.0) -> sp.csr_matrix:
    """Upper triangle of the 1-D Dirichlet Laplacian minus shift * I (eigenvalues 2 - 2 cos(k pi / (n + 1)) - shift)."""
    full = sp.diags([-np.ones(n - 1), 2.0 * np.ones(n) - shift, -np.ones(n - 1)], [-1, 0, 1], format="csr")
    upper = sp.triu(full, format="csr")
    upper.sort_indices()
    return upper


def residual(upper: sp.csr_matrix, x: np.ndarray, b: np.ndarray) -> float:
    full = upper + sp.triu(upper, k=1).T
    return float(np.linalg.norm(full @ x - b) / np.linalg.norm(b))


@needs_pardiso
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


def _import_as(monkeypatch, result) -> None:
    """Make the module look as if its import of pypardiso had given ``result`` (no reload: that
    would make new exception classes under the feet of the modules that imported them)."""
    module, error = result
    monkeypatch.setattr(linear_solver, "_pypardiso", module)
    monkeypatch.setattr(linear_solver, "PARDISO_IMPORT_ERROR", error)
    monkeypatch.setattr(linear_solver, "HAVE_PARDISO", module is not None)
    monkeypatch.setattr(linear_solver, "_fallback_reported", False)


def test_pypardiso_not_installed_falls_back_to_scipy_with_one_log_line(monkeypatch, caplog):
    monkeypatch.setitem(sys.modules, "pypardiso", None)  # `import pypardiso` raises ModuleNotFoundError for it
    result = linear_solver._import_pardiso()
    assert result == (None, None)
    _import_as(monkeypatch, result)
    with caplog.at_level(logging.WARNING, logger=linear_solver.__name__):
        solvers = [SparseSymmetricSolver() for _ in range(3)]
    assert [s.backend for s in solvers] == ["scipy"] * 3
    lines = [r.getMessage() for r in caplog.records if r.name == linear_solver.__name__]
    assert len(lines) == 1 and "not installed" in lines[0]
    with pytest.raises(RuntimeError, match="pypardiso is not installed"):
        SparseSymmetricSolver("pardiso")
    upper = sp.triu(sp.diags([-np.ones(9), 2.0 * np.ones(10), -np.ones(9)], [-1, 0, 1]), format="csr")
    solvers[0].factorize(upper)
    b = np.arange(10.0)
    assert np.allclose((upper + sp.triu(upper, k=1).T) @ solvers[0].solve(b), b)


@pytest.mark.parametrize("error", ["ImportError('libmkl_rt.so.2: cannot open shared object file')",
                                   "ModuleNotFoundError(\"No module named 'mkl_inner'\", name='mkl_inner')"])
def test_pypardiso_installed_but_broken_warns_with_the_reason(monkeypatch, tmp_path, caplog, error):
    fake = tmp_path / "pypardiso"
    fake.mkdir()
    (fake / "__init__.py").write_text(f"raise {error}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "pypardiso", raising=False)
    module, reason = linear_solver._import_pardiso()
    assert module is None and reason is not None
    assert ("libmkl_rt.so.2" in reason) if error.startswith("ImportError") else ("mkl_inner" in reason)
    _import_as(monkeypatch, (module, reason))
    with pytest.warns(RuntimeWarning, match="installed but failed to import") as record:
        assert SparseSymmetricSolver().backend == "scipy"
        assert SparseSymmetricSolver().backend == "scipy"  # said once per process
    assert len([w for w in record if issubclass(w.category, RuntimeWarning)]) == 1
    assert reason in str(record[0].message)
    assert not [r for r in caplog.records if r.name == linear_solver.__name__]  # a warning, not the "not installed" line
    with pytest.raises(RuntimeError, match="failed to import"):
        SparseSymmetricSolver("pardiso")
