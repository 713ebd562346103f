"""Quasi-static total-Lagrangian solver: Newton-Raphson, line search, adaptive load stepping.

Unknowns are the displacements of the nodes not held by a constraint. A load factor t runs
from 0 to 1; activation and prescribed displacements are interpolated along it
(continuation, SPEC 3.2). Each step is solved by Newton's method with the consistent tangent;
the step is halved when Newton fails (divergence, an inverted element, a singular tangent)
and grows again after easy steps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from persival.model.assembly import InvertedElementError, MaterialField, Tet10Assembler, symmetric_matvec
from persival.model.constraints import Dirichlet, RigidTie
from persival.model.linear_solver import SingularMatrixError, SparseSymmetricSolver
from persival.model.mesh import Tet10Mesh


class ConvergenceError(RuntimeError):
    """The load stepping could not reach t = 1 (the step size fell below its minimum)."""


@dataclass
class SolverOptions:
    rtol: float = 1e-8  # residual relative to the load-step force scale
    atol: float = 1e-9  # N, absolute floor of the residual tolerance
    max_iterations: int = 15
    initial_step: float = 0.25
    min_step: float = 1.0 / 256.0
    max_line_search: int = 6
    backend: str = "auto"


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
    wall_time: float = 0.0

    def as_dict(self) -> dict:
        return {
            "steps": self.steps,
            "step_cuts": self.step_cuts,
            "iterations": self.iterations,
            "iterations_per_step": [len(h) - 1 for h in self.residual_histories],
            "time_assembly_s": self.time_assembly,
            "time_factorization_s": self.time_factorization,
            "time_solve_s": self.time_solve,
            "assemblies": self.n_assemblies,
            "factorizations": self.n_factorizations,
            "wall_time_s": self.wall_time,
        }


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


class QuasiStaticSolver:
    """Solve ``f_int(u) = 0`` on the free DOFs of a tet10 body under boundary constraints."""

    def __init__(
        self,
        mesh: Tet10Mesh,
        material: MaterialField,
        constraints: list[Dirichlet | RigidTie],
        options: SolverOptions | None = None,
        quadrature_order: int = 2,
    ) -> None:
        self.mesh = mesh
        self.material = material
        self.constraints = list(constraints)
        self.options = options or SolverOptions()
        self.assembler = Tet10Assembler(mesh, quadrature_order)
        if material.fibre.shape[:2] != self.assembler.weights.shape:
            raise ValueError("material field does not match the mesh and quadrature")
        n = self.assembler.n_dofs
        constrained = np.zeros(n, dtype=bool)
        for c in self.constraints:
            dofs = c.dofs
            if np.any(constrained[dofs]):
                raise ValueError(f"constraint {c.name!r} overlaps another constraint")
            if dofs.max() >= n:
                raise ValueError(f"constraint {c.name!r} refers to nodes outside the mesh")
            constrained[dofs] = True
        if constrained.all():
            raise ValueError("every degree of freedom is constrained: nothing to solve")
        self.constrained = constrained
        self.free = np.flatnonzero(~constrained)
        free_index = np.full(n, -1, dtype=np.int64)
        free_index[self.free] = np.arange(len(self.free))
        r, c = self.assembler.pattern_rows, self.assembler.pattern_cols
        keep = (free_index[r] >= 0) & (free_index[c] >= 0)
        self._ff_take = np.flatnonzero(keep)
        rows_ff, cols_ff = free_index[r[keep]], free_index[c[keep]]
        nf = len(self.free)
        self._ff_indptr = np.concatenate([[0], np.cumsum(np.bincount(rows_ff, minlength=nf))]).astype(np.int32)
        self._ff_indices = cols_ff.astype(np.int32)
        self.linear_solver = SparseSymmetricSolver(self.options.backend)

    # ------------------------------------------------------------------------------------------
    def _free_upper(self, K: sp.csr_matrix) -> sp.csr_matrix:
        n = len(self.free)
        return sp.csr_matrix((K.data[self._ff_take], self._ff_indices, self._ff_indptr), shape=(n, n))

    def _apply_constraints(self, u: np.ndarray, t: float) -> None:
        for c in self.constraints:
            u[c.dofs] = c.values(self.mesh.points, t)

    def _assemble(self, u, activation, stats):
        t0 = time.perf_counter()
        K, f = self.assembler.tangent(u, self.material, activation)
        stats.time_assembly += time.perf_counter() - t0
        stats.n_assemblies += 1
        return K, f

    def _factorize_and_solve(self, K, rhs, stats):
        t0 = time.perf_counter()
        self.linear_solver.factorize(self._free_upper(K))
        t1 = time.perf_counter()
        x = self.linear_solver.solve(rhs)
        stats.time_factorization += t1 - t0
        stats.time_solve += time.perf_counter() - t1
        stats.n_factorizations += 1
        return x

    def _newton_step(self, u_start, t, activation, stats, secant=None):
        """Solve at load factor t from the converged state u_start; return (u, K, f, history).

        ``secant``: the displacement change per unit load factor over the previous step; the
        extrapolation along it is the predictor of continuation. Without one, the free DOFs
        follow the prescribed ones linearly (so a boundary jump does not crush the first
        element layer).
        """
        opts = self.options
        u = u_start.copy()
        if secant is not None:
            u += secant
        self._apply_constraints(u, t)
        if secant is None:
            jump = u - u_start
            if np.any(jump):
                K, _ = self._assemble(u_start, activation, stats)
                u[self.free] += self._factorize_and_solve(K, -symmetric_matvec(K, jump)[self.free], stats)
        try:
            K, f = self._assemble(u, activation, stats)
        except InvertedElementError:
            u = u_start.copy()
            self._apply_constraints(u, t)
            K, f = self._assemble(u, activation, stats)
        r = f[self.free]
        norm = float(np.linalg.norm(r))
        scale = max(float(np.linalg.norm(f[self.constrained])), norm)
        tolerance = opts.rtol * scale + opts.atol
        history = [norm]
        for _ in range(opts.max_iterations):
            if norm <= tolerance:
                return u, K, f, history
            du = self._factorize_and_solve(K, -r, stats)
            eta = 1.0
            for _ls in range(opts.max_line_search + 1):
                trial = u.copy()
                trial[self.free] += eta * du
                try:
                    K_t, f_t = self._assemble(trial, activation, stats)
                    norm_t = float(np.linalg.norm(f_t[self.free]))
                    if norm_t < (1.0 - 1e-4 * eta) * norm or norm_t <= tolerance:
                        break
                except InvertedElementError:
                    pass
                eta *= 0.5
            else:
                raise ConvergenceError("line search failed to reduce the residual")
            u, K, f, norm = trial, K_t, f_t, norm_t
            r = f[self.free]
            history.append(norm)
            stats.iterations += 1
        if norm <= tolerance:
            return u, K, f, history
        raise ConvergenceError(f"Newton did not converge in {opts.max_iterations} iterations (|r| = {norm:.3e})")

    def solve(
        self,
        activation,
        initial_displacement: np.ndarray | None = None,
        initial_activation=None,
        progress=None,
    ) -> StaticSolution:
        """Continue from (initial_displacement, initial_activation) at t = 0 to ``activation`` at t = 1.

        ``activation`` is a scalar or per-cell array in [0, 1]. ``progress(t)`` is called after
        each accepted load step.
        """
        m = self.mesh.n_cells
        target = self._validated_activation(activation, "activation")
        start = target * 0.0 if initial_activation is None else self._validated_activation(initial_activation, "initial_activation")
        u = np.zeros(self.assembler.n_dofs) if initial_displacement is None else np.asarray(initial_displacement, dtype=float).reshape(-1).copy()
        if u.shape != (self.assembler.n_dofs,) or not np.all(np.isfinite(u)):
            raise ValueError("initial_displacement must be a finite (n_nodes, 3) array")
        stats = NewtonStatistics()
        wall = time.perf_counter()
        opts = self.options
        t, dt = 0.0, min(1.0, opts.initial_step)
        K = f = None
        rate = None  # du/dt of the last accepted step
        while t < 1.0:
            t_new = min(1.0, t + dt)
            act = start + t_new * (target - start)
            secant = None if rate is None else (t_new - t) * rate
            try:
                u_new, K, f, history = self._newton_step(u, t_new, act, stats, secant)
            except (ConvergenceError, InvertedElementError, SingularMatrixError) as exc:
                stats.step_cuts += 1
                dt *= 0.5
                if dt < opts.min_step:
                    raise ConvergenceError(
                        f"load step fell below {opts.min_step} at t = {t:.4f}: {exc}"
                    ) from exc
                continue
            stats.residual_histories.append(history)
            stats.steps += 1
            rate = (u_new - u) / (t_new - t)
            u, t = u_new, t_new
            if progress is not None:
                progress(t)
            if len(history) <= 7:
                dt = min(2.0 * dt, 1.0)
        stats.wall_time = time.perf_counter() - wall
        if f is None:  # nothing to do: report the reactions of the initial state
            _, f = self.assembler.tangent(u, self.material, np.broadcast_to(target, (m,)).copy())
        return StaticSolution(
            displacement=u.reshape(-1, 3),
            reactions=self._reactions(u, f),
            statistics=stats,
            max_volume_change=float(np.abs(np.linalg.det(self.assembler.deformation_gradient(u)) - 1.0).max()),
        )

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
