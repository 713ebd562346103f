"""The motion-and-load activation model (docs/theory.md, 6.4; beyond the paper).

``(Theta, dTheta/dt, d2Theta/dt2, load) -> alpha`` on the deployed model's own moment balance
(:class:`~persival.surrogate.structured.moment_model.MomentModel`: the per-muscle FE moment tables
interpolated as the deployed graph interpolates them, and one
:class:`~persival.model.arm.external_moments.ExternalMoments`), so that the activations it gives hold
the drawn arm at the angle asked for (SPEC 5). The hinge's equation of motion about the elbow
(flexion positive, docs/theory.md, 3.1) is ``I(load) Theta'' = sum_m M_m(Theta, a_m) + M_g(Theta) +
M_load(Theta) + M_p(Theta)``, so the muscles must supply the required moment

    M_req = -(M_g + M_load + M_p) + I(load) Theta'',   M_load = -load g d sin(Theta),
    I(load) = I_0 + load d^2,   I_0 = m (1.213 r_com)^2.

d is the model file's ``forearm.hand_distance``; I_0 uses Winter's forearm-plus-hand radius of
gyration about the elbow (0.827 of the segment length, centre of mass at 0.682: ratio 1.213)
scaled to this model's centre of mass. The hinge has no damping, so the velocity enters nothing
(it is an input for the contract, checked for finiteness). Effort: ``min sum_m a_m^2`` subject
to ``sum_m M_m(Theta, a_m) = M_req``, a in [0, 1]^5 (docs/motion_model.md says why squares,
not the sum). It depends only on (Theta, M_req), so it is solved once on a grid of Theta and of
s = (M_req - M_min(Theta)) / (M_max(Theta) - M_min(Theta)) and interpolated bilinearly; a
moment outside [M_min, M_max] is infeasible: ``predict`` returns feasible=False with the
best-effort (saturated) activations, and the ONNX graph a non-zero ``moment_deficit_Nmm``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from persival.surrogate.least_effort import least_effort
from persival.vocabulary import MUSCLES

__all__ = ["MotionActivationModel", "WINTER_GYRATION_RATIO"]

WINTER_GYRATION_RATIO = 0.827 / 0.682  # radius of gyration about the elbow / centre-of-mass distance
#: activations at which each muscle's moment is sampled for the least-effort solve (docs/theory.md, 6.4)
ACTIVATION_SAMPLES = 65
SOLVE_STRIDE = 4  # the least-effort table is solved on samples 0, 4, ..., 64 (17 chords)


class MotionActivationModel:
    """``predict(motion (n, 4)) -> (activations (n, 5), feasible (n,))``; ONNX via ``export_onnx``."""

    def __init__(self, theta_deg, s_grid, alpha, base, m_min, m_max, load_base, samples, params: dict) -> None:
        self.theta = np.asarray(theta_deg, float)  # (nT,) uniform
        self.s = np.asarray(s_grid, float)  # (nS,) uniform in [0, 1]
        self.alpha = np.asarray(alpha, float)  # (nT, nS, 5)
        self.base = np.asarray(base, float)  # (nT,) -(M_g + M_p), N mm
        self.m_min, self.m_max = np.asarray(m_min, float), np.asarray(m_max, float)  # (nT,) N mm
        self.load_base = np.asarray(load_base, float)  # (nT,) -M_load per kg in the hand, N mm
        self.samples = np.asarray(samples, float)  # (nT, 5, J) M_m at J uniform activations, N mm
        self.params = dict(params)  # hand_distance_mm, gravity_m_s2, inertia_kg_mm2, ...

    @property
    def range_deg(self) -> tuple[float, float]:
        return float(self.theta[0]), float(self.theta[-1])

    @classmethod
    def build(cls, moments, theta_step_deg: float = 1.0, n_moment: int = 201, n_activation: int = ACTIVATION_SAMPLES,
              inertia_kg_mm2: float | None = None, provenance: dict | None = None) -> MotionActivationModel:
        """Solve the least-effort problem on the (Theta, s) grid on a moment balance: the deployed
        model's own (:class:`~persival.surrogate.structured.moment_model.MomentModel`, so that the
        activations it gives hold the drawn arm at the angle asked for; docs/theory.md, 6.4).

        Each muscle's moment is sampled at ``n_activation`` activations of the balance's own
        interpolation in a (a cubic spline through the table's levels): the least-effort solver
        works on the piecewise-linear interpolant of these samples (its chords differ from the
        spline by 13.75 N mm at most at 65 samples on the quick arm); ``predict`` closes the balance
        on the same chords after interpolating the table (:meth:`_balance`, docs/theory.md 6.4).
        """
        external = moments.external
        lo, hi = moments.range_deg
        # motions stay within the joint's anatomical limits (the tables reach beyond them, for
        # the static equilibria of strong co-contractions)
        lo, hi = max(lo, external.limits_deg[0]), min(hi, external.limits_deg[1])
        theta = np.linspace(lo, hi, int(round((hi - lo) / theta_step_deg)) + 1)
        levels = np.linspace(0.0, 1.0, n_activation)
        grid_t, grid_a = np.meshgrid(theta, levels, indexing="ij")
        V = np.stack([moments.muscle_moment(m, grid_t.ravel(), grid_a.ravel()).reshape(grid_t.shape) for m in MUSCLES],
                     axis=1)  # (nT, 5, J)
        m_min, m_max = V.min(axis=2).sum(axis=1), V.max(axis=2).sum(axis=1)
        s = np.linspace(0.0, 1.0, n_moment)
        R = m_min[:, None] + s[None, :] * (m_max - m_min)[:, None]
        # the table is solved on every fourth sample's chords (a quarter of the work): predict
        # closes the balance on all of them afterwards (_balance), which sets the angle's accuracy
        coarse = slice(None, None, SOLVE_STRIDE)
        a, _ = least_effort(np.repeat(V[:, :, coarse], n_moment, axis=0), levels[coarse], R.ravel())
        params = {
            "hand_distance_mm": external.hand_distance_mm, "gravity_m_s2": external.gravity_m_s2,
            "inertia_kg_mm2": float(inertia_kg_mm2 or external.mass_kg
                                    * (WINTER_GYRATION_RATIO * external.centre_of_mass_mm) ** 2),
            "forearm_mass_kg": external.mass_kg, "effort": "sum of squared activations",
            "balance": "the deployed model's moment balance", "activation_samples": int(n_activation),
            **(provenance or {})}
        base = -external.value(theta)
        load_base = external.gravity(theta) - external.gravity(theta, 1.0)
        return cls(theta, s, a.reshape(len(theta), n_moment, 5), base, m_min, m_max, load_base, V, params)

    @classmethod
    def from_table(cls, table, spec, **options) -> MotionActivationModel:
        """From a complete FE moment table (``persival moments``) and its model file's forearm and
        joint, through the same moment balance the deployed model fits to it."""
        from persival.surrogate.structured.moment_model import MomentModel

        if not table.complete:
            raise ValueError(f"the moment table is unfinished ({int(table.done.sum())} of {table.done.size} columns)")
        # near_deg picks among equilibria; the motion model prescribes the angle and needs none
        moments = MomentModel.from_table(table, spec, near_deg=table.finite_range_deg()[0])
        provenance = {"model_hash": table.meta.get("model_hash"), "profile": table.meta.get("profile")}
        return cls.build(moments, provenance=provenance, **options)

    # ------------------------------------------------------------------ evaluation
    def _check(self, motion) -> np.ndarray:
        m = np.atleast_2d(np.array(motion, dtype=np.float64))
        if m.ndim != 2 or m.shape[1] != 4:
            raise ValueError(f"motion must have shape (n, 4) (deg, deg/s, deg/s^2, kg), got {m.shape}")
        if not np.isfinite(m).all():
            raise ValueError(f"motion: {int((~np.isfinite(m).all(axis=1)).sum())} row(s) are not finite")
        if (m[:, 3] < 0).any():
            raise ValueError(f"motion: the load must be >= 0 kg, got {float(m[m[:, 3] < 0, 3][0])!r}")
        (lo, hi), out = self.range_deg, m[(m[:, 0] < self.range_deg[0] - 1e-9) | (m[:, 0] > self.range_deg[1] + 1e-9)]
        if len(out):
            raise ValueError(f"motion: elbow angle {out[0, 0]:.3f} deg is outside the model's range {lo:.2f} to {hi:.2f} deg")
        return m

    def required_moment(self, motion) -> np.ndarray:
        """M_req (N mm) of the muscles for (angle, velocity, acceleration, load) rows (docs/theory.md, 6.4)."""
        return self._required(self._check(motion), np, self.base, self.load_base)

    def _required(self, m, xp, base, load_base):
        """The moment balance of docs/theory.md, 6.4, written once for numpy and torch (``xp``); the
        external moments are tabulated on the angle grid from the one ExternalMoments the deployed
        model balances (linear between 1-degree nodes: under 0.7 N mm)."""
        p = self.params
        theta, acc, load = m[:, 0], m[:, 2], m[:, 3]
        i, w = self._cell(theta, self.theta, xp)
        at = lambda values: values[i] * (1 - w) + values[i + 1] * w  # noqa: E731
        d = p["hand_distance_mm"]
        inertia = 1e-3 * (p["inertia_kg_mm2"] + load * d**2) * acc * (np.pi / 180.0)  # kg mm^2 rad/s^2 -> N mm
        return at(base) + load * at(load_base) + inertia

    def _interp_theta(self, theta, values, xp):
        i, w = self._cell(theta, self.theta, xp)
        return values[i] * (1 - w) + values[i + 1] * w

    @staticmethod
    def _cell(x, grid, xp):
        """Cell index and weight on a uniform grid (clamped), the same arithmetic in numpy and torch."""
        n = len(grid)
        u = (x - float(grid[0])) * ((n - 1) / float(grid[-1] - grid[0]))
        u = xp.clip(u, 0.0, n - 1.0) if xp is np else u.clamp(0.0, n - 1.0)
        i = xp.floor(u).astype(np.int64) if xp is np else xp.floor(u).long()
        i = xp.clip(i, 0, n - 2) if xp is np else i.clamp(0, n - 2)
        return i, u - i

    _ARRAYS = ("alpha", "m_min", "m_max", "base", "load_base", "samples")
    #: bisection steps that close the balance after the table's interpolation (docs/theory.md, 6.4)
    BALANCE_STEPS = 16  # t to 3e-5 of a full range: the angles of 30 steps, half the graph (docs/theory.md 6.4)
    BALANCE_PHASES = 3

    def _evaluate(self, m, xp, tables):
        """Activations and the signed moment deficit (N mm; 0 where feasible) for checked rows."""
        alpha, m_min, m_max, base, load_base, samples = tables
        R = self._required(m, xp, base, load_base)
        lo, hi = self._interp_theta(m[:, 0], m_min, xp), self._interp_theta(m[:, 0], m_max, xp)
        i, wt = self._cell(m[:, 0], self.theta, xp)
        j, ws = self._cell((R - lo) / (hi - lo), self.s, xp)
        nS = len(self.s)
        flat = alpha.reshape(-1, 5)
        wt, ws = wt[:, None], ws[:, None]
        a = ((flat[i * nS + j] * (1 - ws) + flat[i * nS + j + 1] * ws) * (1 - wt)
             + (flat[(i + 1) * nS + j] * (1 - ws) + flat[(i + 1) * nS + j + 1] * ws) * wt)
        relu = (lambda x: np.maximum(x, 0.0)) if xp is np else xp.relu
        deficit = relu(R - hi) - relu(lo - R)
        return self._balance(a, R, (i, wt), samples, deficit == 0.0, xp), deficit

    def _balance(self, a, R, cell, samples, feasible, xp):
        """Close the balance sum_m M_m(a_m) = R (to the samples' chords) after the bilinear
        interpolation of the activation table, which misses it by up to about 100 N mm where a
        muscle saturates between grid nodes (0.77 deg at 145 deg on the quick arm): the muscles
        strictly inside (0, 1) move along their moment slopes, the direction least effort moves
        them in (its optimality condition 2 a_m = lambda dM_m/da_m), by the step a bisection finds
        (a Newton step overshoots where a chord's slope changes). Infeasible rows keep the
        saturated best effort."""
        i, wt = cell
        V = samples[i] * (1 - wt[:, :, None]) + samples[i + 1] * wt[:, :, None]  # (b, 5, J) at theta
        for _ in range(self.BALANCE_PHASES):  # a muscle that saturates in one phase leaves the next's direction
            moment, slope = self._chords(V, a, xp)
            free = (a > 1e-9) & (a < 1.0 - 1e-9) & feasible[:, None]
            d = xp.where(free, slope, 0.0 * slope)
            scale = xp.abs(d).max(1) if xp is np else xp.abs(d).amax(1)
            e = d / xp.where(scale > 0, scale, 1.0 + 0.0 * scale)[:, None]  # |t| <= 1: the steepest crosses [0, 1]
            lo, hi = -1.0 + 0.0 * R, 1.0 + 0.0 * R
            for _ in range(self.BALANCE_STEPS):
                t = 0.5 * (lo + hi)
                short = self._chords(V, xp.clip(a + t[:, None] * e, 0.0, 1.0), xp)[0].sum(1) < R
                lo, hi = xp.where(short, t, lo), xp.where(short, hi, t)
            moved = xp.clip(a + (0.5 * (lo + hi))[:, None] * e, 0.0, 1.0)
            # kept only where it closes the balance further: a moment that is not monotone along the
            # direction (a chord's slope changing sign) can mislead the bisection
            better = xp.abs(self._chords(V, moved, xp)[0].sum(1) - R) < xp.abs(moment.sum(1) - R)
            a = xp.where(better[:, None], moved, a)
        return a

    @staticmethod
    def _chords(V, a, xp):
        """M_m(a_m) and dM_m/da_m on the chords through the uniform samples V (b, 5, J)."""
        steps = V.shape[2] - 1
        u = a * steps
        j = xp.clip(xp.floor(u), 0, steps - 1)
        if xp is np:
            j = j.astype(np.int64)
            v0, v1 = np.take_along_axis(V, j[:, :, None], 2)[..., 0], np.take_along_axis(V, j[:, :, None] + 1, 2)[..., 0]
        else:
            j = j.long()
            v0, v1 = V.gather(2, j[:, :, None])[..., 0], V.gather(2, j[:, :, None] + 1)[..., 0]
        return v0 + (v1 - v0) * (u - j), (v1 - v0) * steps

    def predict(self, motion, with_deficit: bool = False):
        """Activations (n, 5) and feasible (n,) bool; infeasible rows are flagged, not clipped
        silently (their activations are the saturated best effort). Raises ValueError on bad
        input: not (n, 4), not finite, a negative load or an angle outside the range."""
        a, deficit = self._evaluate(self._check(motion), np, tuple(getattr(self, k) for k in self._ARRAYS))
        return (a, deficit == 0.0, deficit) if with_deficit else (a, deficit == 0.0)

    def holdable_load_kg(self, theta_deg) -> np.ndarray:
        """Largest load held statically at each angle (inf where the load does not pull the arm down)."""
        theta = np.atleast_1d(np.asarray(theta_deg, float))
        spare = np.interp(theta, self.theta, self.m_max) - np.interp(theta, self.theta, self.base)
        lever = np.interp(theta, self.theta, self.load_base)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(lever > 1e-9, np.maximum(spare, 0.0) / lever, np.inf)

    def static_range_deg(self, lowest_deg: float = 10.0) -> tuple[float, float]:
        """The angles the muscles hold with no load, from ``lowest_deg`` (the paper's admissible 10
        deg) up: the unbroken run of the grid where [M_min, M_max] holds the required moment."""
        ok = (self.base >= self.m_min - 1e-9) & (self.base <= self.m_max + 1e-9) & (self.theta >= lowest_deg - 1e-9)
        if not ok.any():
            raise ValueError(f"no angle from {lowest_deg:g} deg on is held by the muscles with no load")
        start = int(np.argmax(ok))
        stop = start + (int(np.argmin(ok[start:])) if not ok[start:].all() else len(ok) - start)
        return max(float(self.theta[start]), lowest_deg), float(self.theta[stop - 1])

    def at_rest(self, lowest_deg: float = 10.0):
        """The angle activation model of this balance: Theta -> alpha at zero velocity, acceleration and
        load (:class:`persival.surrogate.rest_angle_model.RestAngleModel`)."""
        from persival.surrogate.rest_angle_model import RestAngleModel

        return RestAngleModel(self, self.static_range_deg(lowest_deg))

    # ------------------------------------------------------------------ export and files
    def torch_module(self):
        import torch

        model = self

        class MotionGraph(torch.nn.Module):
            def __init__(self):
                super().__init__()
                for name in model._ARRAYS:
                    self.register_buffer(name, torch.tensor(getattr(model, name), dtype=torch.float64))

            def forward(self, motion):  # float64 inside: the float32 contract costs only the output's rounding
                tables = tuple(getattr(self, k) for k in model._ARRAYS)
                a, deficit = model._evaluate(motion.double(), torch, tables)
                return a.float(), deficit.unsqueeze(1).float()

        return MotionGraph()

    def export_onnx(self, folder: str | Path) -> dict:
        """folder/activation_motion.onnx (persival.surrogate.motion_onnx) and its metadata entry."""
        from persival.surrogate.motion_onnx import export_motion_onnx

        return export_motion_onnx(self, folder)

    def save(self, folder: str | Path) -> Path:
        (folder := Path(folder)).mkdir(parents=True, exist_ok=True)
        np.savez(folder / "motion_model.npz", theta=self.theta, s=self.s, **{k: getattr(self, k) for k in self._ARRAYS})
        (folder / "motion_model.json").write_text(json.dumps({"kind": "motion-activation-model", **self.params}, indent=1))
        return folder

    @classmethod
    def load(cls, folder: str | Path) -> MotionActivationModel:
        params = json.loads(((folder := Path(folder)) / "motion_model.json").read_text())
        if params.pop("kind", None) != "motion-activation-model":
            raise ValueError(f"{folder} does not hold a motion activation model")
        with np.load(folder / "motion_model.npz") as d:
            if "samples" not in d.files:
                raise ValueError(f"{folder}: a motion model of an older version (no moment samples): build it again")
            return cls(d["theta"], d["s"], *(d[k] for k in ("alpha", "base", "m_min", "m_max", "load_base", "samples")),
                       params)
