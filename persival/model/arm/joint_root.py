"""The joint's root: the elbow angle where the muscles' moments, gravity, a held load and the
joint's limits balance, by a safeguarded Newton iteration on theta (docs/theory.md, 3.7)."""

from __future__ import annotations

import numpy as np

from persival.model.fe.solver import ConvergenceError

__all__ = ["joint_root"]


def joint_root(arm, target, start: dict, angle: float, tracker) -> tuple[float, float, float, dict, dict]:
    """Solve g(theta) = 0 of ``arm.moment_balance`` by a safeguarded Newton iteration on theta
    (docs/theory.md, 3.7: an equivalent of the bordered system). Its derivative is the Schur complement of every
    muscle (exact, so the iteration converges quadratically; a secant where the muscles' chord
    slopes make it creep, ``_step_slope``); a bracket of the root and a
    largest step keep it from jumping past a stiff joint limit, and a trial angle whose
    muscles fail to converge is pulled back halfway. Where the muscles' noise floor keeps |g|
    just above the tolerance, the root located by other means ends it too (``_at_noise_floor``).
    Returns theta (deg), g and dg/dtheta there, the muscle states and the iteration's statistics.
    """
    opts = arm.options
    stats: dict = {"joint_iterations": 0, "iterations": 0}
    theta = float(angle)
    tracker.joint(0, theta)
    g, dg, states = arm.moment_balance(theta, target, start, stats, tracker)
    slope = dg  # what the steps divide by (_step_slope); dg is reported as the joint's stiffness
    lo, hi = -np.inf, np.inf  # bracket: g(lo) < 0 < g(hi) (g grows with theta when stable)
    lower, upper = arm.spec.joint.limits_deg
    g_before = np.inf
    for _ in range(60):
        tolerance = arm.moment_tolerance(states)
        if abs(g) <= tolerance or _at_noise_floor(opts, g, g_before, slope, hi - lo, tolerance):
            break
        g_before = g
        if g > 0:
            hi = min(hi, theta)
        else:
            lo = max(lo, theta)
        step = -np.degrees(g / slope) if slope > 0 else (-opts.joint_max_step if g > 0 else opts.joint_max_step)
        step = float(np.clip(step, -opts.joint_max_step, opts.joint_max_step))
        trial = theta + step
        if not lo < trial < hi:  # Newton left the bracket: bisect
            trial = 0.5 * (lo + hi) if np.isfinite(lo) and np.isfinite(hi) else theta + step
        trial = float(np.clip(trial, lower - 30.0, upper + 30.0))
        for _retry in range(4):
            tracker.joint(stats["joint_iterations"] + 1, trial, g)
            try:
                g_t, dg_t, states_t = arm.moment_balance(trial, target, states, stats, tracker)
                break
            except ConvergenceError as exc:
                failure = exc
                trial = 0.5 * (theta + trial)
        else:
            raise ConvergenceError(f"the muscles did not converge on the way from {theta:.2f} deg: {failure}")
        slope = _step_slope(theta, g, trial, g_t, dg_t)
        theta, g, dg, states = trial, g_t, dg_t, states_t
        stats["joint_iterations"] += 1
    else:
        raise ConvergenceError(f"joint equilibrium not found: moment residual {g:.3e} N mm at {theta:.2f} deg")
    return theta, g, dg, states, stats


def _step_slope(theta: float, g: float, trial: float, g_trial: float, dg_trial: float) -> float:
    """The slope (N mm/rad) of the next step (docs/theory.md, 3.7): the muscles' Schur complement
    dg, or the secant of the last step where that step kept g's sign and cut |g| by less than
    half. The muscles' near corrections keep their start's slope (moment_balance), and with
    walls that chord can be several times too steep: a hanging arm crept from -7.1 to
    -4.7e-4 N mm at 0.78 per step and ran out of iterations."""
    if g * g_trial > 0 and abs(g_trial) > 0.5 * abs(g) and trial != theta:
        secant = (g_trial - g) / np.radians(trial - theta)
        if secant > 0:
            return float(secant)
    return dg_trial


def _at_noise_floor(opts, g: float, g_before: float, dg: float, bracket: float, tolerance: float) -> bool:
    """Whether |g|, within ``joint_noise_factor`` of the tolerance, is the muscles' noise floor
    at a root already located: bracketed within ``joint_bracket_deg``, or, where the floor keeps
    g's sign, approached from that side by steps that no longer reduce |g| (``joint_stall_ratio``)
    and are shorter than ``joint_stall_deg``. A converging iteration reduces |g| by far more
    per step, so it goes on to the tolerance."""
    if abs(g) > opts.joint_noise_factor * tolerance:
        return False
    stalled = g * g_before > 0 and abs(g) >= opts.joint_stall_ratio * abs(g_before) and dg > 0
    return bracket <= opts.joint_bracket_deg or (stalled and abs(np.degrees(g / dg)) <= opts.joint_stall_deg)
