"""One muscle's surface as a smooth function of (theta, own activation), from its response table.

The tabulated FE surfaces (every table angle and activation level) are reduced by POD
(docs/theory.md 7.7): ``x = mean + c(theta, a) @ modes``. The coefficients are interpolated like
the moments: cubic Hermite in theta through their values and slopes (the tables' slopes projected
on the modes), an interpolating cubic spline in the activation. By default the world positions
are reduced (Q = I); in the muscle's own frame, where the tables store it and the line of action
is fixed, fewer modes suffice, and the world position turns the own frame with the line of
action, ``x = O + (y - O) Q(theta)^T``, computed as ``x = (y + O (Q - I)) Q^T``: the shift is then
three more coefficients of the same product in the exported graph. Q's nine entries are
Hermite-interpolated in theta too (the two forms agree where Q is orthogonal, at the table
angles; between them they differ by O (Q Q^T - I), the interpolation error of Q itself: at most
2e-3 mm on the quick arm's 5-degree table steps)."""

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
        shift = self.origin @ q - self.origin  # O (Q - I), (b, 3)
        return np.einsum("bni,bji->bnj", own.reshape(len(own), -1, 3) + shift[:, None, :], q)


def fit_muscle_shape(table, unit, name: str, surface_ids: np.ndarray, angle_index: np.ndarray, tolerance_mm: float,
                     max_modes: int, world_frame: bool = False) -> MuscleShape:
    """The shape model of one muscle from its table columns at the table angles ``angle_index``.

    ``unit``: the muscle's FE unit (mesh points, origin and Q(theta)); ``surface_ids``: its
    surface nodes in the unit's numbering, in the order the surrogate answers them.
    ``world_frame``: reduce the world positions (Q = I) instead of the own frame's."""
    angles = table.angles_deg[angle_index]
    reference = unit.mesh.points[surface_ids]
    origin = np.asarray(unit.origin, dtype=float)
    rotations = np.stack([unit.rotation(t) for t in angles])
    rotation_slopes = np.stack([(unit.rotation(t + ROTATION_STEP_DEG) - unit.rotation(t - ROTATION_STEP_DEG))
                                for t in angles]) / (2 * ROTATION_STEP_DEG)
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
    if world_frame:  # x = O + (y - O) Q^T, dx/dtheta = dy/dtheta Q^T + (y - O) dQ^T/dtheta
        slopes = (np.einsum("tasi,tji->tasj", slopes, rotations)
                  + np.einsum("tasi,tji->tasj", values - origin, rotation_slopes))
        values = origin + np.einsum("tasi,tji->tasj", values - origin, rotations)
        rotations = np.broadcast_to(np.eye(3), rotations.shape)
        rotation_slopes = np.zeros_like(rotation_slopes)
    pod = POD(max_rank=max_modes, tolerance_mm=tolerance_mm).fit(values.reshape(n_t * n_a, -1))
    mean, modes = pod.mean, pod.modes
    coefficient_values = pod.transform(values.reshape(n_t * n_a, -1)).reshape(n_t, n_a, -1)
    coefficient_slopes = slopes.reshape(n_t, n_a, -1) @ modes.T
    return MuscleShape(name, origin, mean, modes, np.concatenate([coefficient_values, coefficient_slopes], axis=0),
                       np.concatenate([rotations.reshape(n_t, 9), rotation_slopes.reshape(n_t, 9)], axis=0), pod.report())
