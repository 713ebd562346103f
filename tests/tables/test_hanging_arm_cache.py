"""The hanging arm and the muscles' rest states: continued from the mesh poses, cached, and
found from the response tables (docs/fe_tables.md). Its own module so that the test run can put
these minutes beside the response-table module's on the other worker."""

from __future__ import annotations

import numpy as np
import pytest

from persival.model.arm.arm_model import ArmModel

pytestmark = pytest.mark.slow  # continuations from the mesh poses take minutes (make test-fast skips it)


def test_hanging_arm_from_the_tables_is_the_direct_one_and_comes_from_the_cache_the_second_time(
        coarse_arm, coarse_table, tmp_path, monkeypatch):
    """ensure_tables caches the rest states first (the table workers need them), then the hanging
    arm by the tables' exact path: the same FE equilibrium as the continuation from the mesh poses
    (the test run's cache holds that one: tests/data/state_cache). A second model re-converges it
    from the cache in a Newton iteration or two per muscle."""
    from persival.tables.open import hanging_from_tables

    direct = coarse_arm.base_state()
    monkeypatch.setenv("PERSIVAL_CACHE", str(tmp_path))
    fresh = ArmModel(profile="coarse")
    fresh.rest_states()
    assert fresh.load_cached_rest_states() and not fresh.has_cached_base()  # rest states only, no hanging arm yet
    state = hanging_from_tables(fresh, coarse_table)
    assert abs(state.elbow_angle_deg - direct.elbow_angle_deg) < 1e-4
    assert np.abs(state.displacement - direct.displacement).max() < 1e-3
    assert abs(state.moment_residual) <= coarse_arm.moment_tolerance(state.muscle_states)
    again = ArmModel(profile="coarse").base_state()
    assert again.statistics["from_cache"] and abs(again.elbow_angle_deg - state.elbow_angle_deg) < 1e-6
    assert np.abs(again.displacement - state.displacement).max() < 1e-6
    assert again.statistics["iterations"] <= 10
