"""The motion-and-load activation model (SPEC 5 beyond the paper), on the coarse FE moment table
of tests/data through the deployed model's moment balance (see tests/tables/test_moment_table.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from persival.surrogate.least_effort import _moments_at, least_effort
from persival.surrogate.motion_model import MotionActivationModel
from persival.surrogate.motion_onnx import motion_probe
from persival.tables.moment_table import MomentTable
from persival.vocabulary import MUSCLES

FIXTURE = Path(__file__).parents[1] / "data" / "moments_coarse.npz"
FLEXORS = slice(0, 3)


@pytest.fixture(scope="module")
def table():
    return MomentTable.load(FIXTURE)


@pytest.fixture(scope="module")
def balance(table):
    """The deployed model's moment balance on the table (what the motion model solves on)."""
    from persival.model.arm.model_file import load_model_file
    from persival.surrogate.structured.moment_model import MomentModel

    return MomentModel.from_table(table, load_model_file(None)[0], near_deg=30.0)


@pytest.fixture(scope="module")
def model(balance):
    return MotionActivationModel.build(balance)


def rows(theta, load=0.0, velocity=0.0, acceleration=0.0):
    theta = np.atleast_1d(np.asarray(theta, float))
    return np.column_stack([theta, np.full_like(theta, velocity), np.full_like(theta, acceleration),
                            np.full_like(theta, load)])


def residual(balance, model, motion, activations):
    """sum_m M_m(Theta, a_m) - M_req with the deployed balance's own interpolant (N mm)."""
    total = sum(balance.muscle_moment(name, motion[:, 0], activations[:, m]) for m, name in enumerate(MUSCLES))
    return total - model.required_moment(motion)


def test_at_rest_the_activations_balance_the_joint(table, balance, model):
    theta = np.linspace(15.0, 110.0, 77)
    motion = rows(theta)
    a, feasible = model.predict(motion)
    assert feasible.all() and (a >= 0).all() and (a <= 1).all()
    # M_req at zero load and acceleration is -(M_g + M_p): the same balance as the arm's (SPEC 3.3)
    # (to the 1-degree grid's linear interpolation: 0.5 N mm)
    expected = -(table.gravity_moment(theta) + table.passive_joint_moment(theta))
    assert np.allclose(model.required_moment(motion), expected, rtol=0, atol=0.5)
    res = residual(balance, model, motion, a)
    scale = np.abs(model.required_moment(motion)).max()
    assert np.abs(res).max() < 0.01 * scale  # the (Theta, s) grid's interpolation
    levels = np.linspace(0.0, 1.0, 33)
    V = np.stack([[balance.muscle_moment(n, np.full(33, t), levels) for n in MUSCLES] for t in theta])
    exact, ok = least_effort(V, levels, model.required_moment(motion))
    assert ok.all() and np.abs(residual(balance, model, motion, exact)).max() < 2.0  # the 33 samples' chords
    assert np.abs(a - exact).max() < 0.02


def test_the_activations_hold_the_deployed_balance_at_the_angle_asked(balance, model):
    """SPEC 5: the angle a user asks for (with a load) is the deployed balance's root, within 0.5 deg."""
    rng = np.random.default_rng(1)
    lo, hi = model.static_range_deg()
    theta = rng.uniform(lo, hi, 300)
    load = rng.uniform(0.0, 0.999, 300) * np.minimum(model.holdable_load_kg(theta), 5.0)
    a, feasible = model.predict(rows(theta) + np.column_stack([np.zeros((300, 3)), load]))
    assert feasible.all()
    achieved = balance.equilibrium(a, load)
    assert np.abs(achieved - theta).max() < 0.5
    assert lo == 10.0 and hi > 140.0  # the coarse arm holds itself from 10 deg to its reach


def test_load_and_acceleration_raise_flexor_activation_velocity_does_nothing(model):
    theta = np.linspace(35.0, 90.0, 12)
    one, ok1 = model.predict(rows(theta, 0.5))
    two, ok2 = model.predict(rows(theta, 1.0))
    assert ok1.all() and ok2.all()
    assert np.all(two[:, FLEXORS].sum(1) > one[:, FLEXORS].sum(1) + 0.01)
    assert np.all(two[:, FLEXORS] >= one[:, FLEXORS] - 1e-9)
    assert np.all(two[:, 3:] < 0.01)  # extensors stay off when flexing against gravity
    fast, _ = model.predict(rows(theta, 0.5, acceleration=300.0))
    assert np.all(fast[:, FLEXORS].sum(1) > one[:, FLEXORS].sum(1))
    assert np.array_equal(model.predict(rows(theta, 0.5, velocity=250.0))[0], one)


def test_too_heavy_a_load_is_flagged_not_clipped_silently(model):
    held = model.holdable_load_kg(np.array([60.0, 90.0]))
    assert np.all(held > 0.5) and held[0] > held[1]  # more lever for gravity at 90 deg
    a, feasible, deficit = model.predict(rows([60.0, 90.0], held.max() + 5.0), with_deficit=True)
    assert not feasible.any() and np.all(deficit > 0)
    assert np.allclose(a[:, FLEXORS], 1.0, atol=0.05)  # the best effort, flagged
    _, ok = model.predict(rows([90.0], 0.95 * held[1]))
    assert ok.all()
    for bad, match in ((rows([90.0], -1.0), "load must be >= 0"), (rows([np.nan]), "not finite"),
                       (rows([300.0]), "outside the model's range"), (np.zeros((2, 3)), "shape")):
        with pytest.raises(ValueError, match=match):
            model.predict(bad)


def test_least_effort_is_not_beaten_by_slsqp(table):
    from scipy.optimize import minimize

    theta = np.array([40.0, 70.0, 95.0])
    V = np.stack([table.level_moments(n, theta) for n in MUSCLES], 1)
    R = np.array([3000.0, 5000.0, 2500.0])
    a, ok = least_effort(V, table.levels, R)
    assert ok.all()
    rng = np.random.default_rng(0)
    for i in range(3):
        balance = {"type": "eq", "fun": lambda x, i=i: _moments_at(V[i:i + 1], table.levels, x[None])[0] - R[i]}
        for _ in range(4):
            r = minimize(lambda x: x @ x, rng.uniform(0, 1, 5), method="SLSQP", bounds=[(0, 1)] * 5,
                         constraints=[balance], options={"ftol": 1e-12, "maxiter": 300})
            if r.success and abs(balance["fun"](r.x)) < 1e-3:
                assert a[i] @ a[i] <= r.fun + 1e-4


def test_onnx_agrees_with_python_and_files_round_trip(model, tmp_path):
    import onnxruntime as ort

    entry = model.export_onnx(tmp_path)
    assert entry["file"] == "activation_motion.onnx" and entry["input"] == "motion" and entry["max_load_kg"] > 0
    session = ort.InferenceSession(str(tmp_path / entry["file"]), providers=["CPUExecutionProvider"])
    assert [o.name for o in session.get_outputs()] == ["activations", "moment_deficit_Nmm"]
    probe = motion_probe(model, 300, seed=3).astype(np.float32)
    got, deficit = session.run(None, {"motion": probe})
    ref, feasible, ref_deficit = model.predict(probe.astype(np.float64), with_deficit=True)
    assert got.shape == (300, 5) and got.dtype == np.float32 and deficit.shape == (300, 1)
    assert np.abs(got - ref)[feasible].max() < 1e-6
    assert np.array_equal(deficit[:, 0] == 0, feasible) and np.allclose(deficit[:, 0], ref_deficit, rtol=1e-5, atol=1e-3)
    again = MotionActivationModel.load(model.save(tmp_path / "saved"))
    assert np.array_equal(again.predict(probe.astype(np.float64))[0], ref)


def test_cli_builds_the_model_and_refuses_a_foreign_table(tmp_path):
    from typer.testing import CliRunner

    from persival.cli import app

    runner = CliRunner()
    result = runner.invoke(app, ["motion", "--table", str(FIXTURE), "--out", str(tmp_path / "m"), "--angles", "60,90"])
    assert result.exit_code == 0, result.output
    assert {p.name for p in (tmp_path / "m").iterdir()} >= {"motion_model.json", "motion_model.npz", "motion_model.png",
                                                             "activation_motion.onnx"}
    foreign = tmp_path / "foreign.toml"
    from persival.model.arm.defaults import default_model_path

    foreign.write_text(default_model_path().read_text() + "\n# another model\n")
    result = runner.invoke(app, ["motion", "--table", str(FIXTURE), "--out", str(tmp_path / "x"), "--model", str(foreign)])
    assert result.exit_code == 2 and "another model" in result.stderr and not (tmp_path / "x").exists()
