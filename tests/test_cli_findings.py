"""What a new user met on the command line: accuracy of an all-muscle SG, the TFLite install hint,
the speed table at 80 columns, and training logs that count epochs per fold."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from rich.console import Console
from typer.testing import CliRunner

from persival.cli.show import to_rich
from persival.evaluate import paper_values
from persival.evaluate.bench_nn import BENCH_COLUMNS, TERMINAL_COLUMNS
from persival.evaluate.tables import make_table


@pytest.mark.slow
def test_accuracy_of_an_all_muscle_sg(tmp_path):
    """`persival accuracy --surrogate sg=...` on the SG of all five muscles (the run's `sg/`)."""
    from persival.campaign.design import Design
    from persival.campaign.runner import INLINE, run_campaign
    from persival.campaign.simulator import SimulatorSpec
    from persival.cli import evaluate as commands
    from persival.surrogate.build import fit_sparse_grid

    spec = SimulatorSpec("analytic", {"mesh_size": 20.0})
    run_campaign(tmp_path / "l1.zarr", Design.sparse_grid(1), spec, scheduler=INLINE, progress=False)
    run_campaign(tmp_path / "held_out.zarr", Design.random(6, seed=3), spec, scheduler=INLINE, progress=False)
    sg = fit_sparse_grid(tmp_path / "l1.zarr", tmp_path / "sg")  # every muscle of the campaign
    assert len(sg.surfaces.names) == 5

    app, bench = typer.Typer(), typer.Typer()
    app.add_typer(bench, name="bench")
    commands.register(app)
    res = CliRunner().invoke(app, ["accuracy", "--test", str(tmp_path / "held_out.zarr"),
                                   "--surrogate", f"sg={tmp_path / 'sg'}", "--out", str(tmp_path / "acc")])
    assert res.exit_code == 0, res.output
    row = json.loads((tmp_path / "acc" / "accuracy.json").read_text())["surrogates"]["sg"]
    # a level-1 grid of a smooth analytic response: errors of millimetres, not zero, not huge
    assert 0 < row["mean MAE_mm"] < row["max MaxAE_mm"] < 50
    assert row["states"] == 243


def test_the_tflite_hint_prints_the_extra_literally(monkeypatch):
    from persival.evaluate import bench_nn, tflite_peer

    monkeypatch.setattr(tflite_peer, "peer_available", lambda: False)
    console = Console(record=True, width=200)
    rows, info = bench_nn._peer_rows("relu", 10, 0.1, lambda text: console.print(text, markup=False))
    assert rows == [] and not info["installed"]
    assert "pip install -e '.[peer]'" in console.export_text(clear=False)
    # a cell of a table printed with rich is text, not markup
    table = make_table("t", "t", "d", [("what", "what", "{}")], [{"what": "pip install -e '.[peer]'"}])
    console.print(to_rich(table))
    assert console.export_text().count("'.[peer]'") == 2


def test_bench_nn_table_is_readable_at_80_columns():
    rows = []
    for variant, runtime, ms in [("paper arch 5->2809 (SPEC 6 widths), three separate nets", "PyTorch 2.9.1 eager", 17.52),
                                 ("deployed pod ONNX float32", "onnxruntime 1.22.0", 0.0374),
                                 ("SG level 1 (243 points, whole surface)", "numpy 2.3.4 float32", 0.4211)]:
        for batch in (1, 64):
            rows.append({"variant": variant, "runtime": runtime, "threads": 1, "batch": batch, "ms_per_call": ms * batch,
                         "ms_per_state": ms, "calls": 1000, "file_mb": 0.299, "parameters": 12345,
                         "accuracy_on": "all, 25 states", "heldout_maxae_mm": 30.123, "heldout_mae_mm": 3.601,
                         "speedup_vs_tflite": 6.03 / ms if batch == 1 else None})
    table = make_table("bench_nn", "Evaluation times (SPEC 8)", "", BENCH_COLUMNS, rows, paper_values.SPEED)
    console = Console(record=True, width=80)
    console.print(to_rich(table, TERMINAL_COLUMNS))
    text = console.export_text()
    assert max(len(line) for line in text.splitlines()) <= 80
    # every number whole on one line (not folded into pieces), the paper's rows included
    for number in ["17.5200", "0.0374", "0.4211", "30.123", "3.601", "161.2", "13.6500", "9.8800"]:
        assert number in text, number
    # the variant and its runtime read as words, at most a few lines per row
    assert "onnxruntime 1.22.0" in text and "deployed pod ONNX" in text
    assert len(text.splitlines()) < 6 * (len(rows) + len(paper_values.SPEED))


def test_training_logs_count_epochs_per_fold(tmp_path):
    from persival.pipeline.stages import _train_progress
    from persival.surrogate.dataset import Dataset, Surfaces
    from persival.surrogate.training import TrainingConfig, train

    rng = np.random.default_rng(0)
    n, nodes = 40, 6
    surfaces = Surfaces(("biceps",), (nodes,), rng.normal(size=(nodes, 3)), np.array([[0, 1, 2], [3, 4, 5]]), (2,))
    alpha = rng.uniform(0, 1, (n, 5))
    positions = surfaces.reference_points + alpha[:, :1, None] * np.ones((n, nodes, 3))
    data = Dataset(alpha, positions, 30 + 90 * alpha[:, 0], surfaces)
    seen = []
    train(data, TrainingConfig(arch="pod", folds=2, epochs=3, rank=2), tmp_path / "net",
          lambda done, total, loss, mae, where: seen.append((done, total, where)))
    assert [w for _, _, w in seen] == [f"fold {f}/2 epoch {e}/3" for f in (1, 2) for e in (1, 2, 3)]
    assert [(d, t) for d, t, _ in seen] == [(k, 6) for k in range(1, 7)]  # the bar still counts all epochs
    console = Console(record=True, width=200)
    report = _train_progress(console, "pod net")
    report(6, 6, 0.01, [0.1, 0.2, 0.3], "fold 2/2 epoch 3/3")
    assert "pod net: fold 2/2 epoch 3/3, val. loss 0.01" in console.export_text()


def test_model_list_shows_whole_file_names_at_80_columns():
    from persival.cli.app import app
    from persival.model.arm.defaults import packaged_models

    res = CliRunner().invoke(app, ["model", "list"], env={"COLUMNS": "80"}, terminal_width=80)
    assert res.exit_code == 0, res.output
    assert max(len(line) for line in res.output.splitlines()) <= 80
    files = "".join(line.split("│")[3].strip() for line in res.output.splitlines() if line.count("│") == 4)
    folder = packaged_models()["default"].parent
    for path in packaged_models().values():
        assert str(path.relative_to(folder)) in files  # folded over lines, never cut
    assert f"files in {folder}" in res.output


def test_a_bad_option_value_is_one_line():
    from persival.cli.app import app

    res = CliRunner().invoke(app, ["motion", "play", "--load", "-1", "x.csv"], prog_name="persival")
    assert res.exit_code == 2
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: persival motion play: Invalid value for '--load'"), res.output
