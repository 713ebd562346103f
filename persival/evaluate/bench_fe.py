"""FE speed benchmark: cost of one Newton iteration against one factorization of its tangent.

The body is the paper-size verification spindle (40 x 300 mm, about 3.5k tet10 and 20k DOF,
docs/theory.md, 2.2; target in docs/benchmarks.md): both ends fixed, fully activated, so the timings are taken at a
real, strongly nonlinear equilibrium state.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np


@dataclass
class FEBenchmark:
    cells: int
    dofs: int
    free_dofs: int
    surface_nodes: int
    backend: str
    assembly_s: float
    internal_force_s: float
    analysis_s: float
    factorization_s: float
    solve_s: float
    newton_iteration_s: float
    solve_wall_s: float
    load_steps: int
    newton_iterations: int
    max_volume_change: float

    @property
    def ratio(self) -> float:
        return self.newton_iteration_s / self.factorization_s


def _best_of(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run_fe_benchmark(mesh_size: float = 6.3, activation: float = 1.0, repeats: int = 5, backend: str = "auto") -> FEBenchmark:
    from persival.model.fe.constraints import Dirichlet
    from persival.model.fe.geometry import spindle, spindle_material
    from persival.model.fe.linear_solver import SparseSymmetricSolver
    from persival.model.fe.solver import QuasiStaticSolver, SolverOptions

    mesh = spindle(length=300.0, belly_radius=20.0, tendon_radius=5.0, mesh_size=mesh_size)
    solver = QuasiStaticSolver(
        mesh,
        spindle_material(mesh),
        [Dirichlet("origin", mesh.node_sets["origin"]), Dirichlet("insertion", mesh.node_sets["insertion"])],
        SolverOptions(backend=backend),
    )
    solution = solver.solve(activation)
    u = solution.displacement.ravel()
    act = np.full(mesh.n_cells, activation)
    K, f = solver.assembler.tangent(u, solver.material, act)
    K_ff = solver.system.free_upper(K)
    rhs = -f[solver.free] + 1.0

    fresh = SparseSymmetricSolver(backend)
    analysis_and_factorization = _best_of(lambda: SparseSymmetricSolver(backend).factorize(K_ff), 2)
    fresh.factorize(K_ff)
    assembly = _best_of(lambda: solver.assembler.tangent(u, solver.material, act), repeats)
    force = _best_of(lambda: solver.assembler.internal_force(u, solver.material, act), repeats)
    factorization = _best_of(lambda: fresh.factorize(K_ff), repeats)
    solve = _best_of(lambda: fresh.solve(rhs), repeats)

    def newton_iteration():
        K_i, f_i = solver.assembler.tangent(u, solver.material, act)
        fresh.factorize(solver.system.free_upper(K_i))
        fresh.solve(-f_i[solver.free])

    iteration = _best_of(newton_iteration, repeats)
    stats = solution.statistics
    return FEBenchmark(
        cells=mesh.n_cells,
        dofs=3 * mesh.n_nodes,
        free_dofs=len(solver.free),
        surface_nodes=len(mesh.surface_nodes()),
        backend=fresh.backend,
        assembly_s=assembly,
        internal_force_s=force,
        analysis_s=analysis_and_factorization - factorization,
        factorization_s=factorization,
        solve_s=solve,
        newton_iteration_s=iteration,
        solve_wall_s=stats.wall_time,
        load_steps=stats.steps,
        newton_iterations=stats.iterations,
        max_volume_change=solution.max_volume_change,
    )


