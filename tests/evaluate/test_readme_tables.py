"""The README's and docs/benchmarks.md's result blocks come from one results.json.

(a) Rendered from the results.json of the session's small real run (tests/conftest.py, evaluated
as tests/evaluate/test_evaluate.py does), every block carries that run's numbers as the module
formats them. (b) Rewriting is idempotent and touches nothing outside the markers; `persival
report readme --check` says when a block is stale. (c) When the committed docs/results.json
exists (the lead copies a `make run`'s results/report/results.json there), README.md and
docs/benchmarks.md hold exactly its rendering.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from test_evaluate import evaluated, tiny_run  # noqa: F401  (the session's run)
from test_report_summary import _run as hand_made_run
from typer.testing import CliRunner

from persival.evaluate import readme_blocks as rt
from persival.evaluate.results_text import format_mb, format_mm, format_ms

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = ROOT / "docs" / "results.json"
DOCUMENTS = [ROOT / name for name in rt.DEFAULT_FILES]


def _held_out(results: dict, surrogate: str, scope: str = "all") -> dict:
    return next(r for r in results["tables"]["error_propagation"]["rows"]
                if r["surrogate"] == surrogate and r["scope"] == scope and "held-out" in r["tested_on"])


def _bench(results: dict, variant: str, threads: int = 1, batch: int = 1) -> dict:
    return next(r for r in results["tables"]["bench_nn"]["rows"]
                if r["variant"] == variant and r["threads"] == threads and r["batch"] == batch)


def _outside(text: str) -> str:
    """The text with every block's contents cut out: what a rewrite must leave alone."""
    return re.sub(r"(<!-- results:([a-z0-9-]+) -->\n).*?(<!-- /results:\2 -->)", r"\1\3", text, flags=re.DOTALL)


@pytest.fixture(scope="module")
def small_results(evaluated, tiny_run) -> dict:  # noqa: F811
    from persival.evaluate.report import write_report

    write_report(tiny_run)
    return rt.load_results(tiny_run / "report" / "results.json")


@pytest.fixture
def hand_made_results(tmp_path) -> Path:
    """A real results.json of `persival report` on hand-made tables (no pipeline: seconds)."""
    from persival.evaluate.report import write_report

    out = hand_made_run(tmp_path)
    write_report(out)
    return out / "report" / "results.json"


@pytest.mark.slow
def test_the_blocks_carry_the_small_run_s_numbers(small_results):
    results = small_results
    accuracy = rt.render("accuracy", results)
    held, sg, paper = results["summary"]["held_out"], _held_out(results, "SG"), _held_out(results, "paper NN", "biceps")
    # the small run's export states no held-out measurement: the deployed row is the network's table row
    assert "**POD network (deployed, before export)**" in accuracy
    for value in (held["max_ae_mm"], held["mae_mm"], held["max_angle_error_deg"]):
        assert f"**{format_mm(value)} " in accuracy
    for value in (sg["max MaxAE_mm"], sg["mean MAE_mm"], sg["max angle_error_deg"], paper["max MaxAE_mm"]):
        assert f"{format_mm(value)} " in accuracy
    assert "17.79 / 18.28 mm" in accuracy and "25 random held-out analytic states" not in accuracy  # 10 states here
    assert f"{held['states']} random held-out analytic states" in accuracy

    f32 = _bench(results, "deployed pod ONNX float32")
    for name in ("speed", "bench-speed"):
        block = rt.render(name, results)
        assert format_ms(f32["ms_per_state"]) in block and format_mb(f32["file_mb"]) in block, name
    sg_speed = _bench(results, "SG level 1 (243 points, whole surface)")
    assert f"{format_ms(sg_speed['ms_per_state'])} ms" in rt.render("speed", results)
    assert f"{format_ms(_bench(results, 'deployed pod ONNX int8', 2, 64)['ms_per_state'])} ms" in rt.render(
        "bench-speed", results)

    pod = next(r for r in results["tables"]["random_activations"]["rows"] if r["network"] == "pod" and r["scope"] == "all")
    text = " ".join(rt.render("out-of-training", results).split())
    assert f"{format_mm(pod['max MaxAE_mm'])} / {format_mm(pod['mean MAE_mm'])} mm at random activations" in text
    assert "(the paper: 11.96 / 2.15 and 3.75 / 0.97 mm)" in text
    bench = " ".join(rt.render("bench-accuracy", results).split())
    assert f"{format_mm(sg['max MaxAE_mm'])} / {format_mm(paper['max MaxAE_mm'])} mm" in bench
    # no stage records in the fixture's run (it is not a `persival run`): the run block keeps its text
    assert rt.render("run", results) is None


def test_the_run_block_reads_the_stage_records(hand_made_results):
    results = json.loads(hand_made_results.read_text())
    results["tables"]["error_propagation"]["truth_source"]["simulator"] = "arm"
    muscles = {"biceps": {"tet10": 2000, "surface_nodes": 2478}, "triceps": {"tet10": 1529, "surface_nodes": 3000}}
    results["stages"] = {
        "model": {"wall_time_s": 9.0, "summary": {"profile": "quick", "muscles": muscles}},
        "tables": {"wall_time_s": 492.0, "summary": {"levels": [0, 0.5, 1], "angles_deg": [0, 80, 160]}},
        "fe": {"wall_time_s": 13.0, "summary": {"states": {"hanging": {"elbow_angle_deg": 32.2151},
                                                           "flexors_full": {"elbow_angle_deg": 151.43}}}},
        "campaign": {"wall_time_s": 138.0}, "train": {"wall_time_s": 90.0},
        "run": {"wall_time_s": 1.0e6},  # an earlier run's record: not this run's stages
    }
    text = " ".join(rt.render("run", results).split())
    assert "on our FE arm" in text and "(quick profile: 3529 tet10, 2 muscles with 5478 surface nodes, biceps 2478)" in text
    assert "12.4 min in its stages, 8.2 min of it the response tables (6 columns of 3 angles, once per model)" in text
    assert "the campaign 2.3 min, training 1.5 min. Hanging arm 32.22 deg, flexors 1 151.43 deg." in text
    assert results["provenance"]["date"][:10] in text and f"{results['provenance']['machine']['cpu_count']} CPUs" in text


def test_a_rewrite_touches_only_the_blocks_and_is_idempotent(hand_made_results, tmp_path):
    results = rt.load_results(hand_made_results)
    doc = tmp_path / "doc.md"
    doc.write_text("# Results\n\nProse before, `<!-- results:... -->` in code.\n\n<!-- results:accuracy -->\n"
                   "| an old | table |\n<!-- /results:accuracy -->\n\nbetween\n\n<!-- results:speed -->\n"
                   "<!-- /results:speed -->\n<!-- results:out-of-training -->\nwritten by hand, kept\n"
                   "<!-- /results:out-of-training -->\nafter\n")
    before = doc.read_text()
    status = rt.rewrite_file(doc, results)
    # the hand-made run has no out-of-training tables: that block keeps its text
    assert status == {"accuracy": "changed", "speed": "changed", "out-of-training": "no numbers"}
    once = doc.read_text()
    assert _outside(once) == _outside(before) and "written by hand, kept" in once
    assert f"**{format_mm(30.1)} mm**" in once and f"{format_ms(0.037)} ms" in once
    assert rt.rewrite_file(doc, results) == {"accuracy": "unchanged", "speed": "unchanged", "out-of-training": "no numbers"}
    assert doc.read_text() == once


def test_the_command_rewrites_and_checks(hand_made_results, tmp_path):
    from persival.cli import app

    doc = tmp_path / "doc.md"
    doc.write_text("<!-- results:bench-speed -->\nstale\n<!-- /results:bench-speed -->\n")
    args = ["report", "readme", "--results", str(hand_made_results), "--file", str(doc)]
    runner = CliRunner()
    result = runner.invoke(app, [*args, "--check"])
    assert result.exit_code == 1 and f"{doc}: results:bench-speed differs" in result.output
    assert "stale" in doc.read_text()  # --check writes nothing
    result = runner.invoke(app, args)
    assert result.exit_code == 0 and f"{doc}: results:bench-speed changed" in result.output
    result = runner.invoke(app, [*args, "--check"])
    assert result.exit_code == 0 and f"{doc}: results:bench-speed unchanged" in result.output


@pytest.mark.parametrize("text, message", [
    ("<!-- results:speed -->\nno end\n", "without its closing marker: speed"),
    ("<!-- results:nosuch -->\n<!-- /results:nosuch -->\n", "unknown result block 'nosuch'"),
    ("no block at all\n", "no result block"),
])
def test_malformed_blocks_are_refused(hand_made_results, tmp_path, text, message):
    doc = tmp_path / "doc.md"
    doc.write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)):
        rt.rewrite_file(doc, rt.load_results(hand_made_results))
    assert doc.read_text() == text


def test_every_block_of_the_docs_has_a_renderer():
    for path in DOCUMENTS:
        names = re.findall(r"<!-- results:([a-z0-9-]+) -->", path.read_text())
        assert names and set(names) <= set(rt.BLOCKS), path


@pytest.mark.skipif(not COMMITTED.is_file(), reason="docs/results.json is not committed yet: copy a `make run`'s "
                    "results/report/results.json there, then `persival report readme --results docs/results.json`")
def test_the_docs_hold_the_rendering_of_the_committed_results():
    results = rt.load_results(COMMITTED)
    for path in DOCUMENTS:
        text = path.read_text()
        new, status = rt.rewrite(text, results)
        stale = [name for name, what in status.items() if what == "changed"]
        assert new == text, (f"{path.relative_to(ROOT)}: blocks {stale} differ from docs/results.json; run "
                             "`persival report readme --results docs/results.json`")
