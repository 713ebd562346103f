"""The built-in arm's equilibria (coarse profile, real FE solves): docs/theory.md 3.

One module-scoped set of states keeps the suite fast: the hanging arm, then the biceps near 0.5
with every muscle a little active (``DIRECT``) by the direct coupled continuation (its progress
reports, its retries), then the biceps at 1 and the triceps added to the biceps at 0.5 by the
exact path on the response-table fixture
(converged FE states too: the first test below checks the two paths agree). The suite runs with
``--dist loadfile``: a module's tests run together on one xdist worker, so its module fixtures
are built once (with ``--dist load`` both workers built the states, 342 and 379 s; with
``loadgroup`` they were rebuilt whenever another module's tests came in between: four builds
of 180 to 270 s).
"""

import json
from pathlib import Path

import numpy as np
import pytest

from persival.model.arm.arm_model import ArmModel
from persival.model.arm.state_cache import mesh_fingerprint
from persival.model.fe.solver import ConvergenceError
from persival.tables.moment_table import TableMismatchError
from persival.tables.response_table import ResponseTable
from persival.tables.table_solve import TableSolver

pytestmark = pytest.mark.slow  # a shared fixture of this module takes minutes (make test-fast skips it)

FIXTURE = Path(__file__).parents[1] / "data" / "response_table_coarse"


@pytest.fixture(scope="module")
def arm():
    return ArmModel(profile="coarse")


REPORTS = []  # progress of the direct solve (persival.model.arm.progress)
#: The direct solve's activations: the biceps near half, every muscle off the fixture table's
#: levels (0, 0.5, 1), so the exact path's comparison below interpolates in a for all five.
DIRECT = [0.45, 0.1, 0.15, 0.05, 0.1]


@pytest.fixture(scope="module")
def tables(arm):
    """The exact path on the fixture tables; a fixture of another model or mesh fails with the
    command that rebuilds it."""
    from conftest import REBUILD_TABLES

    try:
        return TableSolver(arm, ResponseTable.open(FIXTURE, arm.model_hash, "coarse", mesh_fingerprint(arm.mesh)))
    except TableMismatchError as exc:
        pytest.fail(f"the response-table fixture is of another model or mesh ({exc}); rebuild it: {REBUILD_TABLES}")


@pytest.fixture(scope="module")
def states(arm, tables):
    hanging = arm.base_state()
    half = arm.solve(DIRECT, warm_start=hanging, progress=REPORTS.append)

    def solve(alpha):
        return tables.solve(alpha, near_deg=half.elbow_angle_deg)

    return hanging, half, solve([1.0, 0, 0, 0, 0]), solve([0.5, 0, 0, 0.5, 0])


def test_exact_path_on_the_tables_is_the_direct_solve(arm, tables, states):
    """Same converged FE state by both paths for activations off the table's levels (Newton from
    the neighbouring levels' states): theta within 0.05 deg, every node within 0.01 mm."""
    direct = states[1]
    assert not np.isin(direct.activations, tables.table.levels).any()
    exact = tables.solve(direct.activations, near_deg=states[0].elbow_angle_deg)
    assert exact.statistics["table_start"]
    assert abs(exact.elbow_angle_deg - direct.elbow_angle_deg) < 0.05
    assert np.abs(exact.displacement - direct.displacement).max() < 0.01
    assert abs(exact.moment_residual) <= arm.moment_tolerance(exact.muscle_states)
    assert exact.max_volume_change < 0.01


def test_hanging_arm_is_near_extension_and_balanced(arm, states):
    hanging = states[0]
    assert 0.0 < hanging.elbow_angle_deg < 40.0
    assert abs(hanging.moment_residual) <= arm.moment_tolerance(hanging.muscle_states)
    # moments add up: muscles + gravity + passive joint
    assert sum(hanging.muscle_moments.values()) + hanging.external_moment == pytest.approx(0.0, abs=1e-3)


def test_biceps_flexes_monotonically_and_triceps_extends(states):
    hanging, half, full, against = states
    assert hanging.elbow_angle_deg + 20.0 < half.elbow_angle_deg < full.elbow_angle_deg
    assert against.elbow_angle_deg < half.elbow_angle_deg - 3.0
    assert full.muscle_forces["biceps"] > half.muscle_forces["biceps"] > hanging.muscle_forces["biceps"]
    for state in states:
        assert state.max_volume_change < 0.02  # nearly incompressible (docs/theory.md 1.2)


def test_monolithic_formulation_agrees(arm, states):
    """The muscle-unit decomposition is exact: in the whole-mesh formulation with every face
    tied to the elbow (Hinge ball joints) the same state is in equilibrium."""
    for state in (states[0], states[2]):
        force, moment = arm.verify_equilibrium(state)
        assert force < 1e-5  # N, largest nodal residual of the free DOFs
        assert abs(moment) < 1e-3  # N mm, hinge virtual work minus gravity and joint


def test_virtual_work_of_a_small_rotation_restores(arm, states):
    """Independent check: prescribe theta* +- 0.5 deg and re-equilibrate the muscles; the net
    moment residual changes sign (restoring) and matches the joint stiffness."""
    state = states[1]
    theta = state.elbow_angle_deg
    g_minus, _, _ = arm.moment_balance(theta - 0.5, state.activations, state.muscle_states)
    g_plus, _, _ = arm.moment_balance(theta + 0.5, state.activations, state.muscle_states)
    assert g_minus < 0.0 < g_plus
    slope = (g_plus - g_minus) / np.radians(1.0)
    assert slope == pytest.approx(state.statistics["joint_stiffness_Nmm_per_rad"], rel=0.05)


def test_biceps_belly_thickens_as_it_shortens(arm, states):
    hanging, _, full, _ = states
    unit = arm.units["biceps"]
    axis = unit.direction  # in the muscle's own frame the bow is symmetric: mid tangent = chord
    s = ((unit.mesh.points - unit.origin) @ axis) / unit.mesh_length
    middle = np.abs(s - 0.5) < 0.03

    def belly_radius(state):
        y = unit.mesh.points[middle] + state.muscle_states["biceps"].displacement[middle]
        r = y - y.mean(axis=0)
        r -= np.outer(r @ axis, axis)
        return np.linalg.norm(r, axis=1).max()

    shortening = hanging.muscle_states["biceps"].length - full.muscle_states["biceps"].length
    assert shortening > 20.0
    assert belly_radius(full) > 1.03 * belly_radius(hanging)


def test_non_convergence_is_a_clear_error_and_writes_nothing(arm, states, tmp_path, monkeypatch):
    from dataclasses import replace

    default = arm.options
    arm.set_options(replace(default, max_iterations=1, min_step=0.5))
    try:
        with pytest.raises(ConvergenceError, match="muscle"):
            arm.solve([0.0, 0.0, 1.0, 0.0, 0.0], warm_start=states[0])
    finally:
        arm.set_options(default)
    assert not list(tmp_path.iterdir())


def test_state_files_and_render(arm, states, tmp_path):
    pytest.importorskip("pyvista")
    from persival.evaluate.render import render_states
    from persival.model.arm.output import write_state

    dirs = [write_state(arm, s, tmp_path / f"state{k}") for k, s in enumerate(states[:3])]
    summary = json.loads((dirs[2] / "state.json").read_text())
    assert summary["elbow_angle_deg"] == pytest.approx(states[2].elbow_angle_deg)
    assert abs(summary["moment_residual_Nmm"]) <= arm.moment_tolerance(states[2].muscle_states)
    png = render_states(dirs, tmp_path / "arm.png", window=(200, 260))
    from PIL import Image

    image = np.asarray(Image.open(png).convert("RGB")).astype(float)
    assert image.shape[0] > 260 and image.shape[1] > 1.2 * image.shape[0]  # panels side by side, titles, colour bar
    assert (image.min(axis=2) < 245).mean() > 0.15  # framed to the arm, not mostly white (unframed: 0.12)
    assert (image.std(axis=2) > 10).mean() > 0.05  # coloured muscles (bones are grey)
    with pytest.raises(FileNotFoundError, match="state.json"):
        render_states([tmp_path], tmp_path / "x.png")


def test_held_arm_carries_the_joint_residual_and_draws(arm, states, tmp_path):
    """The arm held 2 deg past the biceps-0.5 equilibrium (an isometric state): every muscle in
    its own equilibrium there, and the brace's moment is the joint residual g, close to the joint
    stiffness times the offset; the state draws with a held title, one muscle, and in section."""
    pytest.importorskip("pyvista")
    from persival.evaluate.render import render_states
    from persival.evaluate.sections import _outline, render_sections
    from persival.model.arm.output import write_state

    half, offset = states[1], 2.0
    held = arm.hold(half.activations, half.elbow_angle_deg + offset, warm_start=half)
    stiffness = half.statistics["joint_stiffness_Nmm_per_rad"]
    assert held.elbow_angle_deg == half.elbow_angle_deg + offset
    assert held.statistics["brace_moment_Nmm"] == held.moment_residual
    assert held.moment_residual == pytest.approx(stiffness * np.radians(offset), rel=0.1)
    assert sum(held.muscle_moments.values()) + held.external_moment + held.moment_residual == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(ValueError, match="joint limits"):
        arm.hold(half.activations, 200.0, warm_start=half)
    dirs = [write_state(arm, s, tmp_path / name) for name, s in (("half", half), ("held", held))]
    assert json.loads((dirs[1] / "state.json").read_text())["newton"]["held_at_deg"] == held.elbow_angle_deg
    assert render_states(dirs, tmp_path / "biceps.png", window=(200, 260), muscles=["biceps"]).is_file()
    import pyvista as pv

    biceps = pv.read(dirs[1] / "biceps.vtu").extract_surface(algorithm="dataset_surface")
    ring = _outline(biceps, 150.0)  # a closed outline across the belly
    assert len(ring) > 10 and np.ptp(ring[:, :, 1]) > 20.0
    assert render_sections(dirs, [100.0, 150.0], tmp_path / "sections.png", ["biceps", "brachialis"]).is_file()


def test_render_without_a_display_is_quiet(arm, states, tmp_path):
    """Off-screen VTK without DISPLAY: no "bad X server connection" (nor any other) warning."""
    import os
    import subprocess
    import sys

    pytest.importorskip("pyvista")
    from persival.model.arm.output import write_state

    folder = write_state(arm, states[0], tmp_path / "hanging")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "VTK_DEFAULT_OPENGL_WINDOW")}
    code = f"from persival.evaluate.render import render_states; render_states([{str(folder)!r}], {str(tmp_path / 'a.png')!r})"
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "a.png").is_file()
    assert "X server" not in run.stderr and "WARN" not in run.stderr, run.stderr


def test_solve_reports_progress(states):
    """The direct solve reported every load step: joint iterations, the angle, the muscles."""
    assert REPORTS, "no progress reported"
    assert [r.load_steps for r in REPORTS] == list(range(1, len(REPORTS) + 1))
    assert {r.phase for r in REPORTS} == {"joint equilibrium"}
    assert REPORTS[-1].joint_iteration == states[1].statistics["joint_iterations"]
    assert "joint iteration" in str(REPORTS[-1]) and REPORTS[-1].muscle in str(REPORTS[-1])


@pytest.fixture(scope="module")
def curves(arm, states, tables):
    """Every muscle's passive and active moment (persival curves) just below and above the hanging
    angle, at the mesh pose and at 90 and 120 deg: the FE states by the exact path on the fixture
    tables (one continuation sweep per muscle and activation without them: 387 s, the suite's
    slowest fixture; the sweeps themselves build every table column, tests/tables/test_moment_table.py)."""
    from persival.evaluate.muscle_curves import muscle_curves

    theta = np.floor(states[0].elbow_angle_deg)
    return muscle_curves(arm, np.array([theta, theta + 1.0, 60.0, 90.0, 120.0]), tables=tables)


def test_moment_curves_predict_the_hanging_arm(states, curves):
    """The calibration tool (persival curves): per-muscle sweeps summed with gravity and the
    joint bracket the FE hanging angle; a muscle at its mesh length pulls (almost) nothing."""
    from persival.evaluate.muscle_curves import predicted_equilibrium

    assert predicted_equilibrium(curves, (0, 0, 0, 0, 0)) == pytest.approx(states[0].elbow_angle_deg, abs=0.05)
    assert curves["angles_deg"][2] == 60.0
    assert abs(curves["biceps"]["passive_tension_N"][2]) < 3.0  # biceps meshed at 60 deg (lambda_0 1.3: 2.2 N)
    assert np.all(curves["biceps"]["active_moment_Nmm"][:3] > 5 * curves["biceps"]["passive_moment_Nmm"][:3])


def test_moment_arms_follow_the_line_of_action_and_are_checked_against_the_bands(curves, tmp_path):
    """Without contact a muscle's FE moment arm M / T is its line of action's -dL/dtheta; the
    band check reads it where the bands are, and the plot carries all four panels."""
    from persival.evaluate.muscle_curves import MOMENT_ARM_BANDS_MM, band_check, moment_arms, plot_curves

    angles = curves["angles_deg"]
    arms = moment_arms(curves)
    for name in ("brachialis", "triceps"):
        assert np.abs(curves[name]["active_tension_N"]).min() > 1.0
        np.testing.assert_allclose(arms[name], -curves[name]["dL_dtheta_mm_per_rad"], rtol=1e-9)
    rows = band_check(curves)
    assert len(rows) == len(MOMENT_ARM_BANDS_MM)
    brachialis_90 = next(r for r in rows if r["muscle"] == "brachialis" and r["angles_deg"] == [85.0, 95.0])
    expected = np.interp([85.0, 90.0, 95.0], angles, arms["brachialis"])
    np.testing.assert_allclose(brachialis_90["model_mm"], [expected.min(), expected.max()])
    assert brachialis_90["inside"] == bool(expected.min() >= 18.0 and expected.max() <= 30.0)
    failed = {**curves, "biceps": {**curves["biceps"], "active_tension_N": np.full(len(angles), np.nan)}}
    assert np.isnan(moment_arms(failed)["biceps"]).all() and band_check(failed)[0]["inside"] is None
    assert plot_curves(curves, tmp_path / "curves.png").stat().st_size > 20_000


def test_a_stalled_activation_jump_detours_through_the_taut_mesh_pose(arm, monkeypatch):
    from scipy.optimize import brentq

    unit = arm.units["brachialis"]
    # the angle where the brachialis is 15 mm shorter than in its mesh pose
    slack = brentq(lambda t: unit.length(t) - (unit.mesh_length - 15.0), unit.mesh_angle_deg, 160.0)
    start = unit._continue(slack, 0.0, unit.rest_state(), detour=False)  # passive and shortened: bowed
    taut = unit._continue(unit.mesh_angle_deg, 1.0, unit.rest_state(), detour=False)  # activated in its mesh pose
    reference = unit._continue(slack, 1.0, taut, detour=False)
    assert reference.tension > 0.0 > start.tension - 1.0  # activated it pulls; slack it barely pushes

    real_solve = unit.solver.solve
    calls = []

    def stall_first(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise ConvergenceError("line search failed to reduce the residual")
        return real_solve(*args, **kwargs)

    monkeypatch.setattr(unit.solver, "solve", stall_first)
    state = unit._continue(slack, 1.0, start)
    assert len(calls) == 3  # the stalled jump, then activate at the mesh pose, then shorten
    # two Newton solutions from different starts agree to the solver's force tolerance (1e-6 N):
    # 9.2e-8 mm with the session VI brachialis (lambda_0 1.30)
    np.testing.assert_allclose(state.displacement, reference.displacement, rtol=0, atol=1e-6)

    def always_stall(*args, **kwargs):
        raise ConvergenceError("line search failed to reduce the residual")

    monkeypatch.setattr(unit.solver, "solve", always_stall)
    with pytest.raises(ConvergenceError, match="muscle .brachialis. from .* deg, activation .* line search failed"):
        unit._continue(slack, 1.0, start)


def test_solve_retries_with_smaller_steps_then_names_every_reason(arm, states, monkeypatch):
    """ArmModel.solve's retry ladder: smaller first activation steps, then a failure
    that says what each try hit; the model's options are left as they were."""
    original, steps = arm._equilibrium, []

    def flaky(target, start, angle, tracker):
        steps.append(arm.options.initial_step)
        if len(steps) < 2:
            raise ConvergenceError("stalled at t = 0.18")
        return original(target, start, angle, tracker)

    before = arm.options
    monkeypatch.setattr(arm, "_equilibrium", flaky)
    state = arm.solve(DIRECT, warm_start=states[1])  # from its own equilibrium: the ladder, not the physics, costs
    assert state.statistics["tries"] == 2 and steps == [before.initial_step, before.initial_step / 2]
    assert arm.options == before

    def stalled(target, start, angle, tracker):
        raise ConvergenceError("stalled")

    monkeypatch.setattr(arm, "_equilibrium", stalled)
    with pytest.raises(ConvergenceError, match="failed 3 tries: first step 0.25: stalled; first step 0.125"):
        arm.solve([0.6, 0, 0, 0, 0], warm_start=states[1])
    assert arm.options == before
