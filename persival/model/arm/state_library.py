"""A muscle's kept equilibria: solved (theta, a) states that warm-start later solves.

A campaign solves each muscle at many angles per activation; neighbouring solved states of the
same activation bracket a new angle a few tenths of a degree apart after a few hundred states,
where the response tables are 5 deg apart. Their cubic Hermite interpolation in theta, with each
state's du/dtheta (MuscleState.sensitivity), is the Newton start (MuscleUnit._from_library,
TableSolver.guess).
"""

from __future__ import annotations

import bisect

import numpy as np

from persival.model.arm.muscle_state import MuscleState

__all__ = ["StateLibrary", "hermite_blend"]


def hermite_blend(t: float, h: float, u0: np.ndarray, u1: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation at t in [0, 1] between states u0, u1 with slopes s0, s1
    (per unit of the coordinate) over a step h of that coordinate."""
    return ((2 * t**3 - 3 * t**2 + 1) * u0 + (-2 * t**3 + 3 * t**2) * u1
            + (t**3 - 2 * t**2 + t) * h * s0 + (t**3 - t**2) * h * s1)


class StateLibrary:
    """Solved states by activation, sorted by angle; at most ``size`` in all, none closer than
    ``spacing_deg`` to a kept one of the same activation (each holds n_nodes x 3 floats)."""

    def __init__(self, spacing_deg: float = 0.2, size: int = 600) -> None:
        self.spacing_deg = spacing_deg
        self.size = size
        self._states: dict[float, list[MuscleState]] = {}

    def __len__(self) -> int:
        return sum(len(v) for v in self._states.values())

    def add(self, state: MuscleState) -> None:
        """Keep ``state`` unless the library is full or holds one this close already."""
        states = self._states.setdefault(state.activation, [])
        k = bisect.bisect_left([s.angle_deg for s in states], state.angle_deg)
        near = [s for s in states[max(k - 1, 0) : k + 1] if abs(s.angle_deg - state.angle_deg) < self.spacing_deg]
        if near or len(self) >= self.size:
            return
        states.insert(k, state)

    def guess(self, theta_deg: float, activation: float, max_gap_deg: float) -> np.ndarray | None:
        """The displacement at theta from the two kept states of this activation that bracket it
        at most ``max_gap_deg`` apart (None if there are none): cubic Hermite in theta with their
        du/dtheta, linear where one lacks it."""
        states = self._states.get(activation)
        if not states:
            return None
        k = bisect.bisect_left([s.angle_deg for s in states], theta_deg)
        if k == 0 or k == len(states):
            return None
        lo, hi = states[k - 1], states[k]
        if hi.angle_deg - lo.angle_deg > max_gap_deg:
            return None
        t = (theta_deg - lo.angle_deg) / (hi.angle_deg - lo.angle_deg)
        if lo.sensitivity is None or hi.sensitivity is None:
            return (1.0 - t) * lo.displacement + t * hi.displacement
        return hermite_blend(t, np.radians(hi.angle_deg - lo.angle_deg), lo.displacement, hi.displacement,
                             lo.sensitivity, hi.sensitivity)
