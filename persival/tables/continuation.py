"""One muscle continued along the elbow angle at a fixed activation: each angle's FE state from
its neighbour's, in steps of at most ``max_step_deg``, from a stretched start; its tension, moment
and moment slope per angle, NaN where a solve fails (docs/theory.md, section 4)."""

from __future__ import annotations

import numpy as np

from persival.model.fe.solver import ConvergenceError

__all__ = ["sweep_muscle"]


def _path(angles: np.ndarray, max_step_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The continuation path: the angles with points inserted so that no step exceeds max_step_deg."""
    path = [angles[0]]
    for a, b in zip(angles[:-1], angles[1:]):
        n = max(1, int(np.ceil((b - a) / max_step_deg - 1e-9)))
        path += list(np.linspace(a, b, n + 1)[1:])
    path = np.array(path)
    return path, np.searchsorted(path, angles - 1e-9)


def _next_state(unit, theta_deg: float, activation: float, state, previous):
    """The next state of a sweep: Newton from an extrapolation of the last states (their shapes
    change smoothly with the angle), else load-stepped continuation from the last.

    The extrapolation is the quadratic through the last state, its slope and the one before (the
    tangent line when there is none before), in the unit's chart (``MuscleUnit.chart``: the length
    for a muscle without bones, whose state depends on L alone; coarse brachioradialis at a = 0.5:
    378 Newton iterations for the sweep against 440 extrapolating in theta). Why: a slack, bowed muscle shortened by
    9 mm took 100 to 200 Newton iterations by load stepping from the last state (coarse
    brachioradialis, profiled); from the extrapolated shape a few. The solve puts the guess's
    insertion face where theta puts it.
    """
    chart, ds = unit.chart(state.angle_deg)
    step = chart(theta_deg) - chart(state.angle_deg)
    if step != 0.0:  # every MuscleUnit state carries its slope
        slope = state.sensitivity / ds
        guess = state.displacement + step * slope
        if previous is not None and chart(previous.angle_deg) != chart(state.angle_deg):
            back = chart(previous.angle_deg) - chart(state.angle_deg)
            curvature = (previous.displacement - state.displacement - back * slope) / back**2
            guess = guess + step**2 * curvature
        solved = unit.solve_from_guess(theta_deg, activation, guess, max_iterations=10)
        if solved is not None:
            return solved
    return unit.solve(theta_deg, activation, state)


def sweep_muscle(arm, muscle, angles, activation: float, max_step_deg: float = 10.0, start=None) -> dict:
    """One muscle's FE equilibria along ``angles`` (deg) at a fixed activation (docs/theory.md, 4.1).

    Continuation along theta, each solve warm-started from its neighbour, in steps of at most
    ``max_step_deg`` (points between the asked angles are solved, not returned: short steps
    converge faster; on the coarse mesh 0:160:40 direct took 750 s, 0:160:20 in 10-degree steps
    600 s, and the tensions at the shared angles agree to 1e-8 N). The passive sweep
    starts at the angle nearest the mesh pose; an active one where the muscle is longest
    (activating a slack, bowed muscle in place is a snap-through, not a continuation), reached
    passively first, or activated from ``start`` (a state at that longest length, e.g. the previous
    level's ``longest_state``: continuation along a). Both run outwards from the start; the first
    failure ends a direction and leaves the rest NaN. Returns tension T (N), the moment M (N mm,
    flexion positive) and its slope dM/dtheta (N mm/rad) and the length geometry at ``angles``,
    the states there (None where a solve failed) and the state at the longest length.
    """
    angles = np.asarray(angles, dtype=float)
    path, index = _path(angles, max_step_deg)
    unit = arm.units[muscle.name]
    geometry = np.array([arm.muscle_length(muscle, t) for t in path])
    lengths = geometry[:, 0]
    tension, moment, slope = (np.full(len(path), np.nan) for _ in range(3))
    longest = int(np.argmax(lengths))
    first = int(np.argmin(np.abs(path - muscle.mesh_angle_deg))) if activation == 0.0 else longest
    origin, states = None, {}
    for begin in ([start] if start is not None and first == longest else []) + [None]:
        try:
            origin = begin or unit.solve(path[first], 0.0, unit.rest_state())
            origin = unit.solve(path[first], float(activation), origin)
            break
        except ConvergenceError:
            origin = None
    if origin is not None:
        for sweep in (range(first, len(path)), range(first, -1, -1)):
            state, previous = origin, None
            for k in sweep:
                try:
                    state, previous = _next_state(unit, path[k], float(activation), state, previous), state
                except ConvergenceError:
                    break
                tension[k], moment[k], slope[k] = state.tension, state.moment, state.moment_slope
                states[k] = state
    dL = geometry[index, 1]
    return {"length_mm": lengths[index], "dL_dtheta_mm_per_rad": dL, "tension_N": tension[index],
            "moment_Nmm": moment[index], "moment_slope_Nmm_per_rad": slope[index], "longest_state": states.get(longest),
            "states": [states.get(int(k)) for k in index]}
