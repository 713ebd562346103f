"""Adaptive sparse grid grown on a real (analytic-simulator) campaign, and the held-out accuracy
stage with the SPEC 7 metrics (issue 5)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from persival.campaign.design import Design
from persival.campaign.runner import INLINE, run_campaign
from persival.campaign.simulator import SimulatorSpec
from persival.campaign.store import CampaignStore
from persival.evaluate.metrics import state_errors, summarize
from persival.evaluate.surrogate_accuracy import accuracy_report, load_held_out, surrogate_errors
from persival.surrogate.adaptive_campaign import run_adaptive_campaign
from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate

SPEC = SimulatorSpec("analytic", {"mesh_size": 14.0})


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory):
    root = tmp_path_factory.mktemp("adaptive")
    run_campaign(root / "l1.zarr", Design.sparse_grid(1), SPEC, scheduler=INLINE, progress=False)
    run_campaign(root / "test.zarr", Design.random(40, seed=7), SPEC, scheduler=INLINE, progress=False)
    SparseGridSurrogate("biceps").fit(root / "l1.zarr").save(root / "regular")
    return root


def _all_states(stores):
    points, positions = [], []
    for path in stores:
        with CampaignStore.open(path) as s:
            points.append(s.activations)
            positions.append(s.surface_positions("biceps"))
    return np.concatenate(points), np.concatenate(positions)


@pytest.mark.slow
def test_adaptive_solves_every_point_once_interpolates_and_resumes(tmp_path):
    logs = []
    result = run_adaptive_campaign(tmp_path / "ad", SPEC, max_points=243, progress=False, log=logs.append)
    grid = result.surrogate.grid
    assert 200 <= grid.n_points <= 243
    stores = sorted((tmp_path / "ad" / "stores").glob("*.zarr"))
    points, positions = _all_states(stores)
    # every grid point was solved exactly once, nothing else was solved
    assert len(points) == grid.n_points == result.simulated
    assert len({p.tobytes() for p in points}) == len(points)
    assert {p.tobytes() for p in points} == {p.tobytes() for p in np.asarray(grid.points)}
    # the surrogate interpolates the FE states at its points
    predicted = result.surrogate.predict(points)
    assert np.abs(predicted - positions).max() < 1e-8
    # refinement went below level 1 somewhere: adaptive, not regular
    assert grid.levels.max() >= 2
    assert logs and "solving" in logs[0]
    meta = json.loads((tmp_path / "ad" / "surrogate" / "surrogate.json").read_text())
    assert meta["adaptive"]["grid_points_per_step"][-1] == grid.n_points
    # the same command again finds every state on disk and solves nothing
    again = run_adaptive_campaign(tmp_path / "ad", SPEC, max_points=243, progress=False)
    assert again.simulated == 0 and again.reused == grid.n_points
    assert np.array_equal(again.surrogate.grid.points, grid.points)


@pytest.mark.slow
def test_seed_store_states_are_reused_and_a_foreign_model_is_refused(campaigns, tmp_path):
    result = run_adaptive_campaign(tmp_path / "ad", SPEC, max_points=243, seed_stores=[campaigns / "l1.zarr"],
                                   progress=False)
    grid = result.surrogate.grid
    in_l1 = np.all(np.isin(np.asarray(grid.points), [0.0, 0.5, 1.0]), axis=1)
    assert result.reused == in_l1.sum() >= 32
    assert result.simulated == (~in_l1).sum() > 0
    coarse = SimulatorSpec("analytic", {"mesh_size": 20.0})
    run_campaign(tmp_path / "coarse.zarr", Design.random(3, seed=1), coarse, scheduler=INLINE, progress=False)
    with pytest.raises(ValueError, match="another model"):
        run_adaptive_campaign(tmp_path / "mixed", SPEC, max_points=64, progress=False,
                              seed_stores=[campaigns / "l1.zarr", tmp_path / "coarse.zarr"])
    with pytest.raises(ValueError, match="computed with"):
        run_adaptive_campaign(tmp_path / "other", coarse, max_points=64, seed_stores=[campaigns / "l1.zarr"],
                              progress=False)


def test_adaptive_beats_regular_at_equal_budget_on_held_out_states(campaigns, tmp_path):
    run_adaptive_campaign(tmp_path / "ad", SPEC, max_points=243, seed_stores=[campaigns / "l1.zarr"], progress=False)
    report = accuracy_report({"regular": campaigns / "regular", "adaptive": tmp_path / "ad" / "surrogate"},
                             campaigns / "test.zarr")
    regular, adaptive = report["surrogates"]["regular"], report["surrogates"]["adaptive"]
    assert report["test_states"] == 40
    # every number says what it was measured on: these are the analytic stand-in's states
    assert report["test_source"]["label"] == "analytic stand-in, 40 states"
    assert regular["source"] == "analytic stand-in, 243 states" and adaptive["source"].startswith("analytic stand-in")
    assert adaptive["states"] <= regular["states"] == 243
    assert adaptive["mean MAE_mm"] < 0.5 * regular["mean MAE_mm"]
    assert adaptive["max MaxAE_mm"] < regular["max MaxAE_mm"]
    # replaying the refinement: the last step is the final surrogate, and the error falls
    path = report["refinement"]["adaptive"]
    assert path[-1]["states"] == adaptive["states"]
    assert path[-1]["mean MAE_mm"] == pytest.approx(adaptive["mean MAE_mm"], rel=1e-9)
    assert path[-1]["mean MAE_mm"] < path[0]["mean MAE_mm"]


def test_accuracy_command_writes_table_and_figure(campaigns, tmp_path):
    from persival.cli import evaluate as commands

    app, bench = typer.Typer(), typer.Typer()
    app.add_typer(bench, name="bench")
    commands.register(app)
    runner = CliRunner()
    res = runner.invoke(app, ["accuracy", "--test", str(campaigns / "test.zarr"),
                              "--surrogate", f"regular={campaigns / 'regular'}", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert "MaxAE" in res.output and (tmp_path / "accuracy.png").stat().st_size > 10_000
    assert "analytic stand-in" in res.output and "FE states" not in res.output
    report = json.loads((tmp_path / "accuracy.json").read_text())
    assert report["surrogates"]["regular"]["states"] == 243 and "fe_states" not in json.dumps(report)
    bad = runner.invoke(app, ["accuracy", "--test", str(campaigns / "test.zarr"), "--surrogate", "regular"])
    assert bad.exit_code == 2 and "LABEL=DIR" in bad.output


def test_surrogate_of_another_model_is_not_compared(campaigns, tmp_path):
    run_campaign(tmp_path / "coarse.zarr", Design.random(3, seed=1), SimulatorSpec("analytic", {"mesh_size": 20.0}),
                 scheduler=INLINE, progress=False)
    surrogate = SparseGridSurrogate.load(campaigns / "regular")
    with pytest.raises(ValueError, match="not comparable"):
        surrogate_errors(surrogate, load_held_out(tmp_path / "coarse.zarr"))


def test_metrics_by_hand():
    ref = np.zeros((2, 4, 3))
    u = np.zeros((2, 4, 3))
    u[0, 0, 0], u[1, 2, 1] = 10.0, 4.0  # largest displacement per state: 10 and 4 mm
    pred = ref.copy()
    pred[0, :, 2] = 1.0  # state 0: every node 1 mm off
    pred[1, 3, 0] = 2.0  # state 1: one node 2 mm off
    e = state_errors(pred, ref, u)
    np.testing.assert_allclose(e["MaxAE_mm"], [1.0, 2.0])
    np.testing.assert_allclose(e["MAE_mm"], [1.0, 0.5])
    np.testing.assert_allclose(e["MaxRE_pct"], [10.0, 50.0])
    np.testing.assert_allclose(e["MRE_pct"], [10.0, 12.5])
    s = summarize(e)
    assert s["max MaxAE_mm"] == 2.0 and s["mean MAE_mm"] == 0.75
    with pytest.raises(ValueError, match="shape"):
        state_errors(pred[:, :3], ref, u)
    with pytest.raises(ValueError, match="no displacement"):
        state_errors(pred, ref, np.zeros_like(u))
    bad = pred.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        state_errors(bad, ref, u)


@pytest.mark.slow
def test_adapt_command_stops_on_tolerance_and_rejects_bad_input(tmp_path):
    from persival.cli import surrogate as commands

    app, bench = typer.Typer(), typer.Typer()
    app.add_typer(bench, name="bench")
    commands.register(app)
    runner = CliRunner()
    args = ["surrogate", "adapt", "--out", str(tmp_path / "ad"), "--max-points", "243", "--simulator", "analytic",
            "--option", "mesh_size=14", "--no-progress"]
    res = runner.invoke(app, [*args, "--tol", "1e6"])  # no surplus reaches 1 km: the corners only
    assert res.exit_code == 0, res.output
    assert "32 points" in res.output and "tolerance" in res.output
    res = runner.invoke(app, [*args, "--tol", "5"])  # refine while some surplus exceeds 5 mm / deg
    assert res.exit_code == 0, res.output
    meta = json.loads((tmp_path / "ad" / "surrogate" / "surrogate.json").read_text())
    assert meta["adaptive"]["tol"] == 5.0 and meta["grid_points"] > 32
    bad = runner.invoke(app, ["surrogate", "adapt", "--out", str(tmp_path / "x"), "--max-points", "10",
                              "--simulator", "external"])
    assert bad.exit_code == 2 and "arm or analytic" in bad.output
    small = runner.invoke(app, ["surrogate", "adapt", "--out", str(tmp_path / "y"), "--max-points", "10",
                                "--simulator", "analytic", "--no-progress"])
    assert small.exit_code == 2 and "32 > max_points=10" in small.output
