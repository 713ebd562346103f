"""The angle activation model (docs/theory.md, 6.3): a smooth map Theta -> alpha_opt(Theta) over the range.

Built by continuation along Theta on the SG (each target starts from its neighbour's solution,
so the map follows one continuous branch of minima), with a global multi-start solve beside it
at every initial knot: where the global optimum lies on another branch (alpha_opt itself jumps
there) the model keeps the continuous branch and records the place in ``branch_notes``.
Between knots the map is piecewise linear; knots are bisected until the solver, started at
the interpolated activation, lands within ``tolerance`` of the interpolation at every interval
midpoint. Piecewise linear rather than a cubic spline: alpha_opt has kinks where a muscle
leaves its bound 0 or 1, and a spline would overshoot there.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from persival.surrogate.inverse import InverseProblem

__all__ = ["AngleActivationModel", "ADMISSIBLE_RANGE_DEG", "check_angles"]

#: docs/theory.md, 6.3: the paper's admissible elbow angles (deg), cut to the reachable range if smaller
ADMISSIBLE_RANGE_DEG = (10.0, 150.0)


def check_angles(theta_deg, range_deg) -> np.ndarray:
    """Elbow angles (n,) float64, finite and inside ``range_deg`` (an angle model's), or ValueError."""
    theta = np.atleast_1d(np.asarray(theta_deg, dtype=np.float64)).reshape(-1)
    if not np.isfinite(theta).all():
        raise ValueError("elbow angles must be finite")
    lo, hi = range_deg
    outside = (theta < lo - 1e-9) | (theta > hi + 1e-9)
    if outside.any():
        raise ValueError(f"elbow angle {theta[outside][0]:.3f} deg is outside the model's range {lo:.2f} to {hi:.2f} deg")
    return theta


class AngleActivationModel:
    """``predict(theta_deg (n,)) -> activations (n, 5)``; ``torch_module()`` for the ONNX export."""

    def __init__(self, knots_deg, activations, branch_notes=None, metadata=None) -> None:
        self.knots = np.asarray(knots_deg, dtype=np.float64)
        self.values = np.asarray(activations, dtype=np.float64)
        self.branch_notes = list(branch_notes or [])
        self.metadata = dict(metadata or {})

    @property
    def range_deg(self) -> tuple[float, float]:
        return float(self.knots[0]), float(self.knots[-1])

    @classmethod
    def build(cls, problem: InverseProblem, spacing_deg: float = 2.0, tolerance: float = 2.5e-4,
              max_knots: int = 4000, progress=None) -> AngleActivationModel:
        reach = problem.reachable_range()
        lo, hi = max(ADMISSIBLE_RANGE_DEG[0], reach[0]), min(ADMISSIBLE_RANGE_DEG[1], reach[1])
        if hi - lo < 1.0:
            raise ValueError(f"the surrogate reaches {reach[0]:.1f} to {reach[1]:.1f} deg: less than one degree of "
                             f"the admissible {ADMISSIBLE_RANGE_DEG[0]:.0f}-{ADMISSIBLE_RANGE_DEG[1]:.0f} deg")
        knots = list(np.linspace(lo, hi, int(np.ceil((hi - lo) / spacing_deg)) + 1))
        global_solution = problem.solve(knots)
        values, notes = [global_solution.activations[0]], []
        for k in range(1, len(knots)):
            a, f = problem.solve_from(knots[k], values[-1])
            if global_solution.objective[k] < f - 1e-6:
                notes.append({"angle_deg": float(knots[k]), "continuous_objective": f,
                              "global_objective": float(global_solution.objective[k]),
                              "global_activations": global_solution.activations[k].tolist()})
            values.append(a)
            if progress is not None:
                progress(1, len(knots))
        knots, values, jumps, unconverged = cls._bisect(problem, knots, values, tolerance, max_knots)
        notes += [{"angle_deg": t, "jump": j, "note": "alpha_opt jumps here (the branch ends): the map "
                   "interpolates linearly across 1e-3 deg"} for t, j in jumps]
        meta = {"reachable_range_deg": list(reach), "tolerance": tolerance, "knots": len(knots),
                "effort_weight": problem.weight, "unconverged_intervals": unconverged}
        return cls(knots, values, notes, meta)

    @staticmethod
    def _bisect(problem, knots, values, tolerance, max_knots, min_width=1e-3):
        """Insert midpoints until the solver agrees with the interpolation everywhere.

        An interval narrower than ``min_width`` deg that still disagrees holds a jump of
        alpha_opt; it is reported, not split further. Returns (knots, values, jumps, unconverged):
        the intervals still disagreeing when ``max_knots`` stopped the bisection, as
        ``[{"from_deg", "to_deg", "disagreement"}]`` (also a warning).
        """
        knots, values = list(knots), [np.asarray(v) for v in values]
        pending, jumps, inserts = list(range(len(knots) - 1)), [], []
        while pending and len(knots) < max_knots:
            inserts = []
            for i in pending:
                mid = 0.5 * (knots[i] + knots[i + 1])
                guess = 0.5 * (values[i] + values[i + 1])
                if knots[i + 1] - knots[i] < min_width:
                    if np.abs(values[i + 1] - values[i]).max() > tolerance:
                        jumps.append((float(mid), float(np.abs(values[i + 1] - values[i]).max())))
                    continue
                a, _ = problem.solve_from(mid, guess)
                if np.abs(a - guess).max() > tolerance:
                    inserts.append((i, mid, a, float(np.abs(a - guess).max())))
            for i, mid, a, _ in reversed(inserts):  # back to front keeps the indices valid
                knots.insert(i + 1, mid)
                values.insert(i + 1, a)
            # the two halves of every split interval are checked again
            pending = sorted({j for n, (i, *_) in enumerate(sorted(inserts)) for j in (i + n, i + n + 1)})
        unconverged = AngleActivationModel._unconverged(knots, pending, inserts, tolerance, max_knots)
        return np.array(knots), np.array(values), jumps, unconverged

    @staticmethod
    def _unconverged(knots, pending, inserts, tolerance, max_knots) -> list[dict]:
        """The intervals ``_bisect`` left disagreeing when ``max_knots`` stopped it, with a warning.

        Each is an interval split in the last round (its two halves unchecked) with the
        disagreement found at its midpoint; where no round ran (the initial knots already reach
        ``max_knots``) every interval is unchecked and its disagreement unknown (None).
        """
        if not pending:
            return []
        if inserts:  # knot i + n (n inserts before it) and i + n + 2 bound the split interval
            out = [{"from_deg": float(knots[i + n]), "to_deg": float(knots[i + n + 2]), "disagreement": d}
                   for n, (i, _, _, d) in enumerate(inserts)]
        else:
            out = [{"from_deg": float(knots[i]), "to_deg": float(knots[i + 1]), "disagreement": None} for i in pending]
        known = [u["disagreement"] for u in out if u["disagreement"] is not None]
        worst = f"worst {max(known):.3g}" if known else "none checked"
        warnings.warn(f"activation model: bisection stopped at max_knots = {max_knots} with {len(out)} interval(s) "
                      f"where the solver still disagrees with the interpolation ({worst}; tolerance {tolerance:.3g}); "
                      "metadata['unconverged_intervals'] lists them", RuntimeWarning, stacklevel=4)
        return out

    # ------------------------------------------------------------------ evaluation
    def predict(self, theta_deg) -> np.ndarray:
        theta = check_angles(theta_deg, self.range_deg)
        return np.column_stack([np.interp(theta, self.knots, self.values[:, m]) for m in range(5)])

    def torch_module(self):
        """The same piecewise-linear map as a torch module (float32), input [batch, 1] in degrees.

        The interval is found by counting the knots below the input and the value by
        interpolating between the two knots around it, as ``predict`` does: no sum of hinge
        functions, whose cancellation would cost float32 accuracy.
        """
        import torch

        knots = torch.tensor(self.knots, dtype=torch.float32)
        values = torch.tensor(self.values, dtype=torch.float32)

        class PiecewiseLinear(torch.nn.Module):
            def __init__(self):
                super().__init__()
                self.register_buffer("knots", knots)
                self.register_buffer("values", values)

            def forward(self, theta):
                x = torch.clamp(theta, self.knots[0], self.knots[-1])  # [b, 1]
                i = (x >= self.knots[1:-1]).to(torch.int64).sum(dim=1)  # interval index [b]
                x0, x1 = self.knots[i], self.knots[i + 1]
                w = ((x[:, 0] - x0) / (x1 - x0)).unsqueeze(1)
                return self.values[i] * (1.0 - w) + self.values[i + 1] * w

        return PiecewiseLinear()

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps({"kind": "angle-activation-model", "knots_deg": self.knots.tolist(),
                                    "activations": self.values.tolist(), "branch_notes": self.branch_notes,
                                    "metadata": self.metadata}, indent=1))
        return path

    @classmethod
    def load(cls, path: str | Path) -> AngleActivationModel:
        data = json.loads(Path(path).read_text())
        if data.get("kind") != "angle-activation-model":
            raise ValueError(f"{path} is not an angle activation model")
        return cls(data["knots_deg"], data["activations"], data["branch_notes"], data["metadata"])
