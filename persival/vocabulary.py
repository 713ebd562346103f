"""The words every stage shares: the muscles and their order, the activation check, the units.

One module at the bottom of the package, imported by every stage, so that the order of the
activation vector (docs/theory.md, introduction) and what counts as a valid one are defined exactly once.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MUSCLES", "N_ACTIVATIONS", "ABBREVIATIONS", "ELBOW_ANGLE_BOUNDS_DEG", "UNITS", "check_activations",
           "check_activation_vector", "check_muscle_names"]

#: The five muscles, in the order of every activation vector (docs/theory.md, introduction):
#: ``MUSCLES.index("triceps") == 3``.
MUSCLES = ("biceps", "brachialis", "brachioradialis", "triceps", "anconeus")
N_ACTIVATIONS = len(MUSCLES)
#: Three-letter column labels of the same order, for tables
ABBREVIATIONS = ("BIC", "BRA", "BRD", "TRI", "ANC")
#: Elbow angles that mean anything (deg): 0 = full extension, beyond 180 the forearm would pass the humerus
ELBOW_ANGLE_BOUNDS_DEG = (0.0, 180.0)

#: Units of the quantities the stages exchange (positions, angles, moments, forces, stresses).
UNITS = {"length": "mm", "angle": "deg", "moment": "N mm", "force": "N", "stress": "MPa", "time": "s"}


def check_activations(activations, what: str = "activations") -> np.ndarray:
    """``activations`` as a float64 (n, 5) array, or ValueError saying what is wrong.

    Accepts one vector (5,) or a batch (n, 5); each must be finite and lie in [0, 1]^5. The
    message names the first offending row and muscle, so that a long design file is easy to fix.

    >>> check_activations([0.5, 0, 0, 0, 0]).shape
    (1, 5)
    >>> check_activations([[0.2, 0, 0, 1.5, 0]])
    Traceback (most recent call last):
    ...
    ValueError: activations: 1 row(s) lie outside [0, 1]^5, first: row 0, triceps = 1.5
    """
    try:
        arr = np.array(activations, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} must be numeric, got {exc}") from None
    if arr.ndim == 1 and arr.shape[0] == N_ACTIVATIONS:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != N_ACTIVATIONS:
        raise ValueError(f"{what} must have shape (n, {N_ACTIVATIONS}) or ({N_ACTIVATIONS},) "
                         f"({', '.join(MUSCLES)}), got {arr.shape}")
    if len(arr) == 0:
        raise ValueError(f"{what}: the array is empty")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{what}: {int(bad.sum())} row(s) are not finite, first: row {i} = {arr[i].tolist()}")
    outside = ((arr < 0.0) | (arr > 1.0)).any(axis=1)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        j = int(np.flatnonzero((arr[i] < 0.0) | (arr[i] > 1.0))[0])
        raise ValueError(f"{what}: {int(outside.sum())} row(s) lie outside [0, 1]^{N_ACTIVATIONS}, first: "
                         f"row {i}, {MUSCLES[j]} = {float(arr[i, j])!r}")
    return arr


def check_muscle_names(names, what: str = "muscles") -> tuple[str, ...]:
    """A choice of muscles, in vocabulary order: None for all of them, or names as a sequence or a
    comma-separated string ("biceps, triceps"); ValueError for an empty choice or an unknown name.

    >>> check_muscle_names("triceps, biceps")
    ('biceps', 'triceps')
    """
    if names is None:
        return MUSCLES
    chosen = [n.strip() for n in names.split(",")] if isinstance(names, str) else list(names)
    if not chosen or set(chosen) - set(MUSCLES):
        raise ValueError(f"{what} must be some of {list(MUSCLES)}, got {names!r}")
    return tuple(n for n in MUSCLES if n in chosen)


def check_activation_vector(activations, what: str = "activations") -> np.ndarray:
    """One activation vector as a float64 (5,) array (a batch of several is an error)."""
    arr = check_activations(activations, what)
    if len(arr) != 1:
        raise ValueError(f"{what}: need one vector of {N_ACTIVATIONS} ({', '.join(MUSCLES)}), got {len(arr)} rows")
    return arr[0]
