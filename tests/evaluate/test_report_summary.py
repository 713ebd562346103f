"""The report leads with the answer: the deployed model against the held-out states, its batch-1
time and file size against the paper, the arm picture and a viewer screenshot; the provenance as
a table with the git commit; results.json's `stages` from the run's stage records; per-panel
colour scales in the hot-spot figure. A hand-made run folder (tables as the evaluation writes
them), so no pipeline runs here."""

from __future__ import annotations

import json

import numpy as np
import pytest

from persival.evaluate import paper_values
from persival.evaluate.tables import make_table, save_table


def _png(path, colour):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.fill_between([0, 1], 0, 1, color=colour)
    fig.savefig(path, dpi=60)
    plt.close(fig)


def _run(tmp_path, deployed=None):
    out = tmp_path / "run"
    rows = [{"surrogate": "SG", "scope": "all", "tested_on": "25 held-out states", "states": 25,
             "max MaxAE_mm": 31.3, "mean MAE_mm": 3.55, "max angle_error_deg": 19.8},
            {"surrogate": "pod NN", "scope": "all", "tested_on": "25 held-out states", "states": 25,
             "max MaxAE_mm": 30.1, "mean MAE_mm": 3.60, "max angle_error_deg": 17.7},
            {"surrogate": "pod NN", "scope": "all", "tested_on": "243 SG support points", "states": 243,
             "max MaxAE_mm": 9.0, "mean MAE_mm": 1.0, "max angle_error_deg": 2.0}]
    cols = [(k, k, "{}") for k in ("surrogate", "scope", "tested_on", "max MaxAE_mm", "mean MAE_mm")]
    save_table(make_table("error_propagation", "Error propagation", "d", cols, rows, paper_values.ERROR_PROPAGATION,
                          truth_source={"label": "FE arm (quick profile), 25 states"}), out / "evaluate")
    bench_rows = [{"variant": "paper arch 5->2809, combined", "runtime": "PyTorch eager", "batch": 1, "threads": 1,
                   "ms_per_state": 17.0, "file_mb": 101.3, "parameters": 25_326_738},
                  {"variant": "deployed pod ONNX float32", "runtime": "onnxruntime", "batch": 1, "threads": 1,
                   "ms_per_state": 0.037, "file_mb": 0.299}]
    save_table(make_table("bench_nn", "Evaluation times", "d", [("variant", "variant", "{}")], bench_rows,
                          paper_values.SPEED, targets={"deployed_best": {"variant": "deployed pod ONNX float32",
                                                                         "threads": 1, "ms_per_state": 0.037}}),
               out / "evaluate")
    provenance = {"deployed": deployed} if deployed else {}
    meta = {"n_nodes": 7123, "provenance": provenance,
            "models": {"deformation": {"architecture": "pod", "variants": {"float32": {"file": "d.onnx", "bytes": 299_000}}}}}
    (out / "export").mkdir(parents=True)
    (out / "export" / "metadata.json").write_text(json.dumps(meta))
    _png(out / "fe" / "arm.png", "tab:blue")
    _png(out / "evaluate" / "viewer.png", "tab:green")
    for k, stage in enumerate(("model", "fe", "campaign")):
        (out / stage).mkdir(exist_ok=True)
        (out / stage / "stage.json").write_text(json.dumps({"stage": stage, "digest": f"d{k}", "wall_time_s": 10.0 * k,
                                                            "summary": {"k": k}}))
    return out


def test_summary_leads_the_report(tmp_path):
    from persival.evaluate.report import write_report

    out = _run(tmp_path)
    page = write_report(out).read_text()
    results = json.loads((out / "report" / "results.json").read_text())
    summary = results["summary"]
    # the deployed network's row against the held-out states (not the support points, not the SG)
    assert summary["deployed_model"] == "pod" and summary["nodes"] == 7123
    assert summary["held_out"] == {"states": 25, "max_ae_mm": 30.1, "mae_mm": 3.60, "max_angle_error_deg": 17.7,
                                   "truth": "FE arm (quick profile), 25 states", "from": "error_propagation table"}
    assert summary["paper_held_out"]["max_ae_mm"] == 18.28
    assert summary["speed"]["batch1_ms"] == 0.037 and summary["speed"]["paper_tflite_ms"] == 9.88
    assert summary["size"]["float32_mb"] == pytest.approx(0.299) and summary["size"]["paper_architecture_mb"] == 101.3
    assert summary["pictures"] == {"arm": "fe/arm.png", "viewer": "evaluate/viewer.png"}
    # on the page: the summary before the first table, with both pictures embedded
    assert page.index('id="summary"') < page.index('id="table-')
    head = page[page.index('id="summary"'):page.index("</section>", page.index('id="summary"'))]
    assert "30.10 mm" in head and "17.70 deg" in head and "0.037 ms" in head and "9.88 ms" in head
    assert head.count('src="data:image/png;base64,') == 2
    # stages from the run's stage records; provenance as a table with the git commit
    assert set(results["stages"]) == {"model", "fe", "campaign"} and results["stages"]["fe"]["summary"] == {"k": 1}
    git = results["provenance"]["git"]
    assert git["commit"] is None or len(git["commit"]) == 40
    assert "<td>git commit</td>" in page and "<td>numpy</td>" in page
    if git["commit"]:
        assert f"<td>{git['commit']}</td>" in page


def test_the_export_s_own_statement_of_the_deployed_model_wins(tmp_path):
    from persival.evaluate.report_summary import headline
    from persival.evaluate.tables import load_table

    deployed = {"model": "structured (shape + moment)", "held_out_fe": {"states": 25, "max_ae_mm": 4.2, "mae_mm": 0.8,
                                                                        "max_angle_error_deg": 0.6}}
    out = _run(tmp_path, deployed)
    tables = {p.stem: load_table(p) for p in (out / "evaluate").glob("*.json")}
    summary = headline(out, tables)
    assert summary["deployed_model"] == "structured (shape + moment)"
    assert summary["held_out"]["max_ae_mm"] == 4.2 and summary["held_out"]["from"] == "export/metadata.json"


def test_hotspot_panels_have_their_own_colour_scales(monkeypatch, tmp_path):
    from persival.evaluate import evaluate_figures

    figures = []
    monkeypatch.setattr(evaluate_figures, "save_figure", lambda fig, path: figures.append(fig))
    rng = np.random.default_rng(0)
    points = rng.normal(size=(30, 3))
    triangles = np.array([[i, i + 1, i + 2] for i in range(28)])
    maps = {"short training": 40 * rng.uniform(size=30), "full training": 3 * rng.uniform(size=30),
            "pod": 0.3 * rng.uniform(size=30)}
    evaluate_figures._matplotlib_panels(points, triangles, maps, tmp_path / "h.png")
    limits = [ax.collections[0].get_clim() for ax in figures[0].axes if ax.name == "3d"]
    assert [hi for _, hi in limits] == pytest.approx([float(v.max()) for v in maps.values()])


@pytest.mark.parametrize("error, why", [(RuntimeError("no EGL or OSMesa render window"), "could not render it"),
                                        (ImportError("No module named 'pyvista'"), "is not installed")])
def test_hotspot_rendering_errors_are_reported_not_dropped(monkeypatch, tmp_path, error, why):
    from persival.evaluate import evaluate_figures

    def fail(*args):
        raise error

    drawn = []
    monkeypatch.setattr(evaluate_figures, "_pyvista_panels", fail)
    monkeypatch.setattr(evaluate_figures, "_matplotlib_panels", lambda *args: drawn.append(args[-1]))
    skipped = {}
    with pytest.warns(RuntimeWarning, match=f"hot-spot figure h.png: pyvista {why}.*{error}.*matplotlib instead"):
        path = evaluate_figures.plot_hotspots(np.zeros((3, 3)), np.array([[0, 1, 2]]), {"net": np.zeros(3)},
                                              tmp_path / "h.png", skipped)
    assert drawn == [path]
    assert str(error) in skipped["hotspots_pyvista"] and "matplotlib" in skipped["hotspots_pyvista"]
