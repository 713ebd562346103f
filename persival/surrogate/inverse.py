"""The inverse problem (docs/theory.md, section 6): least-effort activations for an elbow angle.

``alpha_opt(Theta) = argmin_{alpha in [0,1]^5} |Theta - theta(alpha)| + w sum(alpha)`` (w = 0.05,
theta in degrees) on the SG surrogate of the elbow angle. The absolute value is not smooth;
with a slack variable t it becomes the smooth problem

    min t + w sum(alpha)   s.t.   t >= Theta - theta(alpha),  t >= theta(alpha) - Theta,
                                  0 <= alpha <= 1,  t >= 0,

solved by SLSQP with the SG's exact gradients. Starts: for all targets at once, the objective is
evaluated on one fixed candidate set (a scrambled Sobol' sample of the cube plus its corners,
one batched SG evaluation), and each target starts from its best few distinct candidates; the
best start SLSQP reports as successful wins (a failed one only where none succeeded: the target's
row says ``converged: false`` and a warning names it with scipy's message).
The reachable range is found the same way (min and max of theta over the cube).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from persival.vocabulary import ELBOW_ANGLE_BOUNDS_DEG

__all__ = ["InverseSolution", "InverseProblem", "EFFORT_WEIGHT"]

#: docs/theory.md, 6.1: weight of the effort sum(alpha) against one degree of angle error
EFFORT_WEIGHT = 0.05


@dataclass
class InverseSolution:
    target_deg: np.ndarray  # (n,)
    activations: np.ndarray  # (n, 5)
    achieved_deg: np.ndarray  # (n,)
    objective: np.ndarray  # (n,)
    reachable: np.ndarray  # (n,) bool: target inside the reachable range
    converged: np.ndarray  # (n,) bool: SLSQP reported success for the start taken

    def rows(self) -> list[dict]:
        """The JSON rows of ``persival inverse --json``."""
        return [{"target_deg": float(t), "activations": [float(v) for v in a], "achieved_deg": float(g),
                 "objective": float(o), "reachable": bool(r), "converged": bool(c)}
                for t, a, g, o, r, c in zip(self.target_deg, self.activations, self.achieved_deg, self.objective,
                                            self.reachable, self.converged)]


def _check_targets(targets) -> np.ndarray:
    t = np.atleast_1d(np.asarray(targets, dtype=np.float64))
    if t.ndim != 1 or len(t) == 0:
        raise ValueError(f"targets must be a non-empty list of angles in degrees, got shape {t.shape}")
    if not np.isfinite(t).all():
        raise ValueError(f"elbow-angle targets must be finite, got {t[~np.isfinite(t)][0]}")
    lo, hi = ELBOW_ANGLE_BOUNDS_DEG
    outside = (t < lo) | (t > hi)
    if outside.any():  # not a reachability question: no elbow bends there
        raise ValueError(f"elbow-angle target {t[outside][0]:g} deg is outside {lo:g} to {hi:g} deg")
    return t


class InverseProblem:
    """Least effort (docs/theory.md, 6.1) on any model with ``predict_angle(alpha) -> (m,)`` and
    ``angle_gradient(alpha) -> (m, 5)``."""

    def __init__(self, angle_model, effort_weight: float = EFFORT_WEIGHT, n_candidates: int = 4096,
                 seed: int = 0) -> None:
        if not (hasattr(angle_model, "predict_angle") and hasattr(angle_model, "angle_gradient")):
            raise ValueError("the surrogate has no elbow-angle output (need predict_angle and angle_gradient): "
                             "use a sparse-grid surrogate fitted to a campaign")
        self.model = angle_model
        self.weight = float(effort_weight)
        from scipy.stats import qmc

        corners = np.array(np.meshgrid(*[[0.0, 1.0]] * 5, indexing="ij")).reshape(5, -1).T
        sobol = qmc.Sobol(5, scramble=True, seed=seed).random(n_candidates)
        self.candidates = np.vstack([corners, sobol])
        self.candidate_angles = angle_model.predict_angle(self.candidates)
        self._range: tuple[float, float] | None = None

    # ------------------------------------------------------------------ reachable range
    def reachable_range(self) -> tuple[float, float]:
        """(min, max) elbow angle over [0,1]^5 (deg), by multi-start L-BFGS-B on the SG."""
        if self._range is None:
            ends = [self._extreme_angle(sign) for sign in (1.0, -1.0)]
            self._range = (float(ends[0]), float(ends[1]))
        return self._range

    def _extreme_angle(self, sign: float) -> float:
        """min (sign 1) or max (sign -1) of theta over the cube, from the 5 best candidates."""
        def f(a):
            return sign * self.model.predict_angle(a[None])[0]

        def df(a):
            return sign * self.model.angle_gradient(a[None])[0]

        starts = np.argsort(sign * self.candidate_angles)[:5]
        best = min((minimize(f, self.candidates[k], jac=df, method="L-BFGS-B", bounds=[(0.0, 1.0)] * 5)
                    for k in starts), key=lambda r: r.fun)
        return sign * best.fun

    # ------------------------------------------------------------------ solving
    def objective(self, activations, target: float) -> np.ndarray:
        a = np.atleast_2d(activations)
        return np.abs(target - self.model.predict_angle(a)) + self.weight * a.sum(axis=1)

    def _refine(self, start: np.ndarray, target: float):
        """(activations, objective, scipy's result) of SLSQP from one start."""
        model, w = self.model, self.weight
        theta0 = model.predict_angle(start[None])[0]
        z0 = np.append(start, abs(target - theta0))
        grad_f = np.append(np.full(5, w), 1.0)

        def gap(z):  # [t - (Theta - theta), t + (Theta - theta)] >= 0
            d = target - model.predict_angle(z[None, :5])[0]
            return np.array([z[5] - d, z[5] + d])

        def gap_jac(z):
            g = model.angle_gradient(z[None, :5])[0]
            return np.array([np.append(g, 1.0), np.append(-g, 1.0)])

        result = minimize(lambda z: z[5] + w * z[:5].sum(), z0, jac=lambda z: grad_f, method="SLSQP",
                          bounds=[(0.0, 1.0)] * 5 + [(0.0, None)],
                          constraints=[{"type": "ineq", "fun": gap, "jac": gap_jac}],
                          options={"ftol": 1e-12, "maxiter": 300})
        a = np.clip(result.x[:5], 0.0, 1.0)
        return a, float(self.objective(a, target)[0]), result

    def starts_for(self, targets: np.ndarray, n_starts: int) -> np.ndarray:
        """(n_targets, n_starts, 5): the best distinct candidates per target, all targets in one pass."""
        J = np.abs(targets[:, None] - self.candidate_angles[None, :]) + self.weight * self.candidates.sum(axis=1)[None, :]
        best = np.argsort(J, axis=1)[:, : 8 * n_starts]
        out = np.empty((len(targets), n_starts, 5))
        for i, row in enumerate(best):
            picked: list[np.ndarray] = []
            for k in row:  # distinct: at least 0.2 apart, so the starts probe different basins
                c = self.candidates[k]
                if all(np.abs(c - p).max() > 0.2 for p in picked):
                    picked.append(c)
                if len(picked) == n_starts:
                    break
            while len(picked) < n_starts:
                picked.append(self.candidates[row[len(picked)]])
            out[i] = picked
        return out

    def solve(self, targets, n_starts: int = 4, warm_starts=None) -> InverseSolution:
        """alpha_opt for every target (deg). ``warm_starts`` (n, 5): extra starts (continuation)."""
        targets = _check_targets(targets)
        starts = self.starts_for(targets, n_starts)
        if warm_starts is not None:
            starts = np.concatenate([np.asarray(warm_starts, dtype=float).reshape(len(targets), 1, 5), starts], axis=1)
        alphas = np.empty((len(targets), 5))
        objective = np.empty(len(targets))
        converged = np.empty(len(targets), dtype=bool)
        failures = []
        for i, target in enumerate(targets):
            results = [self._refine(s, target) for s in starts[i]]
            # a failed start can stop anywhere (an iteration limit, a line search that gave up):
            # it stands in only where no start succeeded, and then says so
            succeeded = [r for r in results if r[2].success]
            alphas[i], objective[i], best = min(succeeded or results, key=lambda r: r[1])
            converged[i] = bool(succeeded)
            if not succeeded:
                failures.append(f"{target:g} deg ({best.message})")
        if failures:
            warnings.warn(f"SLSQP failed from all {starts.shape[1]} starts for {len(failures)} of {len(targets)} "
                          f"elbow-angle target(s); their best failed start is kept, marked converged=False: "
                          + "; ".join(failures), RuntimeWarning, stacklevel=2)
        lo, hi = self.reachable_range()
        achieved = self.model.predict_angle(alphas)
        return InverseSolution(targets, alphas, achieved, objective, (targets >= lo - 1e-9) & (targets <= hi + 1e-9),
                               converged)

    def solve_from(self, target: float, start) -> tuple[np.ndarray, float]:
        """One target from one given start (the continuation of the activation model)."""
        a, f, _ = self._refine(np.clip(np.asarray(start, dtype=float), 0.0, 1.0), float(target))
        return a, f
