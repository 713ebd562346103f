"""The joint iteration's stopping rule (persival/model/arm/joint_root.py, through ArmModel._equilibrium), on a moment
balance with a noise floor: muscles in contact with a wall reach their own tolerance with a
residual noise of a few hundredths of a N mm, so the joint's g changes sign across a hair's
width of angle without dropping below the moment tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from persival.model.arm.progress import SolveTracker
from persival.model.fe.solver import ConvergenceError

ROOT_DEG, STIFFNESS = 33.4, 7600.0  # N mm/rad, the hanging arm's joint stiffness in the atlas arm


def _noisy_balance(noise_nmm: float):
    """g(theta) of a stiff joint plus a floor of +-noise away from the root (no exact zero)."""
    def balance(theta_deg, activations, start, statistics=None, tracker=None):
        g = STIFFNESS * np.radians(theta_deg - ROOT_DEG)
        return g + np.copysign(noise_nmm, g), STIFFNESS, {}
    return balance


@pytest.fixture
def arm(coarse_arm, monkeypatch):
    monkeypatch.setattr(coarse_arm, "moment_tolerance", lambda states: 2e-4)
    monkeypatch.setattr(coarse_arm, "_arm_state", lambda target, theta, g, dg, states, stats: (theta, g))
    return coarse_arm


def test_a_bracket_of_a_hair_ends_the_iteration_at_the_root(arm, monkeypatch):
    monkeypatch.setattr(arm, "moment_balance", _noisy_balance(0.03))
    theta, g = arm._equilibrium(np.zeros(5), {}, 20.0, SolveTracker(None))
    assert abs(theta - ROOT_DEG) <= arm.options.joint_bracket_deg
    assert 2e-4 < abs(g) <= 0.03 + STIFFNESS * np.radians(arm.options.joint_bracket_deg)


def test_a_residual_far_above_the_noise_floor_is_still_refused(arm, monkeypatch):
    """A jump of 5 N mm across the root is no noise floor: the iteration reports it."""
    monkeypatch.setattr(arm, "moment_balance", _noisy_balance(5.0))
    with pytest.raises(ConvergenceError, match="joint equilibrium not found"):
        arm._equilibrium(np.zeros(5), {}, 20.0, SolveTracker(None))


def test_a_root_approached_from_one_side_ends_the_iteration_at_the_noise_floor(arm, monkeypatch):
    """A stale slope (twice the true one) and a floor that keeps g's sign: the iteration creeps
    towards the root from below and never brackets it; once its steps no longer reduce |g| and
    are shorter than joint_stall_deg, the root is located."""
    def creeping(theta_deg, activations, start, statistics=None, tracker=None):
        g = STIFFNESS * np.radians(theta_deg - ROOT_DEG)
        return min(g, 0.0) - 8.2e-4, 2.0 * STIFFNESS, {}
    monkeypatch.setattr(arm, "moment_balance", creeping)
    theta, g = arm._equilibrium(np.zeros(5), {}, 20.0, SolveTracker(None))
    assert abs(theta - ROOT_DEG) <= arm.options.joint_stall_deg
    assert 8.2e-4 <= abs(g) <= 8.2e-4 * 1.2


def test_a_slope_several_times_too_steep_is_replaced_by_the_secant(arm, monkeypatch):
    """Muscles whose near corrections keep a chord 4.5 times the joint's true stiffness: Newton
    steps alone cut g by 0.78 per step and run out of iterations; the secant of a step that cut
    |g| by less than half finds the root in a few more balances."""
    calls = []
    def stiff_chord(theta_deg, activations, start, statistics=None, tracker=None):
        calls.append(theta_deg)
        return STIFFNESS * np.radians(theta_deg - ROOT_DEG), 4.5 * STIFFNESS, {}
    monkeypatch.setattr(arm, "moment_balance", stiff_chord)
    theta, g = arm._equilibrium(np.zeros(5), {}, 20.0, SolveTracker(None))
    assert abs(g) <= 2e-4 and abs(theta - ROOT_DEG) < 1e-5
    assert len(calls) <= 5
