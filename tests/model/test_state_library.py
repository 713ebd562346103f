"""The kept-state library (persival.model.arm.state_library): spacing, size cap, Hermite guesses."""

import numpy as np

from persival.model.arm.muscle_state import MuscleState
from persival.model.arm.state_library import StateLibrary


def _state(theta_deg: float, activation: float = 0.5, with_slope: bool = True) -> MuscleState:
    """A state whose displacement is a cubic in theta (radians), with its exact slope."""
    t = np.radians(theta_deg)
    u = np.array([[t**3, 2.0 * t, 1.0]])
    du = np.array([[3.0 * t**2, 2.0, 0.0]])
    return MuscleState(theta_deg, 300.0, activation, u, 10.0, 100.0, -50.0, 0.0, sensitivity=du if with_slope else None)


def test_guess_is_exact_for_a_cubic_and_linear_without_slopes():
    library = StateLibrary()
    for theta in (10.0, 14.0):
        library.add(_state(theta))
    guess = library.guess(12.5, 0.5, max_gap_deg=5.0)
    np.testing.assert_allclose(guess, _state(12.5).displacement, rtol=1e-12)  # cubic Hermite: exact on a cubic
    assert library.guess(12.5, 0.25, 5.0) is None  # another activation
    assert library.guess(12.5, 0.5, 3.0) is None  # the bracket is wider than allowed
    assert library.guess(9.0, 0.5, 5.0) is None and library.guess(15.0, 0.5, 5.0) is None  # no extrapolation
    linear = StateLibrary()
    for theta in (10.0, 14.0):
        linear.add(_state(theta, with_slope=False))
    t = (12.5 - 10.0) / 4.0
    np.testing.assert_allclose(linear.guess(12.5, 0.5, 5.0), (1 - t) * _state(10.0).displacement + t * _state(14.0).displacement)


def test_spacing_and_size_cap():
    library = StateLibrary(spacing_deg=0.2, size=3)
    library.add(_state(10.0))
    library.add(_state(10.1))  # too close to 10.0: not kept
    assert len(library) == 1
    library.add(_state(10.3))
    library.add(_state(10.3, activation=1.0))  # another activation: kept
    library.add(_state(20.0))  # full
    assert len(library) == 3
    assert library.guess(10.2, 0.5, 1.0) is not None and library.guess(15.0, 0.5, 20.0) is None
