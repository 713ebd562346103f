"""One muscle's surface as a smooth function of (theta, own activation), from its response table.

The tabulated FE states (every table angle and activation level) are taken in the muscle's own
frame, where the line of action is fixed, and reduced by POD (docs/theory.md
7.7): ``y = mean + c(theta, a) @ modes``. The coefficients are interpolated like the
moments: cubic Hermite in theta through their values and slopes (the tables' du/dtheta
projected on the modes), an interpolating cubic spline in the activation. The world position
turns the own frame with the line of action, ``x = O + (y - O) Q(theta)^T``; Q's nine entries are
Hermite-interpolated in theta too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from persival.surrogate.reduction import POD
from persival.vocabulary import MUSCLES

__all__ = ["MuscleShape", "fit_muscle_shape"]

ROTATION_STEP_DEG = 1e-3  # central differences of Q(theta) for its Hermite slopes


@dataclass
class MuscleShape:
    """A muscle's surface model: ``positions(theta_w, act_w)`` -> (b, n_s, 3) world mm."""

    name: str
    origin: np.ndarray  # (3,) O: the own frame turns about it
    mean: np.ndarray  # (3 n_s,) own-frame surface positions, mean over the table
    modes: np.ndarray  # (r, 3 n_s)
    coefficient_data: np.ndarray  # (2 n_t, n_a, r): values then slopes per degree, per level
    rotation_data: np.ndarray  # (2 n_t, 9): Q(theta) entries, values then slopes per degree
    report: dict

    @property
    def muscle_index(self) -> int:
        return MUSCLES.index(self.name)

    @property
    def n_nodes(self) -> int:
        return len(self.mean) // 3

    def coefficients(self, theta_weights: np.ndarray, activation_weights: np.ndarray) -> np.ndarray:
        """(b, r) POD coefficients from the theta weights (b, 2 n_t) and activation weights (b, n_a)."""
        return np.einsum("bk,kjr,bj->br", theta_weights, self.coefficient_data, activation_weights)

    def positions(self, theta_weights: np.ndarray, activation_weights: np.ndarray) -> np.ndarray:
        own = self.mean + self.coefficients(theta_weights, activation_weights) @ self.modes
        q = (theta_weights @ self.rotation_data).reshape(-1, 3, 3)
        own = own.reshape(len(own), -1, 3) - self.origin
        return self.origin + np.einsum("bni,bji->bnj", own, q)


def fit_muscle_shape(table, unit, name: str, surface_ids: np.ndarray, angle_index: np.ndarray, tolerance_mm: float,
                     max_modes: int) -> MuscleShape:
    """The shape model of one muscle from its table columns at the table angles ``angle_index``.

    ``unit``: the muscle's FE unit (mesh points, origin and Q(theta)); ``surface_ids``: its
    surface nodes in the unit's numbering, in the order the surrogate answers them."""
    angles = table.angles_deg[angle_index]
    reference = unit.mesh.points[surface_ids]
    values, slopes = [], []
    for j in range(len(table.levels)):
        column = table.column(name, j)
        values.append(reference + column["displacement"][angle_index][:, surface_ids].astype(float))
        slopes.append(column["sensitivity"][angle_index][:, surface_ids].astype(float) * (np.pi / 180.0))
    values = np.stack(values, axis=1)  # (n_t, n_a, n_s, 3)
    slopes = np.stack(slopes, axis=1)
    n_t, n_a = values.shape[:2]
    if not (np.isfinite(values).all() and np.isfinite(slopes).all()):
        raise ValueError(f"{name}: the response table has failed solves inside {angles[0]:g} to {angles[-1]:g} deg")
    pod = POD(max_rank=max_modes, tolerance_mm=tolerance_mm).fit(values.reshape(n_t * n_a, -1))
    mean, modes = pod.mean, pod.modes
    coefficient_values = pod.transform(values.reshape(n_t * n_a, -1)).reshape(n_t, n_a, -1)
    coefficient_slopes = slopes.reshape(n_t, n_a, -1) @ modes.T
    rotations = np.stack([unit.rotation(t).ravel() for t in angles])
    rotation_slopes = np.stack([(unit.rotation(t + ROTATION_STEP_DEG) - unit.rotation(t - ROTATION_STEP_DEG)).ravel()
                                for t in angles]) / (2 * ROTATION_STEP_DEG)
    return MuscleShape(name, np.asarray(unit.origin, dtype=float), mean, modes,
                       np.concatenate([coefficient_values, coefficient_slopes], axis=0),
                       np.concatenate([rotations, rotation_slopes], axis=0), pod.report())
