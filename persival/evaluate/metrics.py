"""The paper's accuracy metrics (docs/theory.md, 8.1), per state and over a set of states.

Per state: node errors ``e_n = |x_pred,n - x_ref,n|`` (mm); MaxAE = max_n e_n, MAE = mean_n e_n;
relative errors divide by the state's largest reference displacement ``max_m |u_ref,m|``
(MaxRE, MRE, in percent here). A table entry is the maximum or the mean of the per-state
values over the tested states.
"""

from __future__ import annotations

import numpy as np

__all__ = ["state_errors", "summarize"]


def state_errors(predicted, reference, reference_displacement) -> dict[str, np.ndarray]:
    """Per-state MaxAE, MAE (mm) and MaxRE, MRE (%) for arrays of shape (m, n_nodes, 3)."""
    predicted = np.asarray(predicted, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    u = np.asarray(reference_displacement, dtype=np.float64)
    if predicted.shape != reference.shape or u.shape != reference.shape or reference.ndim != 3:
        raise ValueError(
            f"predicted, reference and reference_displacement must share one (m, n, 3) shape, got "
            f"{predicted.shape}, {reference.shape}, {u.shape}"
        )
    if not (np.isfinite(predicted).all() and np.isfinite(reference).all() and np.isfinite(u).all()):
        raise ValueError("the compared positions contain NaN or inf")
    e = np.linalg.norm(predicted - reference, axis=2)
    scale = np.linalg.norm(u, axis=2).max(axis=1)
    if np.any(scale <= 0.0):
        raise ValueError("a reference state has no displacement: relative errors are undefined")
    return {
        "MaxAE_mm": e.max(axis=1),
        "MAE_mm": e.mean(axis=1),
        "MaxRE_pct": 100.0 * e.max(axis=1) / scale,
        "MRE_pct": 100.0 * e.mean(axis=1) / scale,
    }


def summarize(per_state: dict[str, np.ndarray]) -> dict[str, float]:
    """Table entries: the maximum and the mean over states of every per-state metric."""
    out = {}
    for name, values in per_state.items():
        values = np.asarray(values, dtype=np.float64)
        out[f"max {name}"] = float(values.max())
        out[f"mean {name}"] = float(values.mean())
    return out
