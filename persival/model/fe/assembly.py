"""Vectorized total-Lagrangian assembly of tet10 internal forces and tangents (docs/theory.md, 2.2).

Weak form of quasi-static equilibrium in the reference configuration:
``f_int[a, i] = sum_q w_q det(J_q) P_iJ dN_a/dX_J`` with ``P = F S`` and the tangent
``K[a i, b k] = sum_q w_q det(J_q) dN_a/dX_J A_iJkL dN_b/dX_L``,
``A_iJkL = dP_iJ/dF_kL = delta_ik S_JL + F_iM F_kN CC_MJNL`` (CC = 2 dS/dC).

All elements are processed by one compiled kernel (numba, parallel over elements; the
constitutive law is the same compiled point function as in :mod:`persival.model.fe.material`),
and the global matrix (upper triangle: K is symmetric) is filled by a gather map computed once: the sparsity
pattern never changes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from persival.model.fe import material, tet10
from persival.model.fe.kernel_cache import drop_stale_kernels
from persival.model.fe.material import DEFAULT_PARAMETERS, MaterialParameters, _law_point
from persival.model.fe.mesh import Tet10Mesh

# the element kernel inlines the law: its cached build must not outlive a change of material.py
drop_stale_kernels(__file__, [material.__file__])


@dataclass
class MaterialField:
    """Material data at every quadrature point, (m, nq[, 3]).

    Built from per-cell values with :meth:`from_cells`; activation is given per solve.
    """

    fibre: np.ndarray
    muscle_fraction: np.ndarray
    bulk_modulus: np.ndarray
    fibre_prestretch: np.ndarray
    parameters: MaterialParameters = DEFAULT_PARAMETERS
    # the muscle matrix's stress-free stretch along the fibre (docs/theory.md, 1.7); None: 1 everywhere
    matrix_prestretch: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.matrix_prestretch is None:
            self.matrix_prestretch = np.ones_like(self.fibre_prestretch)

    @classmethod
    def from_cells(
        cls,
        n_quadrature: int,
        fibre,
        muscle_fraction,
        bulk_modulus,
        fibre_prestretch=1.0,
        n_cells: int | None = None,
        parameters: MaterialParameters = DEFAULT_PARAMETERS,
        matrix_prestretch=1.0,
    ) -> MaterialField:
        fibre = np.asarray(fibre, dtype=float)
        m = n_cells if n_cells is not None else (len(fibre) if fibre.ndim == 2 else None)
        if m is None:
            raise ValueError("n_cells is required when the fibre direction is a single vector")
        fibre = np.broadcast_to(fibre, (m, 3))
        norms = np.linalg.norm(fibre, axis=1)
        if np.any(norms <= 0) or not np.all(np.isfinite(norms)):
            raise ValueError("fibre directions must be finite and non-zero")
        fibre = fibre / norms[:, None]

        def per_point(v, name):
            v = np.broadcast_to(np.asarray(v, dtype=float), (m,))
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{name} contains NaN or inf")
            return np.repeat(v[:, None], n_quadrature, axis=1)

        gm = per_point(muscle_fraction, "muscle_fraction")
        if np.any((gm < 0) | (gm > 1)):
            raise ValueError("muscle_fraction must lie in [0, 1]")
        k = per_point(bulk_modulus, "bulk_modulus")
        if np.any(k <= 0):
            raise ValueError("bulk_modulus must be positive")
        pre = per_point(fibre_prestretch, "fibre_prestretch")
        if np.any(pre <= 0):
            raise ValueError("fibre_prestretch must be positive")
        matrix = per_point(matrix_prestretch, "matrix_prestretch")
        if np.any(matrix <= 0):
            raise ValueError("matrix_prestretch must be positive")
        return cls(np.repeat(fibre[:, None, :], n_quadrature, axis=1), gm, k, pre, parameters, matrix)


class InvertedElementError(ArithmeticError):
    """det F <= 0 at a quadrature point: the trial state is not admissible."""


class Tet10Assembler:
    """Internal force and tangent of a tet10 mesh with a fixed DOF layout (3 per node, xyz)."""

    def __init__(self, mesh: Tet10Mesh, quadrature_order: int = 2) -> None:
        self.mesh = mesh
        qp, w = tet10.quadrature(quadrature_order)
        self.n_quadrature = len(w)
        dN_ref = tet10.shape_gradients(qp)  # (nq, 10, 3)
        X = mesh.points[mesh.cells]  # (m, 10, 3)
        jac = np.einsum("mai,qaj->mqij", X, dN_ref)
        det = np.linalg.det(jac)
        if np.any(det <= 0):
            bad = np.flatnonzero((det <= 0).any(axis=1))
            raise ValueError(f"{len(bad)} inverted or degenerate element(s), e.g. cell {bad[0]}")
        # dN/dX = dN/dxi J^-1, stored (m, nq, 10, 3)
        self.dN = np.einsum("qaj,mqji->mqai", dN_ref, np.linalg.inv(jac))
        self.weights = det * w  # (m, nq)
        self.n_dofs = 3 * mesh.n_nodes
        self.cell_dofs = (3 * mesh.cells[:, :, None] + np.arange(3)).reshape(-1, 30)  # (m, 30)
        self._build_pattern()
        self._Ke: np.ndarray | None = None

    def _build_pattern(self) -> None:
        """CSR pattern of the upper triangle of K and, per nonzero, the element entries that sum into it.

        The tangent is symmetric, so only entries with row <= column are assembled. Each
        nonzero gathers its contributions (a sorted segment of element-matrix positions), which
        parallelizes without write conflicts, unlike a scatter.
        """
        rows = np.repeat(self.cell_dofs, 30, axis=1).ravel()
        cols = np.tile(self.cell_dofs, (1, 30)).ravel()
        upper = np.flatnonzero(rows <= cols)
        key = rows[upper] * self.n_dofs + cols[upper]
        unique, target = np.unique(key, return_inverse=True)
        order = np.argsort(target, kind="stable")
        self._gather_entries = upper[order]  # positions in the flattened (m, 30, 30) element matrices
        self._gather_ptr = np.concatenate([[0], np.cumsum(np.bincount(target, minlength=len(unique)))])
        r, c = np.divmod(unique, self.n_dofs)
        self.pattern_rows = r
        self.pattern_cols = c
        self._indptr = np.concatenate([[0], np.cumsum(np.bincount(r, minlength=self.n_dofs))]).astype(np.int32)
        self._indices = c.astype(np.int32)

    # -- kinematics ---------------------------------------------------------------------------
    def deformation_gradient(self, u: np.ndarray) -> np.ndarray:
        """F = I + grad_X u at every quadrature point, (m, nq, 3, 3)."""
        ue = u.reshape(-1, 3)[self.mesh.cells]  # (m, 10, 3)
        return np.einsum("mai,mqaj->mqij", ue, self.dN) + np.eye(3)

    def _scatter_vector(self, fe: np.ndarray) -> np.ndarray:
        return np.bincount(self.cell_dofs.ravel(), weights=fe.ravel(), minlength=self.n_dofs)

    # -- assembly -----------------------------------------------------------------------------
    def _run_kernel(self, u, material, activation, with_tangent):
        ue = np.ascontiguousarray(u.reshape(-1, 3)[self.mesh.cells])  # (m, 10, 3)
        act = np.ascontiguousarray(activation, dtype=float)
        if act.shape != (self.mesh.n_cells,):
            raise ValueError(f"activation must be given per cell, shape ({self.mesh.n_cells},), got {act.shape}")
        fe = np.empty((self.mesh.n_cells, 10, 3))
        if with_tangent:
            # reused: a fresh 25 MB array per call costs more in page faults than the gather
            if self._Ke is None:
                self._Ke = np.empty((self.mesh.n_cells, 30, 30))
            Ke = self._Ke
        else:
            Ke = np.empty((self.mesh.n_cells, 0, 0))
        bad = _element_kernel(
            ue, self.dN, self.weights, material.fibre, act, material.muscle_fraction, material.bulk_modulus,
            material.fibre_prestretch, material.matrix_prestretch, material.parameters.packed(), with_tangent, fe, Ke,
        )
        if bad:
            raise InvertedElementError(f"det F <= 0 in {bad} element(s)")
        return self._scatter_vector(fe), Ke

    def internal_force(self, u: np.ndarray, material: MaterialField, activation: np.ndarray) -> np.ndarray:
        """f_int (n_dofs,) in N for displacements u (n_dofs,) and per-cell activation (m,)."""
        return self._run_kernel(u, material, activation, False)[0]

    def tangent(
        self, u: np.ndarray, material: MaterialField, activation: np.ndarray
    ) -> tuple[sp.csr_matrix, np.ndarray]:
        """Upper triangle of the tangent K (CSR, fixed pattern) and the internal force f_int (n_dofs,)."""
        f_int, Ke = self._run_kernel(u, material, activation, True)
        data = np.empty(len(self._indices))
        _gather_sum(data, self._gather_ptr, self._gather_entries, Ke.reshape(-1))
        K = sp.csr_matrix((data, self._indices, self._indptr), shape=(self.n_dofs, self.n_dofs))
        return K, f_int


def symmetric_matvec(upper: sp.csr_matrix, x: np.ndarray) -> np.ndarray:
    """K x for a symmetric K stored as its upper triangle."""
    return upper @ x + upper.T @ x - upper.diagonal() * x


@njit(cache=True, parallel=True)
def _gather_sum(data, ptr, entries, values):
    for j in prange(data.shape[0]):
        acc = 0.0
        for p in range(ptr[j], ptr[j + 1]):
            acc += values[entries[p]]
        data[j] = acc


@njit(cache=True, parallel=True)
def _element_kernel(ue, dN, w, a0, act, gm, k, pre, mpre, p, with_tangent, fe, Ke):
    """Element internal forces and tangents of all cells (docs/theory.md, 2.2 weak form, module docstring).

    Returns the number of cells with det F <= 0 at some quadrature point.
    """
    m, nq = w.shape
    bad = 0
    for e in prange(m):
        F = np.empty((3, 3))
        S = np.empty((3, 3))
        CC = np.empty((3, 3, 3, 3))
        T = np.empty((3, 3, 3, 3))
        A = np.empty((3, 3, 3, 3))
        G = np.empty((10, 3, 3, 3))
        failed = False
        fe[e] = 0.0
        if with_tangent:
            Ke[e] = 0.0
        for q in range(nq):
            g = dN[e, q]
            for i in range(3):
                for J in range(3):
                    acc = 1.0 if i == J else 0.0
                    for a in range(10):
                        acc += ue[e, a, i] * g[a, J]
                    F[i, J] = acc
            if _law_point(F, a0[e, q], act[e], gm[e, q], k[e, q], pre[e, q], p, S, CC, with_tangent,
                          mpre[e, q]) <= 0.0:
                failed = True
                break
            wq = w[e, q]
            # P = F S ; f_a,i += w P_iJ dN_aJ
            for i in range(3):
                P0 = F[i, 0] * S[0, 0] + F[i, 1] * S[1, 0] + F[i, 2] * S[2, 0]
                P1 = F[i, 0] * S[0, 1] + F[i, 1] * S[1, 1] + F[i, 2] * S[2, 1]
                P2 = F[i, 0] * S[0, 2] + F[i, 1] * S[1, 2] + F[i, 2] * S[2, 2]
                for a in range(10):
                    fe[e, a, i] += wq * (P0 * g[a, 0] + P1 * g[a, 1] + P2 * g[a, 2])
            if not with_tangent:
                continue
            # A_iJkL = delta_ik S_JL + F_iM F_kN CC_MJNL, via T_iJNL = F_iM CC_MJNL
            for i in range(3):
                for J in range(3):
                    for N in range(3):
                        for L in range(3):
                            T[i, J, N, L] = F[i, 0] * CC[0, J, N, L] + F[i, 1] * CC[1, J, N, L] + F[i, 2] * CC[2, J, N, L]
            for i in range(3):
                for J in range(3):
                    for kk in range(3):
                        for L in range(3):
                            v = F[kk, 0] * T[i, J, 0, L] + F[kk, 1] * T[i, J, 1, L] + F[kk, 2] * T[i, J, 2, L]
                            if i == kk:
                                v += S[J, L]
                            A[i, J, kk, L] = wq * v
            # G_aikL = dN_aJ A_iJkL ; K_(a i)(b k) += G_aikL dN_bL
            for a in range(10):
                for i in range(3):
                    for kk in range(3):
                        for L in range(3):
                            G[a, i, kk, L] = g[a, 0] * A[i, 0, kk, L] + g[a, 1] * A[i, 1, kk, L] + g[a, 2] * A[i, 2, kk, L]
            # K is symmetric (hyperelastic): fill the node blocks b >= a, mirror below
            for a in range(10):
                for i in range(3):
                    r = 3 * a + i
                    for b in range(a, 10):
                        for kk in range(3):
                            Ke[e, r, 3 * b + kk] += G[a, i, kk, 0] * g[b, 0] + G[a, i, kk, 1] * g[b, 1] + G[a, i, kk, 2] * g[b, 2]
        if failed:
            bad += 1
        elif with_tangent:  # mirror: the global upper triangle may need either orientation
            for a in range(10):
                for b in range(a + 1, 10):
                    for i in range(3):
                        for kk in range(3):
                            Ke[e, 3 * b + kk, 3 * a + i] = Ke[e, 3 * a + i, 3 * b + kk]
    return bad
