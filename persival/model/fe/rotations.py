"""Rotation matrices of the arm's kinematics: about the hinge axis, and between two lines of action."""

from __future__ import annotations

import numpy as np

__all__ = ["line_rotation", "rotation_about"]


def rotation_about(axis: np.ndarray, theta_deg: float) -> np.ndarray:
    """Rotation matrix about a unit axis (Rodrigues)."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    t = np.radians(theta_deg)
    return np.eye(3) + np.sin(t) * K + (1.0 - np.cos(t)) * (K @ K)


def line_rotation(d_ref: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The minimal rotation taking unit vector d_ref to unit vector d (the Hinge's face rotation).

    Q = I + [v]x + [v]x^2 / (1 + cos), v = d_ref x d.
    """
    v = np.cross(d_ref, d)
    c = float(d_ref @ d)
    if c <= -1.0 + 1e-12:
        raise ValueError("the line of action reversed its direction")
    V = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + V + V @ V / (1.0 + c)
