"""The contact terms' check: the tangent against central differences of the force, the force
against central differences of the energy (persival.model.fe.contact, persival.model.anatomy.walls)."""

from __future__ import annotations

import numpy as np


def differences(contact, x0: np.ndarray, h: float = 1e-6) -> tuple[float, float, float]:
    """Relative asymmetry of the tangent, and its and the force's largest relative differences."""
    f, K = contact.force_and_tangent(x0)
    K = K.toarray()
    x = x0.ravel()
    K_fd, f_fd = np.zeros_like(K), np.zeros_like(f)
    for j in range(x.size):
        e = np.zeros(x.size)
        e[j] = h
        K_fd[:, j] = (contact.force(x + e) - contact.force(x - e)) / (2 * h)
        f_fd[j] = (contact.energy(x + e) - contact.energy(x - e)) / (2 * h)
    scale = np.abs(K).max()
    return np.abs(K - K.T).max() / scale, np.abs(K_fd - K).max() / scale, np.abs(f_fd - f).max() / np.abs(f).max()
