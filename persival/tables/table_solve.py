"""The FE arm's state for any activation vector from its response tables (docs/theory.md, 4.3 and 4.4).

Two paths, both from :class:`~persival.tables.response_table.ResponseTable`:

* **exact** (:meth:`TableSolver.solve`): the scalar joint equilibrium
  ``sum_m M_m(theta, a_m) + M_gravity + M_joint = 0`` on the tabulated moments (Hermite in
  theta, linear in a) gives theta_0; each muscle is re-solved by Newton at (theta_0, a_m) from
  its four neighbouring table states (in its own frame: cubic Hermite in theta with the
  tabulated slopes du/dtheta, linear in activation), and the
  joint equilibrium is converged once more with the FE moments (ArmModel.equilibrium_from). The
  result is a converged FE solution of the full model, to the solver's tolerances, not an
  interpolation. A muscle whose Newton from the guess fails (off-level activations of a muscle
  that hangs slack at a = 0) tries, in order: Newton from a bracketing level's state at theta_0,
  that level's equilibrium continued in a alone, and load stepping from its nearest table state.
* **table-only** (:meth:`TableSolver.interpolate`): theta_0 and the interpolated node positions,
  no FE solve: five 2-D interpolations and one scalar root (a surrogate of its own).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy.optimize import brentq

from persival.model.arm.muscle_state import MuscleState
from persival.model.arm.muscle_unit import ConvergenceError
from persival.model.arm.state_library import hermite_blend
from persival.tables.response_table import ResponseTable
from persival.vocabulary import MUSCLES, check_activation_vector

__all__ = ["TableSolver", "OutsideTableError"]


class OutsideTableError(ValueError):
    """The joint equilibrium of these activations lies outside the tabulated angles."""


def _bracket(grid: np.ndarray, x: float) -> tuple[int, float]:
    """Index k and weight w with x = (1 - w) grid[k] + w grid[k + 1] (clamped to the grid)."""
    k = int(np.clip(np.searchsorted(grid, x, side="right") - 1, 0, len(grid) - 2))
    w = float(np.clip((x - grid[k]) / (grid[k + 1] - grid[k]), 0.0, 1.0))
    return k, w


class TableSolver:
    """Exact and table-only states of the FE arm from a complete response table."""

    def __init__(self, arm, table: ResponseTable):
        if not table.complete:
            raise ValueError(f"{table.root}: the response table is unfinished ({int(table.done.sum())} of "
                             f"{table.done.size} columns); run `persival tables` to finish it")
        self.arm = arm
        self.table = table
        self.moments = table.moment_table()
        # every tabulated angle: a column that failed somewhere is NaN there, and a state's balance
        # is searched where the columns it interpolates converged (equilibrium_angle)
        angles = table.angles_deg
        self._fine = np.arange(angles[0], angles[-1] + 1e-9, 0.25)
        self._level_moments = {m: self.moments.level_moments(m, self._fine) for m in MUSCLES}

    # ------------------------------------------------------------------ joint equilibrium on the table
    def residual(self, theta_deg, activations) -> np.ndarray:
        """sum_m M_m(theta, a_m) + M_gravity (with the hand's load) + M_joint (N mm; > 0 turns the
        forearm towards flexion; the arm's own external moments, docs/theory.md 3.6)."""
        theta = np.atleast_1d(np.asarray(theta_deg, dtype=float))
        total = self.arm.external.value(theta, self.arm.hand_load_kg)
        for name, a in zip(MUSCLES, activations):
            total = total + self.moments.moment(name, theta, np.full(len(theta), a))
        return total

    def equilibrium_angle(self, activations, near_deg: float | None = None) -> float:
        """The stable root of :meth:`residual` (sign + to -) nearest ``near_deg`` (default: the
        lowest), refined by Brent's method on the interpolated moments."""
        alpha = check_activation_vector(activations)
        # linear in a: np.interp reads only the two levels that bracket a (a NaN elsewhere stays out)
        g = sum(np.array([np.interp(a, self.moments.levels, row) for row in self._level_moments[name]])
                for name, a in zip(MUSCLES, alpha))
        g = g + self.arm.external.value(self._fine, self.arm.hand_load_kg)
        lo, hi = self._converged_span(g, near_deg)
        inside = (self._fine >= lo) & (self._fine <= hi)
        down = np.flatnonzero((g[:-1] > 0) & (g[1:] <= 0) & inside[:-1] & inside[1:])
        if not len(down):  # no stable root inside: the forearm turns past one end of the table
            side = "below" if g[inside][0] < 0 else "above"
            raise OutsideTableError(f"the equilibrium of activations {alpha.tolist()} lies {side} the tabulated "
                                    f"angles {lo:g} to {hi:g} deg (where the columns of these activations converged)")
        k = down[0] if near_deg is None else down[np.argmin(np.abs(self._fine[down] - near_deg))]
        a, b = self._fine[k], self._fine[k + 1]
        if g[k + 1] == 0:
            return float(b)
        return float(brentq(lambda t: float(self.residual(t, alpha)[0]), a, b, xtol=1e-10))

    def _converged_span(self, g: np.ndarray, near_deg: float | None) -> tuple[float, float]:
        """The run of fine angles where g is finite that holds ``near_deg`` (or lies nearest it;
        the widest run when None)."""
        finite = np.isfinite(g)
        if not finite.any():
            raise OutsideTableError("no tabulated angle where the columns of these activations all converged")
        edges = np.flatnonzero(np.diff(np.concatenate([[0], finite.astype(int), [0]])))
        runs = [(self._fine[a], self._fine[b - 1]) for a, b in zip(edges[::2], edges[1::2])]
        if near_deg is None:
            return max(runs, key=lambda r: r[1] - r[0])
        return min(runs, key=lambda r: 0.0 if r[0] <= near_deg <= r[1] else min(abs(r[0] - near_deg), abs(r[1] - near_deg)))

    # ------------------------------------------------------------------ states from the table
    def guess(self, muscle: str, theta_deg: float, activation: float) -> MuscleState | None:
        """The muscle's state at (theta, a) from its four neighbouring table states (None where
        one failed): cubic Hermite in theta through the two bracketing angles (values and
        slopes du/dtheta), linear in activation: fourth-order in the angle step where linear
        is second (a solve puts the insertion face where theta puts it)."""
        angles = self.table.angles_deg
        k, t = _bracket(angles, theta_deg)
        # states this muscle solved before at this activation, closer together than the table's
        guess = self.arm.units[muscle].library.guess(theta_deg, activation, angles[k + 1] - angles[k])
        if guess is None:
            guess = self._table_guess(muscle, k, t, activation)
        if guess is None:
            return None
        return MuscleState(float(theta_deg), self.length(muscle, theta_deg), float(activation), guess,
                           float("nan"), float("nan"), float("nan"), 0.0)

    def _table_guess(self, muscle: str, k: int, t: float, activation: float) -> np.ndarray | None:
        """Hermite in theta between table angles k and k + 1 (at t), linear in activation."""
        angles = self.table.angles_deg
        h = np.radians(angles[k + 1] - angles[k])
        j, v = _bracket(self.table.levels, activation)
        guess = np.zeros((self.table.header["n_nodes"][muscle], 3))
        for weight, jj in ((1 - v, j), (v, j + 1)):
            if weight == 0.0:
                continue
            col = self.table.column(muscle, jj)
            d, s = col["displacement"][k : k + 2], col["sensitivity"][k : k + 2]
            if not (np.isfinite(d).all() and np.isfinite(s).all()):
                return None
            guess += weight * hermite_blend(t, h, d[0], d[1], s[0], s[1])
        return guess

    def nearest(self, muscle: str, theta_deg: float, activation: float) -> MuscleState:
        """The finite table state nearest (theta, a) (theta in degrees counts like a in 1/30)."""
        table = self.table
        best, where = np.inf, None
        for j, level in enumerate(table.levels):
            moment = table.column(muscle, j)["moment"]
            for k, angle in enumerate(table.angles_deg):
                d = abs(angle - theta_deg) / 30.0 + abs(level - activation)
                if np.isfinite(moment[k]) and d < best:
                    best, where = d, (k, j)
        if where is None:
            raise ValueError(f"the response table has no converged state of {muscle}")
        return table.state(muscle, *where)

    def muscle_state(self, muscle: str, theta_deg: float, activation: float) -> tuple[MuscleState, str]:
        """The FE equilibrium of one muscle at (theta, a) and how it was reached: 'guess' (Newton
        from the interpolated state), 'level a_j' (Newton from the bracketing level a_j's state at
        theta), 'from level a_j' (that level solved, then continued in a alone) or 'continuation'
        (load stepping from the nearest table state)."""
        unit = self.arm.units[muscle]
        guess = self.guess(muscle, theta_deg, activation)
        if guess is not None:
            # its own moment slope and du/dtheta (one factorization more): with interpolated ones the
            # joint iteration's derivative is off by about 1 % and it takes 2 to 3 corrections, not 1
            state = unit.solve_from_guess(theta_deg, activation, guess.displacement)
            if state is not None:
                return state, "guess"
        newton_order, continuation_order = self._off_level_orders(activation)
        on_level = {}
        for level in newton_order:  # Newton at a from a bracketing level's state
            start = self.guess(muscle, theta_deg, level)
            if start is not None:
                on_level[level] = start
                state = unit.solve_from_guess(theta_deg, activation, start.displacement, max_iterations=20)
                if state is not None:
                    return state, f"level {level:g}"
        for level in continuation_order:  # that level's equilibrium, then a alone moves
            start = on_level.get(level)
            if start is None:
                continue
            solved = unit.solve_from_guess(theta_deg, level, start.displacement)
            if solved is not None:
                try:
                    return unit.solve(theta_deg, activation, solved), f"from level {level:g}"
                except ConvergenceError:
                    pass
        return unit.solve(theta_deg, activation, self.nearest(muscle, theta_deg, activation)), \
            "continuation"

    def _off_level_orders(self, activation: float) -> tuple[list[float], list[float]]:
        """The two table levels around an off-level activation (none on a level), the better start
        first, for Newton at a from a level's state and for continuing a level's equilibrium in a
        alone. Newton: the nearer level, unless it is the passive level 0, where a muscle can hang
        slack and bowed (Newton from there fails). Continuation: the nearer level, level 0 only
        within the lowest quarter of its interval (a slack, bowed muscle activated from 0 to a few
        per cent straightens in 10 to 65 Newton iterations where coming down from 0.25 takes 250 to
        340; from 0.08 up 0.25 is the cheaper side, 31 to 163 against 159 to 296: quick mesh, seven
        held-out states of the session-VI main job)."""
        j, v = _bracket(self.table.levels, activation)
        if v in (0.0, 1.0):
            return [], []
        lo, hi = float(self.table.levels[j]), float(self.table.levels[j + 1])
        newton = [hi, lo] if v > 0.5 or lo == 0.0 else [lo, hi]
        continuation = [lo, hi] if v < (0.25 if lo == 0.0 else 0.5) else [hi, lo]
        return newton, continuation

    def length(self, muscle: str, theta_deg: float) -> float:
        """Origin-insertion length (mm) of the muscle at theta."""
        return self.arm.muscle_length(self.arm.spec.muscle(muscle), theta_deg)[0]

    # ------------------------------------------------------------------ the two paths
    def solve(self, activations, near_deg: float | None = None, progress=None):
        """The exact path: a converged FE state of the whole arm (an ArmState). ``near_deg``:
        which stable root of the tabulated balance to start from (default: the one nearest the
        hanging arm, as the direct solve from it)."""
        alpha = check_activation_vector(activations)
        t0 = time.perf_counter()
        theta0 = self.start_angle(alpha, near_deg)
        starts, how = {}, {}
        for name, a in zip(MUSCLES, alpha):
            starts[name], how[name] = self.muscle_state(name, theta0, float(a))
        t_start = time.perf_counter() - t0
        state = self.arm.equilibrium_from(alpha, starts, theta0, progress)
        state.statistics.update({"table_angle_deg": theta0, "table_start": how, "start_iterations":
                                 int(sum(s.iterations for s in starts.values())), "start_seconds": t_start})
        state.wall_time_s = time.perf_counter() - t0
        return state

    def interpolate(self, activations, near_deg: float | None = None) -> tuple[float, np.ndarray]:
        """The table-only path: (theta_0, world displacements (n_nodes, 3) of all muscles)."""
        alpha = check_activation_vector(activations)
        theta0 = self.start_angle(alpha, near_deg)
        # a failed neighbour: the nearest table state, placed at theta_0 as it is
        states = {name: self.guess(name, theta0, float(a)) or replace(self.nearest(name, theta0, float(a)), angle_deg=theta0)
                  for name, a in zip(MUSCLES, alpha)}
        return theta0, self.arm.displacement(states, theta0)

    def start_angle(self, activations, near_deg: float | None = None) -> float:
        """theta_0 of both paths: the tabulated balance's stable root nearest ``near_deg``, by
        default the one the direct solve from the hanging arm finds."""
        near = self.arm.base_state().elbow_angle_deg if near_deg is None else near_deg
        return self.equilibrium_angle(activations, near)
