"""Response tables of the FE arm and the states solved from them (docs/fe_tables.md).

The agreement checks read ``tests/data/response_table_coarse``: the coarse-profile table built by
``persival tables --profile coarse --angles 0:160:20 --levels 0,0.5,1 --out ...`` (about 4 min on
2 cores, so a fixture; it is keyed by model hash and mesh, and the checks skip with a message
when the model changed). The build, its kill-and-resume and its refusals are tested on a small
real table computed here. The exact path against the direct coupled solve (every muscle off the
table's levels) is tests/model/test_arm_solve.py's, the cached and table-found hanging arm
tests/tables/test_hanging_arm_cache.py's.
"""

from __future__ import annotations

import copy
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from persival.tables.moment_table import TableMismatchError
from persival.tables.response_table import ResponseTable
from persival.tables.table_build import build_response_table
from persival.tables.table_solve import OutsideTableError, TableSolver
from persival.vocabulary import MUSCLES

pytestmark = pytest.mark.slow  # a shared fixture of this module takes minutes (make test-fast skips it)

FIXTURE = Path(__file__).parents[1] / "data" / "response_table_coarse"


@pytest.fixture(scope="module")
def arm(coarse_arm):
    return coarse_arm


@pytest.fixture(scope="module")
def solver(arm, coarse_table):
    return TableSolver(arm, coarse_table)


def test_joint_converges_to_the_relative_tolerance_without_an_absolute_one(arm, solver):
    """With moment_atol 0 the joint iteration must still stop, at moment_rtol of the summed
    muscle moments (the muscles' own moments are exact only to their Newton tolerance: a fixed
    1e-4 N mm stalled a quick state at 2.3e-4), and the joint corrections' muscle solves take
    their Newton directions from each muscle's earlier factorization."""
    options = arm.options
    arm.set_options(replace(options, moment_atol=0.0))
    try:
        state = solver.solve([0.7, 0.3, 0.0, 0.2, 0.0], near_deg=arm.base_state().elbow_angle_deg)
    finally:
        arm.set_options(options)
    summed = sum(abs(m) for m in state.muscle_moments.values())
    assert summed > 1e3
    assert abs(state.moment_residual) <= options.moment_rtol * summed
    assert state.statistics["moment_tolerance_Nmm"] == pytest.approx(options.moment_rtol * summed, rel=1e-9)


def test_joint_corrections_reuse_the_muscles_factorizations(arm, solver):
    """A correction of a few hundredths of a degree: Newton from the predictor with directions
    refined on the factorization of the state it starts from, no new factorization, and the same
    state as with fresh factorizations."""
    hanging = arm.base_state()
    start = solver.muscle_state("biceps", hanging.elbow_angle_deg + 1.0, 0.5)[0]
    unit = arm.units["biceps"]
    theta = start.angle_deg + 0.03
    factorizations = []
    factorize = unit.solver.system.linear_solver.factorize
    unit.solver.system.linear_solver.factorize = lambda A: (factorizations.append(1), factorize(A))
    try:
        reused = unit.solve(theta, 0.5, start, fresh_slope=False)
    finally:
        del unit.solver.system.linear_solver.factorize
    fresh = unit.solve_from_guess(theta, 0.5, start.displacement)
    assert reused.iterations >= 1 and not factorizations
    assert np.abs(reused.displacement - fresh.displacement).max() < 1e-6
    assert reused.moment == pytest.approx(fresh.moment, rel=1e-7)


def test_table_only_path_is_near_the_exact_state(arm, solver):
    """The interpolated state: on a table level the angle comes from Hermite-interpolated FE
    moments (close), the nodes from linear interpolation over 20 deg (coarse but bounded)."""
    alpha = [0.5, 0.0, 0.0, 0.0, 0.0]
    theta, u = solver.interpolate(alpha, near_deg=arm.base_state().elbow_angle_deg)
    exact = solver.solve(alpha, near_deg=arm.base_state().elbow_angle_deg)
    assert abs(theta - exact.elbow_angle_deg) < 0.5
    assert np.abs(u - exact.displacement).max() < 3.0
    assert np.abs(u - exact.displacement).mean() < 0.5


def test_equilibrium_angle_solves_the_tabulated_moment_balance(solver):
    for alpha in ([0, 0, 0, 0, 0], [1, 1, 1, 0, 0], [0, 0, 0, 0.3, 0.3], [0.3, 0.2, 0.1, 0.4, 0.9]):
        theta = solver.equilibrium_angle(alpha)
        assert abs(solver.residual(theta, alpha)[0]) < 1e-6
        # stable: the residual falls through zero (flexing below, extending above)
        assert solver.residual(theta - 0.5, alpha)[0] > 0 > solver.residual(theta + 0.5, alpha)[0]
    assert solver.equilibrium_angle([1, 1, 1, 0, 0]) > solver.equilibrium_angle([0, 0, 0, 0, 0]) \
        > solver.equilibrium_angle([0, 0, 0, 0.3, 0.3])
    # full extensors hold the forearm just above full extension (the flexors pass in front of the
    # trochlea there, the joint limit stiffens below 0 deg)
    assert 0.0 < solver.equilibrium_angle([0, 0, 0, 1, 1]) < 10.0
    # a balance outside the tabulated angles is a clear error (the campaign simulator then solves
    # directly): the hanging arm on the table cut to 40-160 deg
    cut = copy.copy(solver)
    cut._fine = solver._fine[solver._fine >= 40.0]
    cut.lo_deg = 40.0
    cut._level_moments = {m: solver.moments.level_moments(m, cut._fine) for m in MUSCLES}
    with pytest.raises(OutsideTableError, match="lies below the tabulated angles 40 to 160 deg"):
        cut.equilibrium_angle([0, 0, 0, 0, 0])
    # a level that failed at some angles is NaN only for the activations it brackets: the
    # brachialis' passive column cut off above 100 deg leaves the flexed and the hanging arm where
    # they were, and a state that needs it beyond 100 deg is refused with the span it has
    failed = copy.copy(solver)
    rows = solver._level_moments["brachialis"].copy()
    rows[solver._fine > 100.0, 0] = np.nan
    failed._level_moments = {**solver._level_moments, "brachialis": rows}
    for alpha in ([1, 1, 1, 0, 0], [0, 0, 0, 0, 0]):
        assert failed.equilibrium_angle(alpha) == solver.equilibrium_angle(alpha)
    assert solver.equilibrium_angle([1, 0, 1, 0, 0]) > 100.0
    with pytest.raises(OutsideTableError, match=r"lies above the tabulated angles -?\d+ to 100 deg"):
        failed.equilibrium_angle([1, 0, 1, 0, 0])


def test_bad_activations_are_refused_before_any_work(solver):
    for alpha, message in (([1.5, 0, 0, 0, 0], "biceps"), ([0, np.nan, 0, 0, 0], "finite"), ([0, 0, 0], "5")):
        with pytest.raises(ValueError, match=message):
            solver.solve(alpha)
        with pytest.raises(ValueError, match=message):
            solver.interpolate(alpha)


def test_killed_build_resumes_without_recomputing(arm, tmp_path):
    root = tmp_path / "table"
    grid = dict(angles=[50.0, 60.0, 70.0], levels=[0.0, 1.0])
    build_response_table(arm, root, **grid, scheduler="inline", muscles=["brachialis"])
    table = ResponseTable.open(root)
    assert table.done.sum() == 2 and table.done[1].all()  # brachialis only
    first = {j: table.column("brachialis", j) for j in (0, 1)}
    assert np.isfinite(first[1]["tension"]).all() and (first[1]["tension"] > first[0]["tension"]).all()
    # every state has its slope, the one at the mesh pose (60 deg: the rest state) too
    assert all(np.isfinite(first[j]["sensitivity"]).all() for j in (0, 1))
    kept = table.column_path("brachialis", 0).stat().st_mtime_ns
    table.column_path("brachialis", 1).unlink()  # the build was killed before its last column was written
    seen = []
    build_response_table(arm, root, **grid, scheduler="inline", muscles=["brachialis"],
                         progress=lambda done, total: seen.append(done))
    assert table.column_path("brachialis", 0).stat().st_mtime_ns == kept  # not recomputed
    again = ResponseTable.open(root).column("brachialis", 1)
    assert np.allclose(again["tension"], first[1]["tension"], rtol=1e-6)
    assert seen[0] == 1 and seen[-1] == 2


def test_parallel_build_on_dask_workers_equals_the_inline_one(arm, tmp_path):
    """Three muscles on two dask workers: the driver keeps at most one task per worker in flight
    (the third waits and goes to whichever worker frees first); the columns are the inline ones."""
    grid = dict(angles=[55.0, 60.0], levels=[0.0, 1.0])
    table = build_response_table(arm, tmp_path / "dask", **grid, n_workers=2, muscles=["brachialis", "anconeus", "triceps"])
    assert table.done[[1, 3, 4]].all() and not table.done[[0, 2]].any()
    inline = build_response_table(arm, tmp_path / "inline", **grid, scheduler="inline", muscles=["anconeus"])
    for j in (0, 1):
        assert np.allclose(table.column("anconeus", j)["tension"], inline.column("anconeus", j)["tension"], rtol=1e-6)


def test_foreign_or_unfinished_tables_are_refused(arm, tmp_path):
    root = tmp_path / "table"
    build_response_table(arm, root, angles=[55.0, 60.0], levels=[0.0, 1.0], scheduler="inline", muscles=[])
    header = json.loads((root / "header.json").read_text())
    with pytest.raises(ValueError, match="unfinished"):
        TableSolver(arm, ResponseTable.open(root))
    with pytest.raises(TableMismatchError, match="another model: model hash"):
        ResponseTable.open(root, model_hash="0" * 64)
    with pytest.raises(TableMismatchError, match="mesh profile 'coarse', not 'quick'"):
        ResponseTable.open(root, profile="quick")
    with pytest.raises(TableMismatchError, match="another mesh"):
        ResponseTable.open(root, mesh="f" * 64)
    with pytest.raises(TableMismatchError, match="asked for"):
        build_response_table(arm, root, angles=[50.0, 60.0], levels=[0.0, 1.0], scheduler="inline", muscles=[])
    other = tmp_path / "other"
    shutil.copytree(root, other)
    (other / "header.json").write_text(json.dumps({**header, "format": "something-else"}))
    with pytest.raises(TableMismatchError, match="not a response table"):
        ResponseTable.open(other)
    (tmp_path / "stuff").mkdir()
    (tmp_path / "stuff" / "file.txt").write_text("x")
    with pytest.raises(TableMismatchError, match="not a response table"):
        build_response_table(arm, tmp_path / "stuff", angles=[55.0, 60.0], levels=[0.0, 1.0], scheduler="inline")
    with pytest.raises(FileNotFoundError, match="no response table"):
        ResponseTable.open(tmp_path / "nothing")


def test_sensitivity_is_the_slope_of_the_equilibrium(arm):
    """du/dtheta and dM/dtheta from the condensed solve equal the central-difference slopes of
    equilibria at neighbouring angles."""
    unit = arm.units["brachialis"]
    theta, h = unit.mesh_angle_deg, 0.05
    plus = unit.solve(theta + h, 0.5, unit.rest_state())
    minus = unit.solve(theta - h, 0.5, plus)
    centre = unit.solve(theta, 0.5, minus)
    step = np.radians(2 * h)
    slope = (plus.displacement - minus.displacement) / step
    assert np.abs(centre.sensitivity - slope).max() < 1e-2 * np.abs(slope).max()
    assert centre.moment_slope == pytest.approx((plus.moment - minus.moment) / step, rel=1e-3)
    # the insertion face moves rigidly along the line of action, dL/dtheta mm per radian
    face = unit.mesh.node_sets["insertion"]
    dL = unit.path.geometry(theta)[1]
    assert np.allclose(centre.sensitivity[face], dL * unit.direction, atol=1e-9)


def test_hermite_guess_reproduces_table_states_and_beats_linear(arm, solver):
    muscle, level = "brachioradialis", 1  # a = 0.5
    table = solver.table
    k = 3
    at_node = solver.guess(muscle, table.angles_deg[k], 0.5)
    assert np.allclose(at_node.displacement, table.state(muscle, k, level).displacement, atol=1e-5)
    theta = 0.5 * (table.angles_deg[k] + table.angles_deg[k + 1])
    exact = arm.units[muscle].solve(theta, 0.5, table.state(muscle, k, level))
    hermite = np.abs(solver.guess(muscle, theta, 0.5).displacement - exact.displacement).max()
    a, b = table.state(muscle, k, level), table.state(muscle, k + 1, level)
    w = (theta - a.angle_deg) / (b.angle_deg - a.angle_deg)
    linear = np.abs((1 - w) * a.displacement + w * b.displacement - exact.displacement).max()
    assert hermite < 0.5 * linear, (hermite, linear)


def test_tables_of_an_older_format_are_refused(arm, tmp_path):
    root = tmp_path / "table"
    build_response_table(arm, root, angles=[55.0, 60.0], levels=[0.0, 1.0], scheduler="inline", muscles=[])
    header = json.loads((root / "header.json").read_text())
    (root / "header.json").write_text(json.dumps({**header, "version": 1}))
    with pytest.raises(TableMismatchError, match="format version 1"):
        ResponseTable.open(root)


def test_response_tables_answer_as_a_surrogate(arm, solver, tmp_path):
    """The table-only path behind the common surrogate interface: fit, predict, save, load."""
    from persival.campaign.arm_simulator import muscle_surface
    from persival.campaign.simulator import SurfaceTopology
    from persival.surrogate.dataset import Dataset, Surfaces
    from persival.surrogate.open import load_surrogate
    from persival.surrogate.table_surrogate import ResponseTableSurrogate

    names = ("biceps", "triceps")
    surfaces = Surfaces.from_topologies([SurfaceTopology(n, arm.mesh.points[muscle_surface(arm, n)[0]],
                                                         muscle_surface(arm, n)[1]) for n in names])
    alpha = np.array([[0.5, 0, 0, 0, 0], [0.2, 0.4, 0.1, 0.3, 0.0]])
    theta0, u0 = solver.interpolate(alpha[0])
    ids = np.concatenate([muscle_surface(arm, n)[0] for n in names])
    states = np.stack([arm.mesh.points[ids] + solver.interpolate(a)[1][ids] for a in alpha])
    data = Dataset(alpha, states, np.array([solver.interpolate(a)[0] for a in alpha]), surfaces,
                   {"model_hash": arm.model_hash, "label": "FE arm (coarse), table-only"})
    surrogate = ResponseTableSurrogate("coarse", tables=str(FIXTURE)).fit(data)
    assert np.allclose(surrogate.predict(alpha), states)
    assert np.allclose(surrogate.predict_angle(alpha), data.elbow_angles)
    again = load_surrogate(surrogate.save(tmp_path / "tables"))
    assert again.kind == "response-table" and np.allclose(again.predict(alpha[:1]), states[:1])
    with pytest.raises(ValueError, match="same arm"):
        ResponseTableSurrogate("coarse", tables=str(FIXTURE)).fit(
            Dataset(alpha, states, data.elbow_angles, surfaces, {"model_hash": "0" * 64}))


@pytest.mark.slow
def test_a_changed_muscle_rebuilds_only_its_own_columns(arm, tmp_path):
    """The built-in file with the brachioradialis' bow changed is a new model (new hash, new table),
    but the anconeus is the same FE problem: its columns are taken over, not solved again, and the
    changed muscle's key differs."""
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.defaults import default_model_path

    grid = dict(angles=[55.0, 60.0], levels=[0.0, 1.0])
    first = build_response_table(arm, tmp_path / "A", **grid, scheduler="inline", muscles=["anconeus"], reuse_from=[])
    text = default_model_path().read_text()
    start = text.index('name = "brachioradialis"')
    bow = text.index("bow = 10.0", start)
    changed = tmp_path / "changed_arm.toml"
    changed.write_text(text[:bow] + "bow = 12.0" + text[bow + len("bow = 10.0"):])
    other = ArmModel(changed, arm.profile)
    assert other.model_hash != arm.model_hash

    second = build_response_table(other, tmp_path / "B", **grid, scheduler="inline", muscles=["anconeus"],
                                  reuse_from=[tmp_path / "A"])
    keys_a, keys_b = first.header["muscle_keys"], second.header["muscle_keys"]
    assert keys_a["anconeus"] == keys_b["anconeus"] and keys_a["brachioradialis"] != keys_b["brachioradialis"]
    assert [keys_a[m] == keys_b[m] for m in ("biceps", "brachialis", "triceps")] == [True] * 3
    for level in (0, 1):  # the very columns, seconds of compute included: copied, not solved again
        a, b = first.column("anconeus", level), second.column("anconeus", level)
        assert all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)
    assert not second.done[[0, 1, 2, 3]].any()
