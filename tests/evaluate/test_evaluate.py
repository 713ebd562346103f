"""The evaluation stage on a tiny real run folder: SPEC 7 tables, prototypes, figures, SPEC 8 bench.

The run is the session's small real run (tests/conftest.py: analytic level-1 campaign, SG of
all five muscles, activation model, SG training data, a POD net and a paper net on the biceps
trained for a few epochs, ONNX export), copied once so that the evaluation can write into it;
tests/evaluate/test_report.py reuses the copy and its evaluation.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from persival.evaluate.accuracy_tables import StoppingRule, draw_until_stable
from persival.evaluate.prototypes import SHAPES, dense_parameters, prototype_widths

pytestmark = pytest.mark.slow  # a shared fixture of this module takes minutes (make test-fast skips it)

TABLES = ("in_training", "random_activations", "random_angles", "error_propagation", "prototypes")
# tests/evaluate/test_report.py imports the fixtures below, which makes pytest hold a second copy of each:
# this cache lets both copies share one run per session
_SESSION: dict = {}


@pytest.fixture(scope="session")
def tiny_run(small_run, tmp_path_factory) -> Path:
    """A private copy of the session's small run (tests/conftest.py): evaluate writes into it."""
    if "run" not in _SESSION:
        _SESSION["run"] = Path(shutil.copytree(small_run, tmp_path_factory.mktemp("evaluate") / "run", symlinks=True))
    return _SESSION["run"]


@pytest.fixture(scope="session")
def evaluated(tiny_run) -> dict:
    from persival.evaluate.evaluation import evaluate_run, run_bench

    if "evaluated" not in _SESSION:
        t0 = time.perf_counter()
        result = evaluate_run(tiny_run, progress=False, bench=False)
        result["bench"] = run_bench(tiny_run, progress=False, reps=40, budget_s=0.2, peer=False)
        print(f"\nevaluated in {time.perf_counter() - t0:.1f} s")
        _SESSION["evaluated"] = result
    return _SESSION["evaluated"]


def test_stopping_rule_stops_after_patience_draws_without_growth():
    rule = StoppingRule(patience=300, max_draws=20000)
    assert rule.feed(np.arange(100.0)) == 100 and not rule.stopped  # still growing
    used = rule.feed(np.full(1000, 5.0))
    assert used == 300 and rule.stopped and not rule.capped and rule.draws == 400 and rule.best == 99.0
    capped = StoppingRule(patience=300, max_draws=250)
    assert capped.feed(np.arange(1000.0)) == 250 and capped.stopped and capped.capped


def test_prototype_parameter_counts_are_the_papers():
    """The width rule (first hidden layer at the input's width) reproduces the paper's counts exactly."""
    from persival.surrogate.networks import PaperNet, count_parameters, mlp

    counts = {s: dense_parameters([5, *prototype_widths(s, 5, 2809), 2809]) for s in SHAPES}
    assert counts["T-shaped"] == 17_154
    assert counts["rectangular"] == 71_056_494
    assert counts["triangular"] == 26_103_046
    assert 3 * counts["exponential"] == count_parameters(PaperNet(2809)) == 25_326_738  # SPEC 6: 25.3 M
    for shape in SHAPES:  # the closed form counts what torch builds
        widths = prototype_widths(shape, 5, 60, n_mid=20)
        assert dense_parameters([5, *widths, 60]) == count_parameters(mlp([5, *widths, 60], "silu"))


def test_every_table_is_written_as_markdown_and_json(evaluated, tiny_run):
    folder = tiny_run / "evaluate"
    assert evaluated["skipped"] == {}
    for name in (*TABLES, "bench_nn"):
        table = json.loads((folder / f"{name}.json").read_text())
        md = (folder / f"{name}.md").read_text()
        assert table["rows"] and table["title"] in md and table["provenance"]["command"]
        assert "| paper |" in md, f"{name}: the paper's figures are not beside ours"
    summary = json.loads((folder / "evaluation.json").read_text())
    assert summary["provenance"]["machine"]["cpu_count"] >= 1 and "torch" in summary["provenance"]["versions"]


def test_accuracy_tables_compare_the_papers_scopes(evaluated, tiny_run):
    tables = evaluated["tables"]
    expected = [("paper", "biceps"), ("pod", "all"), ("pod", "biceps")]
    for name in ("in_training", "random_activations", "random_angles"):
        assert [(r["network"], r["scope"]) for r in tables[name]["rows"]] == expected, name
    n_data = json.loads((tiny_run / "data" / "training_data.json").read_text())["config"]["n_samples"]
    assert all(r["states"] == n_data for r in tables["in_training"]["rows"])
    for name in ("random_activations", "random_angles"):
        for r in tables[name]["rows"]:
            assert 300 < r["draws"] < 20000 and not r["capped"], (name, r)
            assert r["max MaxAE_mm"] >= r["mean MaxAE_mm"] >= r["mean MAE_mm"] > 0
    assert "analytic stand-in" in tables["random_activations"]["description"]


def test_the_sg_against_itself_has_zero_error_and_stops_at_once(tiny_run):
    from persival.evaluate.run_layout import load_run

    run = load_run(tiny_run)
    run.networks = {"sg": run.sg}  # the SG "as a network": every draw has MaxAE 0
    draws = draw_until_stable(run, lambda rng, n: rng.uniform(0, 1, (n, 5)), patience=300, batch=64)
    for result in draws.values():
        assert result["draws"] == 301  # the first draw sets the record, 300 more do not beat it
        assert np.abs(result["errors"]["MaxAE_mm"]).max() < 1e-9


def test_error_propagation_labels_the_source_and_the_sg_interpolates(evaluated):
    table = evaluated["tables"]["error_propagation"]
    rows = {(r["surrogate"], r["scope"], r["tested_on"]): r for r in table["rows"]}
    assert rows[("SG", "all", "243 SG support points")]["max MaxAE_mm"] < 1e-6
    assert rows[("SG", "all", "10 held-out states")]["max MaxAE_mm"] > 0
    assert rows[("pod NN", "all", "10 held-out states")]["added_pct"] is not None
    assert table["truth_source"]["simulator"] == "analytic" and "FE" not in table["description"]


def test_prototypes_table(evaluated):
    rows = evaluated["tables"]["prototypes"]["rows"]
    assert [r["shape"] for r in rows] == list(SHAPES)
    for r in rows:
        widths = [int(w) for w in r["widths"].split()]
        assert r["parameters"] == dense_parameters([5, *widths, 447]) and r["mae_mm"] > 0 and r["epochs"] == 10
    assert rows[1]["parameters_at_2809"] == 71_056_494


def test_figures(evaluated, tiny_run):
    for name in ("hotspots", "history_paper", "history_pod", "activation_model"):
        path = Path(evaluated["figures"][name])
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000, name
    maps = json.loads((tiny_run / "evaluate" / "hotspots_biceps.json").read_text())
    assert len(maps) == 3 and all(v["max_mm"] >= v["mean_mm"] > 0 for v in maps.values())


def test_bench_table_rows(evaluated, tiny_run):
    table = evaluated["bench"]
    rows = table["rows"]
    onnx = [r for r in rows if r["variant"].startswith("deployed")]
    assert len(onnx) == 3 * 2 * 2  # tiers x threads x batches
    assert {r["threads"] for r in onnx} == {1, 2} and {r["batch"] for r in rows} == {1, 64}
    assert all(r["ms_per_call"] > 0 and r["calls"] >= 40 for r in rows)
    f32 = next(r for r in onnx if r["variant"].endswith("float32"))
    assert f32["file_mb"] == pytest.approx((tiny_run / "export" / "deformation.onnx").stat().st_size / 1e6)
    assert f32["heldout_mae_mm"] > 0 and f32["accuracy_on"] == "all, 10 states"
    assert any(r["variant"].startswith("SG") for r in rows)
    assert any(r["variant"] == "paper arch 5->2809, three separate nets" for r in rows)
    assert table["targets"]["size_target_met"] is True
    assert any("--no-peer" in n for n in table["notes"])


def test_tflite_peer_or_skip():
    from persival.evaluate.tflite_peer import INSTALL_HINT, peer_available, run_in_subprocess

    if not peer_available():
        pytest.skip(INSTALL_HINT)
    result = run_in_subprocess(n_nodes=64, n_mid=16, reps=10, budget_s=0.2, batches=(1, 4))
    runtimes = {(r["runtime"].split()[0], r["threads"], r["batch"]) for r in result["rows"]}
    assert ("TFLite", 1, 1) in runtimes and ("TFLite", 2, 4) in runtimes and ("Keras", "default", 1) in runtimes
    assert result["parameters"] == 3 * dense_parameters([5, *result["widths"], 64]) and result["tflite_bytes"] > 0


def test_cli_bad_inputs_are_one_line_and_leave_nothing(tmp_path, tiny_run):
    from persival.cli import app

    runner = CliRunner()
    (tmp_path / "afile").write_text("x")
    (tmp_path / "empty").mkdir()
    cases = [(["evaluate", "--run", str(tmp_path / "nosuch")], "no such run folder"),
             (["evaluate", "--run", str(tmp_path / "empty")], "no sparse-grid surrogate"),
             (["bench", "nn", "--run", str(tmp_path / "afile")], "no such run folder"),
             (["report", "--run", str(tmp_path / "empty")], "no evaluation")]
    for args, expected in cases:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert result.stderr.strip().startswith("error: ") and len(result.stderr.strip().splitlines()) == 1
        assert expected in result.stderr, (args, result.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "empty"]
    assert list((tmp_path / "empty").iterdir()) == []
