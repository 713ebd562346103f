"""The reduction step (EZyRB's Database -> Reduction -> Approximation): proper orthogonal
decomposition of surface snapshots (docs/theory.md 7.3).

``POD(...).fit(snapshots)`` keeps the leading modes of the snapshots' fluctuation about their
mean by one of three rules: a given ``rank``; the smallest rank keeping ``energy`` of the
fluctuations' squared norm (at most ``max_rank``); or the smallest rank that reproduces every
snapshot within ``tolerance_mm`` at every node. ``transform`` gives coefficients,
``inverse_transform`` snapshots back. The POD network approximates the coefficients with a
network, the structured surrogate with smooth interpolation in (theta, a).

>>> import numpy as np
>>> t = np.linspace(0.0, 1.0, 50)[:, None]
>>> snapshots = np.hstack([t, 2 * t, t**2, 0 * t, 1 + 0 * t, 3 * t])  # 2 nodes, rank 2
>>> pod = POD(tolerance_mm=1e-9).fit(snapshots)
>>> pod.rank, float(np.abs(pod.inverse_transform(pod.transform(snapshots)) - snapshots).max()) < 1e-12
(2, True)
"""

from __future__ import annotations

import numpy as np

__all__ = ["POD", "pod_basis"]


class POD:
    """Mean (d,) and orthonormal modes (r, d) of snapshots (n, d) (d = 3 x nodes, interleaved xyz)."""

    def __init__(self, rank: int | None = None, energy: float = 0.99999, max_rank: int | None = None,
                 tolerance_mm: float | None = None) -> None:
        if rank is not None and tolerance_mm is not None:
            raise ValueError("give a rank or a tolerance, not both")
        self.rank_asked, self.energy, self.max_rank, self.tolerance_mm = rank, energy, max_rank, tolerance_mm
        self.mean: np.ndarray | None = None
        self.modes: np.ndarray | None = None
        self.singular_values: np.ndarray | None = None
        self.worst_error_mm: float | None = None  # with tolerance_mm: the worst node error of the projection

    @property
    def rank(self) -> int:
        return 0 if self.modes is None else len(self.modes)

    def fit(self, snapshots: np.ndarray) -> POD:
        u = np.asarray(snapshots, dtype=np.float64).reshape(len(snapshots), -1)
        if self.tolerance_mm is None:
            self.mean, self.modes, self.singular_values = pod_basis(u, self.rank_asked, self.energy, self.max_rank)
            return self
        self.mean = u.mean(axis=0)
        centred = u - self.mean
        _, sigma, vt = np.linalg.svd(centred, full_matrices=False)
        most = min(self.max_rank or len(sigma), len(sigma))
        for r in range(1, most + 1):
            residual = centred - (centred @ vt[:r].T) @ vt[:r]
            self.worst_error_mm = float(np.sqrt((residual.reshape(len(u), -1, 3) ** 2).sum(axis=2)).max())
            if self.worst_error_mm <= self.tolerance_mm:
                break
        self.modes, self.singular_values = vt[:r], sigma
        return self

    def transform(self, snapshots: np.ndarray) -> np.ndarray:
        """Coefficients (n, r) of snapshots (n, d) or (n, nodes, 3)."""
        return (np.asarray(snapshots, dtype=np.float64).reshape(len(snapshots), -1) - self.mean) @ self.modes.T

    def inverse_transform(self, coefficients: np.ndarray) -> np.ndarray:
        """Snapshots (n, d) of coefficients (n, r)."""
        return self.mean + np.asarray(coefficients) @ self.modes

    def report(self) -> dict:
        """The numbers a fitted POD is described by (captured energy, the first singular values)."""
        s = self.singular_values
        return {"modes": self.rank, "worst_projection_error_mm": self.worst_error_mm,
                "energy": float((s[: self.rank] ** 2).sum() / max(float((s**2).sum()), 1e-300)),
                "singular_values": s[: max(self.rank, 1) + 4].tolist()}


def pod_basis(displacements: np.ndarray, rank: int | None = None, energy: float = 0.99999, max_rank: int | None = None):
    """Mean (3N,), the leading POD modes (r, 3N) of (n, N, 3) displacements, and their singular values.

    ``rank`` given: that many modes; else the smallest rank keeping ``energy`` of the
    fluctuation's squared norm, at most ``max_rank``. With a cap well below the sample count,
    the modes come from a randomized subspace iteration (:func:`_leading_modes`): the main job's
    4000 x 23382 snapshots took 24 s by the n x n Gram matrix and its full eigendecomposition.
    """
    u = np.asarray(displacements, dtype=np.float64).reshape(len(displacements), -1)
    mean = u.mean(axis=0)
    centred = u - mean
    wanted = rank if rank is not None else max_rank
    if wanted is not None and wanted + 24 < min(centred.shape) // 2:
        s, modes = _leading_modes(centred, wanted + 16)
    else:  # the n x n Gram matrix (n samples << 3N outputs) instead of an SVD of the snapshots
        w, v = np.linalg.eigh(centred @ centred.T)
        w, v = np.clip(w[::-1], 0.0, None), v[:, ::-1]
        s = np.sqrt(w)
        modes = None
    if rank is None:
        captured = np.cumsum(s**2) / max(float(np.vdot(centred, centred)), 1e-300)  # no (n, 3N) temporary
        rank = int(np.searchsorted(captured, energy) + 1)
        rank = rank if max_rank is None else min(rank, max_rank)
    rank = int(min(rank, int(np.sum(s > s[0] * 1e-10)), len(s)))
    basis = modes[:rank] if modes is not None else (v[:, :rank].T @ centred) / s[:rank, None]
    return mean, basis, s[:rank]


def _leading_modes(a: np.ndarray, k: int, power_iterations: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """The k leading singular values and right singular vectors (k, m) of a (n, m): randomized
    subspace iteration (Halko, Martinsson and Tropp 2011, algorithm 4.4) with a fixed seed, then
    Rayleigh-Ritz. The snapshots' spectrum falls fast, so six iterations leave the modes kept by
    the energy criterion exact to rounding (tests/surrogate/test_networks.py compares with the Gram route)."""
    q = np.linalg.qr(a @ np.random.default_rng(0).standard_normal((a.shape[1], k)))[0]
    for _ in range(power_iterations):
        q = np.linalg.qr(a @ np.linalg.qr(a.T @ q)[0])[0]
    _, s, vt = np.linalg.svd(q.T @ a, full_matrices=False)
    return s, vt
