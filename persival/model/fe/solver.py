"""Quasi-static total-Lagrangian solver: Newton-Raphson, line search, adaptive load stepping.

Unknowns are the displacements of the nodes not held by a constraint. A load factor t runs
from 0 to 1; activation and prescribed displacements are interpolated along it
(continuation, docs/theory.md, 2.3). Each step is solved by Newton's method with the consistent tangent;
the step is halved when Newton fails (divergence, an inverted element, a singular tangent)
and grows again after easy steps. The linear algebra on the free DOFs (factorizations, their
reuse, the condensed response) is persival.model.fe.free_dofs.

One module on purpose (a numerical kernel over 300 lines): load stepping, Newton, the line
search and the step control share one state (the current tangent, its factorization and the
step history), which a split would have to pass back and forth.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from persival.model.fe.assembly import InvertedElementError, MaterialField, Tet10Assembler
from persival.model.fe.constraints import Dirichlet, Hinge
from persival.model.fe.free_dofs import FreeDofs
from persival.model.fe.linear_solver import SingularMatrixError
from persival.model.fe.mesh import Tet10Mesh

log = logging.getLogger(__name__)


class ConvergenceError(RuntimeError):
    """The load stepping could not reach t = 1 (the step size fell below its minimum)."""


class InvertedStartError(ConvergenceError):
    """The start state has inverted elements (det F <= 0): no state to continue from. A
    ConvergenceError, so callers that fall back to another start (a library guess, a detour) still do."""

    def __init__(self, n_inverted: int, where: str) -> None:
        super().__init__(f"{where} has {n_inverted} inverted element(s) (det F <= 0): no state to solve from")
        self.n_inverted, self.where = n_inverted, where

    def __reduce__(self):  # rebuilt from its own arguments where a campaign worker sends it back
        return type(self), (self.n_inverted, self.where)


@dataclass
class SolverOptions:
    rtol: float = 1e-8  # residual relative to the load-step force scale
    atol: float = 1e-9  # N, absolute floor of the residual tolerance
    max_iterations: int = 20
    initial_step: float = 0.25
    min_step: float = 1.0 / 256.0
    max_line_search: int = 6
    moment_atol: float = 1e-4  # N mm, hinge moment residual at convergence (free hinge)
    # ... or this share of the muscles' summed |moments|, where larger (ArmModel's joint
    # iteration): each muscle's moment is exact only to its own Newton tolerance (rtol of its
    # forces), and summed moments of 1e4 to 1e5 N mm put that noise floor near 1e-4 N mm
    moment_rtol: float = 1e-7
    max_angle_step: float = 5.0  # deg, largest hinge-angle change of one Newton iteration
    joint_max_step: float = 15.0  # deg, largest angle change of one staggered joint iteration (ArmModel)
    # ... and the root is taken as found once its bracket is this narrow (deg) while the residual
    # is within joint_noise_factor of the tolerance: muscles in frictionless contact with a wall
    # carry a moment noise of a few hundredths of a N mm (0.03 N mm measured in a hanging arm),
    # which can keep |g| above a 2e-4 N mm tolerance at a root already bracketed
    joint_bracket_deg: float = 1e-4
    joint_noise_factor: float = 1e3
    # ... or where the floor keeps g's sign and the iteration creeps towards the root from one side
    # (8.2e-4 N mm at 33.32 deg in a hanging arm; 0.21 N mm at 140.3 deg with the flexors fully
    # active, by Newton steps of 6e-4 deg): once a step cuts |g| by less than this ratio and the next
    # one would be shorter than joint_stall_deg
    joint_stall_ratio: float = 0.9
    joint_stall_deg: float = 1e-3
    backend: str = "auto"
    # Newton directions from the last factorization this solver made (of a nearby tangent: an
    # earlier iteration, or the previous solve of the same body), refined against the current
    # tangent; a factorization only where the refinement does not contract (no hinge only)
    reuse_factorization: bool = False
    # each load step starts from the previous one extrapolated along its secant; without it, from
    # the tangent's response to the prescribed motion (one more factorization per step). Bodies in
    # contact with each other need the latter: an extrapolation can carry a point through the
    # thin part of its neighbour, into a spurious equilibrium
    secant_predictor: bool = True


@dataclass
class NewtonStatistics:
    steps: int = 0
    step_cuts: int = 0
    iterations: int = 0
    residual_histories: list[list[float]] = field(default_factory=list)
    time_assembly: float = 0.0
    time_factorization: float = 0.0
    time_solve: float = 0.0
    n_assemblies: int = 0
    n_factorizations: int = 0
    n_reused: int = 0  # Newton directions from an earlier factorization (options.reuse_factorization)
    wall_time: float = 0.0


@dataclass
class Reaction:
    force: np.ndarray  # N, exerted by the constraint on the body
    moment: np.ndarray  # N mm, about the constraint's centre


@dataclass
class StaticSolution:
    displacement: np.ndarray  # (n_nodes, 3) mm
    reactions: dict[str, Reaction]
    statistics: NewtonStatistics
    max_volume_change: float  # max |det F - 1| over quadrature points
    hinge_angle_deg: float | None = None  # the free hinge's equilibrium angle
    hinge_moment_residual: float = 0.0  # N mm: muscles + external moment at convergence
    # upper-triangle tangent at ``displacement`` (None when no Newton step assembled one); the
    # solver's factorization is then of a tangent one Newton step away (condensed_response reuses it)
    tangent: sp.csr_matrix | None = None
    # (n_dofs,) N: the internal force at ``displacement``; on the constrained DOFs, the reactions per DOF
    internal_force: np.ndarray | None = None


class QuasiStaticSolver:
    """Solve ``f_int(u) = 0`` on the free DOFs of a tet10 body under boundary constraints.

    With a free :class:`Hinge`, the hinge angle is one more unknown: its equation is the
    moment balance ``dPi/dtheta = f_h . dx_h/dtheta - M_ext(theta) = 0`` and Newton solves the
    symmetric bordered system by a Schur complement on the factorized ``K_ff`` (two right-hand
    sides, one factorization).

    ``extra_terms``: further potential terms (contact with rigid obstacles, docs/theory.md, 3.5; see
    :mod:`persival.model.fe.contact`). Each has ``force_and_tangent(x) -> (f (n_dofs,), K)`` at the
    current node positions ``x = X + u`` (n_nodes, 3): its gradient and its full symmetric
    Hessian (sparse, n_dofs x n_dofs), added to the residual and the tangent, and ``force(x)``
    (the gradient alone). K's entries must lie in the FE pattern (a node's own 3x3 block always
    does): they are added into the assembled matrix in place, so the pattern, and the sparse
    solver's symbolic analysis, stay fixed while a contact active set changes; a term with
    ``couples_bodies`` (contact between bodies) may go beyond it. An optional ``set_load_factor(t)`` is called
    before each load step's Newton iterations. A term that depends on a free hinge's angle is
    not linearized in it (prescribed angles and fixed obstacles are exact).
    """

    def __init__(
        self,
        mesh: Tet10Mesh,
        material: MaterialField,
        constraints: list[Dirichlet | Hinge],
        options: SolverOptions | None = None,
        quadrature_order: int = 2,
        assembler: Tet10Assembler | None = None,
        extra_terms: list | None = None,
    ) -> None:
        self.mesh = mesh
        self.extra_terms = list(extra_terms or [])
        self.material = material
        self.constraints = list(constraints)
        self.options = options or SolverOptions()
        self.assembler = assembler or Tet10Assembler(mesh, quadrature_order)
        if material.fibre.shape[:2] != self.assembler.weights.shape:
            raise ValueError("material field does not match the mesh and quadrature")
        n = self.assembler.n_dofs
        constrained = np.zeros(n, dtype=bool)
        for c in self.constraints:
            dofs = c.dofs
            if dofs.max() >= n:
                raise ValueError(f"constraint {c.name!r} refers to nodes outside the mesh")
            if np.any(constrained[dofs]):
                raise ValueError(f"constraint {c.name!r} overlaps another constraint")
            constrained[dofs] = True
        if constrained.all():
            raise ValueError("every degree of freedom is constrained: nothing to solve")
        free_hinges = [c for c in self.constraints if isinstance(c, Hinge) and c.free]
        if len(free_hinges) > 1:
            raise ValueError("at most one free hinge is supported")
        self.hinge: Hinge | None = free_hinges[0] if free_hinges else None
        self.constrained = constrained
        self.system = FreeDofs(self.assembler.pattern_rows, self.assembler.pattern_cols, constrained,
                               self.options.backend)
        self.free = self.system.free
        self._moment_offset = self._initial_moment_residual = 0.0
        if self.hinge is not None:
            # length that turns the hinge moment into a force for the combined residual norm
            arm = np.linalg.norm(np.cross(self.mesh.points[self.hinge.nodes] - self.hinge.centre, self.hinge.axis), axis=1)
            self._moment_length = max(float(np.sqrt(np.mean(arm**2))), 1e-12)

    # ------------------------------------------------------------------------------------------
    def _apply_constraints(self, u: np.ndarray, t: float, theta: float | None) -> None:
        for c in self.constraints:
            if c is self.hinge:
                u[c.dofs] = c.displacement_at(self.mesh.points, theta)
            else:
                u[c.dofs] = c.values(self.mesh.points, t)

    def tangent(self, u: np.ndarray, activation: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
        """Upper-triangle tangent (the assembler's fixed pattern) and residual force of the whole
        potential: elasticity plus the extra terms."""
        K, f = self.assembler.tangent(u, self.material, activation)
        if self.extra_terms:
            f = self._add_extra_terms(u, f, K)
        return K, f

    def internal_force(self, u: np.ndarray, activation: np.ndarray) -> np.ndarray:
        """Residual force of the whole potential (elasticity plus the extra terms)."""
        f = self.assembler.internal_force(u, self.material, activation)
        return self._add_extra_terms(u, f) if self.extra_terms else f

    def _add_extra_terms(self, u, f, K=None):
        """f + sum of the terms' forces (e.g. contact, docs/theory.md, 3.5); their tangents' upper triangles
        are added into K.data."""
        x = self.mesh.points + np.asarray(u, dtype=float).reshape(-1, 3)
        for term in self.extra_terms:
            if K is None:
                f = f + term.force(x)
                continue
            f_term, K_term = term.force_and_tangent(x)
            f = f + f_term
            self.system.add_into(K, K_term, type(term).__name__, getattr(term, "couples_bodies", False))
        return f

    def matvec(self, K, x: np.ndarray) -> np.ndarray:
        """K x for the upper-triangle tangent (persival.model.fe.free_dofs)."""
        return self.system.matvec(K, x)

    def _set_load_factor(self, t: float) -> None:
        for term in self.extra_terms:
            if hasattr(term, "set_load_factor"):
                term.set_load_factor(t)

    def _assemble(self, u, activation, stats):
        t0 = time.perf_counter()
        K, f = self.tangent(u, activation)
        stats.time_assembly += time.perf_counter() - t0
        stats.n_assemblies += 1
        return K, f

    def _hinge_terms(self, u, theta, K=None, f=None):
        """Moment residual r_theta and, with K, the border K_f,theta and K_theta,theta."""
        h = self.hinge
        dx, d2x = h.velocity(self.mesh.points, theta)  # per radian
        f_h = f.reshape(-1, 3)[h.nodes]
        M_ext, dM_ext = h.external_moment(np.radians(theta))
        r_theta = float(np.sum(f_h * dx)) - M_ext - self._moment_offset
        if K is None:
            return r_theta, None, None
        G = np.zeros(self.assembler.n_dofs)
        G[h.dofs] = dx.ravel()
        KG = self.matvec(K, G)
        k_tt = float(G @ KG) + float(np.sum(f_h * d2x)) - dM_ext
        return r_theta, KG[self.free], k_tt

    def hinge_balance(self, u: np.ndarray, theta: float, activation: np.ndarray) -> tuple[float, float]:
        """Moment residual dPi/dtheta (N mm) of the free hinge at (u, theta) and the joint
        stiffness with the free DOFs re-equilibrated: the Schur complement
        k_tt - k_ft . K_ff^-1 k_ft (N mm/rad) of the bordered Hessian."""
        if self.hinge is None:
            raise ValueError("this problem has no free hinge")
        self._moment_offset = 0.0
        K, f = self.tangent(np.asarray(u, dtype=float).ravel(), activation)
        r_theta, k_ft, k_tt = self._hinge_terms(np.asarray(u, dtype=float).ravel(), theta, K, f)
        self.system.linear_solver.factorize(self.system.free_upper(K))
        return r_theta, float(k_tt - k_ft @ self.system.linear_solver.solve(k_ft))

    def condensed_response(self, K: sp.csr_matrix, g: np.ndarray, reuse_factorization: bool = False,
                           force_rate: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """The Schur complement along a motion g of the constrained DOFs and du/ds
        (:meth:`FreeDofs.condensed_response`)."""
        return self.system.condensed_response(K, g, reuse_factorization, force_rate)

    def _residual_norm(self, f, r_theta):
        norm = float(np.linalg.norm(f[self.free]))
        if self.hinge is None:
            return norm
        return float(np.hypot(norm, r_theta / self._moment_length))

    def _direction(self, u, theta, K, f, r_theta, stats, rtol: float) -> tuple[np.ndarray, float]:
        """The Newton direction: du on the free DOFs (to a relative linear residual ``rtol``
        where a factorization is reused) and, with a free hinge, dtheta (deg) from the bordered
        system by its Schur complement on the factorized K_ff (two right-hand sides)."""
        r = f[self.free]
        if self.hinge is None:
            return self.system.newton_direction(K, -r, stats, rtol, self.options.reuse_factorization), 0.0
        _, k_ft, k_tt = self._hinge_terms(u, theta, K, f)
        x = self.system.factorize_and_solve(K, np.column_stack([-r, k_ft]), stats)
        schur = k_tt - k_ft @ x[:, 1]
        if schur == 0.0 or not np.isfinite(schur):
            raise SingularMatrixError("bordered hinge system is singular")
        dtheta = (-r_theta - k_ft @ x[:, 0]) / schur
        du = x[:, 0] - x[:, 1] * dtheta
        dtheta = float(np.degrees(dtheta))
        # Trust region on the angle: near a fold of the equilibrium path the Schur
        # complement (the effective joint stiffness) nearly vanishes and the raw step
        # flies off (seen: 212 deg for a 1372 N mm imbalance at 370 N mm/rad).
        if abs(dtheta) > self.options.max_angle_step:
            shrink = self.options.max_angle_step / abs(dtheta)
            du, dtheta = du * shrink, dtheta * shrink
        return du, dtheta

    def _line_search(self, u, theta, du, dtheta, r, r_theta, norm, tolerance, t, activation, stats):
        """The accepted point along (du, dtheta): (u, theta, K, f, |r|, r_theta) there.

        The problem is hyperelastic, so the Newton direction should lower the potential:
        s(eta) = dPi/deta = d . r(u + eta d) is its slope along the direction. Accept a step
        that lowers the residual norm or flattens the slope (|s| <= 0.5 |s(0)|: the energy
        minimum along d is near); otherwise move eta by regula falsi on s. The slope test copes
        with the kinks of the fibre laws at lambda = 1, where the residual norm alone often
        refuses good steps."""
        slope0 = float(du @ r) + (np.radians(dtheta) * r_theta if self.hinge else 0.0)
        eta = 1.0
        for _ in range(self.options.max_line_search + 1):
            trial = u.copy()
            trial[self.free] += eta * du
            theta_t = None if theta is None else theta + eta * dtheta
            if self.hinge is not None:
                self._apply_constraints(trial, t, theta_t)
            try:
                K_t, f_t = self._assemble(trial, activation, stats)
                r_theta_t = self._hinge_terms(trial, theta_t, f=f_t)[0] if self.hinge else 0.0
                norm_t = self._residual_norm(f_t, r_theta_t)
                slope = float(du @ f_t[self.free]) + (np.radians(dtheta) * r_theta_t if self.hinge else 0.0)
                flattened = slope0 < 0 and abs(slope) <= 0.5 * abs(slope0)
                if norm_t < (1.0 - 1e-4 * eta) * norm or norm_t <= tolerance or flattened:
                    return trial, theta_t, K_t, f_t, norm_t, r_theta_t
                if slope0 < 0 < slope:  # overshot the minimum along d: interpolate
                    eta = min(max(eta * slope0 / (slope0 - slope), 0.1 * eta), 0.9 * eta)
                    continue
            except InvertedElementError:
                pass
            eta *= 0.5
        raise ConvergenceError("line search failed to reduce the residual")

    def _newton_step(self, u_start, theta_start, t, activation, stats, secant=None):
        """Solve at load factor t from the converged state; return (u, theta, K, f, history).

        ``secant``: (du, dtheta) over the previous step scaled to this one; the extrapolation
        along it is the predictor of continuation. Without one (or if it folds an element), the
        free DOFs follow the prescribed ones linearly, so a boundary jump does not crush the
        first element layer.
        """
        opts = self.options
        self._set_load_factor(t)
        # residual homotopy: the initial state's moment imbalance is released along t
        self._moment_offset = (1.0 - t) * self._initial_moment_residual

        def predict(use_secant: bool):
            u = u_start.copy()
            theta = theta_start
            if use_secant:
                u += secant[0]
                theta = None if theta is None else theta + secant[1]
            self._apply_constraints(u, t, theta)
            if not use_secant:
                jump = u - u_start
                # a start whose faces already sit where they go (up to the float32 rounding of a
                # stored state) needs no predictor: it would cost a factorization for nothing
                if np.abs(jump).max() > 1e-6 * (1.0 + np.abs(u_start).max()):
                    K, _ = self._assemble(u_start, activation, stats)
                    u[self.free] += self.system.factorize_and_solve(K, -self.matvec(K, jump)[self.free], stats)
            return u, theta

        try:
            u, theta = predict(secant is not None)
            K, f = self._assemble(u, activation, stats)
        except InvertedElementError:
            if secant is None:
                raise
            u, theta = predict(False)  # the extrapolation folded an element: predict linearly
            K, f = self._assemble(u, activation, stats)
        r_theta = self._hinge_terms(u, theta, f=f)[0] if self.hinge else 0.0
        norm = self._residual_norm(f, r_theta)
        scale = max(float(np.linalg.norm(f[self.constrained])), norm)
        tolerance = opts.rtol * scale + opts.atol
        history = [norm]

        def converged():
            moment_tolerance = max(opts.moment_atol, opts.rtol * self._moment_length * scale if self.hinge else 0.0)
            return norm <= tolerance and abs(r_theta) <= moment_tolerance

        for _ in range(opts.max_iterations):
            if converged():
                return u, theta, K, f, history
            r = f[self.free]
            # linear residual at most a tenth of what the Newton tolerance leaves (and 1e-3)
            du, dtheta = self._direction(u, theta, K, f, r_theta, stats, min(1e-3, 0.1 * tolerance / max(norm, 1e-300)))
            u, theta, K, f, norm, r_theta = self._line_search(u, theta, du, dtheta, r, r_theta, norm, tolerance, t,
                                                              activation, stats)
            history.append(norm)
            stats.iterations += 1
        if converged():
            return u, theta, K, f, history
        raise ConvergenceError(f"Newton did not converge in {opts.max_iterations} iterations (|r| = {norm:.3e})")

    def solve(
        self,
        activation,
        initial_displacement: np.ndarray | None = None,
        initial_activation=None,
        initial_angle: float | None = None,
        progress=None,
    ) -> StaticSolution:
        """Continue from (initial_displacement, initial_activation) at t = 0 to ``activation`` at t = 1.

        ``activation`` is a scalar or per-cell array in [0, 1]. With a free hinge,
        ``initial_angle`` (deg) starts its angle (default: the hinge's ``start_deg``); the
        initial displacement must then be consistent with it. ``progress(t)`` is called after
        each accepted load step.
        """
        m = self.mesh.n_cells
        target, start, u, theta = self._validated_start(activation, initial_displacement, initial_activation,
                                                        initial_angle)
        stats = NewtonStatistics()
        self.system.factor_is_recent = False
        tangent = None
        wall = time.perf_counter()
        opts = self.options
        self._moment_offset = 0.0
        self._initial_moment_residual = self._start_imbalance(u, theta, start)
        t, dt = 0.0, min(1.0, opts.initial_step)
        f = None
        rate = None  # (du/dt, dtheta/dt) of the last accepted step
        while t < 1.0:
            t_new = min(1.0, t + dt)
            act = start + t_new * (target - start)
            secant = None if rate is None or not opts.secant_predictor else ((t_new - t) * rate[0],
                                                                             (t_new - t) * rate[1])
            try:
                u_new, theta_new, tangent, f, history = self._newton_step(u, theta, t_new, act, stats, secant)
            except (ConvergenceError, InvertedElementError, SingularMatrixError) as exc:
                log.debug("step t=%.4f -> %.4f failed (%s); halving", t, t_new, exc)
                stats.step_cuts += 1
                dt *= 0.5
                if dt < opts.min_step:
                    raise ConvergenceError(f"load step fell below {opts.min_step} at t = {t:.4f}: {exc}") from exc
                continue
            log.debug("step t=%.4f -> %.4f converged in %d iterations: %s", t, t_new, len(history) - 1,
                      " ".join(f"{v:.1e}" for v in history))
            stats.residual_histories.append(history)
            stats.steps += 1
            rate = ((u_new - u) / (t_new - t), 0.0 if theta is None else (theta_new - theta) / (t_new - t))
            u, theta, t = u_new, theta_new, t_new
            if progress is not None:
                progress(t)
            if len(history) <= 7:  # easy step: grow (gently: a failed try costs 20 iterations)
                dt = min(1.5 * dt, 1.0)
        stats.wall_time = time.perf_counter() - wall
        if f is None:  # nothing to do: report the reactions of the initial state
            f = self.internal_force(u, np.broadcast_to(target, (m,)).copy())
        self._moment_offset = 0.0
        r_theta = self._hinge_terms(u, theta, f=f)[0] if self.hinge is not None else 0.0
        return StaticSolution(
            displacement=u.reshape(-1, 3),
            reactions=self._reactions(u, f),
            statistics=stats,
            max_volume_change=float(np.abs(np.linalg.det(self.assembler.deformation_gradient(u)) - 1.0).max()),
            hinge_angle_deg=theta,
            hinge_moment_residual=r_theta,
            tangent=tangent if self.system.factor_is_recent else None,
            internal_force=f,
        )

    def _validated_start(self, activation, initial_displacement, initial_activation, initial_angle):
        """(target activation, start activation, u, theta) of a solve, checked."""
        target = self._validated_activation(activation, "activation")
        start = (target * 0.0 if initial_activation is None
                 else self._validated_activation(initial_activation, "initial_activation"))
        u = (np.zeros(self.assembler.n_dofs) if initial_displacement is None
             else np.asarray(initial_displacement, dtype=float).reshape(-1).copy())
        if u.shape != (self.assembler.n_dofs,) or not np.all(np.isfinite(u)):
            raise ValueError("initial_displacement must be a finite (n_nodes, 3) array")
        theta = None
        if self.hinge is not None:
            theta = float(self.hinge.start_deg if initial_angle is None else initial_angle)
            if not np.isfinite(theta):
                raise ValueError("initial_angle must be finite")
        self._check_not_inverted(u, "the start")
        return target, start, u, theta

    def _check_not_inverted(self, u, where: str) -> None:
        """Refuse a state with det F <= 0 at some quadrature point, naming how many elements. Let
        through, every load step from it fails and is halved down to ``min_step`` (a misleading
        "load step fell below"), and on a free hinge its moment imbalance, which cannot be
        evaluated there, would count as zero: a balanced start."""
        det = np.linalg.det(self.assembler.deformation_gradient(u))
        n_inverted = int(np.count_nonzero((~(det > 0.0)).any(axis=1)))  # NaN counts as inverted too
        if n_inverted:
            raise InvertedStartError(n_inverted, where)

    def _start_imbalance(self, u, theta, activation) -> float:
        """The free hinge's moment residual at the start (0 without one). An unbalanced start (a
        state posed with theta prescribed, say) cannot take the full moment in one step: its
        imbalance is released gradually along t (the residual homotopy of _newton_step)."""
        if self.hinge is None:
            return 0.0
        u0 = u.copy()
        self._apply_constraints(u0, 0.0, theta)
        self._check_not_inverted(u0, f"the start posed at the hinge angle {theta:.2f} deg")
        self._set_load_factor(0.0)
        return self._hinge_terms(u0, theta, f=self.internal_force(u0, activation))[0]

    def _validated_activation(self, activation, name) -> np.ndarray:
        a = np.asarray(activation, dtype=float)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contains NaN or inf")
        if np.any((a < 0.0) | (a > 1.0)):
            raise ValueError(f"{name} must lie in [0, 1], got [{a.min()}, {a.max()}]")
        try:
            return np.broadcast_to(a, (self.mesh.n_cells,)).astype(float)
        except ValueError:
            raise ValueError(f"{name} must be a scalar or one value per cell ({self.mesh.n_cells})") from None

    def _reactions(self, u: np.ndarray, f: np.ndarray) -> dict[str, Reaction]:
        x = self.mesh.points + u.reshape(-1, 3)
        fn = f.reshape(-1, 3)
        out = {}
        for c in self.constraints:
            force_nodes = fn[c.nodes]
            centre = c.moment_centre(self.mesh.points)
            out[c.name] = Reaction(
                force=force_nodes.sum(axis=0),
                moment=np.cross(x[c.nodes] - centre, force_nodes).sum(axis=0),
            )
        return out
