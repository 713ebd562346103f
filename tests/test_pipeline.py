"""`persival run` end to end on a tiny analytic configuration: every stage leaves its artifact and
its stage.json, a second run skips them all, and a changed setting reruns only what depends on it."""

import json

import pytest

from persival.pipeline import STAGES, RunConfig, run


@pytest.mark.slow
def test_run_end_to_end_resumes_stage_by_stage(tmp_path):
    from rich.console import Console

    config = RunConfig(simulator="analytic", held_out=4,
                       samples=300, pod_folds=1, pod_epochs=3, paper_epochs=1, fe_states=False, bench=False)
    console = Console(record=True, width=120)
    first = run(tmp_path, config, console)
    names = [s[0] for s in STAGES if s[0] != "fe"]
    assert list(first) == names
    assert (tmp_path / "export" / "metadata.json").exists() and (tmp_path / "report" / "index.html").exists()
    assert json.loads((tmp_path / "motion" / "stage.json").read_text())["summary"]["skipped"]
    meta = json.loads((tmp_path / "export" / "metadata.json").read_text())
    assert meta["provenance"]["source"]["simulator"] == "analytic"
    log = console.export_text()
    assert f"1/{len(names)} model" in log and f"{len(names)}/{len(names)} report" in log

    console = Console(record=True, width=120)
    run(tmp_path, config, console)
    assert console.export_text().count("(unchanged, skipped)") == len(names)

    console = Console(record=True, width=120)
    run(tmp_path, RunConfig(**{**config.__dict__, "pod_epochs": 4}), console)
    log = console.export_text()
    for name in ("model", "campaign", "sg", "inverse", "data"):
        assert "(unchanged, skipped)" in log.split(f" {name}: ")[1].split("\n")[0], name
    assert "(unchanged, skipped)" not in log.split(" train: ")[1].split("\n")[0]


def test_the_viewer_screenshot_is_skipped_with_a_note_where_there_is_no_browser(tmp_path, monkeypatch):
    """The evaluate stage's viewer picture: without Chromium the run goes on and says why."""
    from rich.console import Console

    import persival.deploy.bench_viewer as bench_viewer
    from persival.pipeline import stages

    def no_browser(*args, **kwargs):
        raise bench_viewer.ViewerBenchError("missing: Chromium at /usr/bin/chromium (apt-get install chromium)")

    monkeypatch.setattr(bench_viewer, "run_viewer_bench", no_browser)
    skipped = stages._viewer_screenshot(tmp_path, Console(quiet=True))
    assert "apt-get install chromium" in skipped["viewer screenshot"]


@pytest.mark.slow
def test_a_campaign_with_failed_states_stops_the_run_and_the_next_run_resumes_it(tmp_path, monkeypatch):
    """Failed sparse-grid states stop `persival run` after the campaign with what to do; the store is
    kept, and the next run solves only the states that failed, then goes on."""
    from rich.console import Console

    import persival.pipeline as pipeline
    from persival.campaign.analytic import AnalyticSimulator
    from persival.campaign.runner import CampaignIncomplete
    from persival.campaign.store import CampaignStore

    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES if s[0] in ("model", "tables", "campaign")])
    solved, stalls = [], {"biceps at 1": True}
    simulate = AnalyticSimulator.simulate

    def biceps_at_one_fails(self, activations, warm_start=None, attempt=0):
        if activations[0] == 1.0 and stalls["biceps at 1"]:
            raise RuntimeError("Newton stalled")
        solved.append(tuple(activations))
        return simulate(self, activations, warm_start, attempt)

    monkeypatch.setattr(AnalyticSimulator, "simulate", biceps_at_one_fails)
    config = RunConfig(simulator="analytic", held_out=4, fe_states=False, bench=False)
    with pytest.raises(CampaignIncomplete, match=r"of the sparse grid's 243 states failed \(.*Newton stalled"):
        run(tmp_path, config, Console(quiet=True))
    store_path = tmp_path / "campaign" / "campaign.zarr"
    with CampaignStore.open(store_path) as store:
        first = store.summary()
    assert first["failed"] > 0 and first["done"] + first["failed"] == 243
    assert not (tmp_path / "campaign" / "stage.json").exists()

    solved.clear()
    stalls["biceps at 1"] = False
    console = Console(record=True, width=120)
    done = run(tmp_path, config, console)
    assert "campaign: sparse-grid campaign + random held-out states (resumed)" in console.export_text()
    assert done["campaign"]["summary"]["campaign"]["done"] == 243
    assert sum(a[0] == 1.0 for a in solved) == first["failed"]  # the failed ones, nothing solved twice
    assert len(solved) == first["failed"] + 4  # and the held-out states, which the first run never reached


def test_a_user_error_half_way_keeps_the_stages_that_finished(tmp_path, monkeypatch):
    """`persival run`: a user error in the first stage leaves nothing behind; one in a later stage
    keeps the stages before it (the next run resumes from them) and is reported as a user error."""
    from typer.testing import CliRunner

    import persival.pipeline as pipeline
    from persival.cli import app
    from persival.pipeline import stages

    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES if s[0] in ("model", "tables")])

    def bad_table(out, config, console):
        raise ValueError("no table here")

    for failing, kept in (("model", False), ("tables", True)):
        monkeypatch.setattr(stages, "RUNNERS", {**stages.RUNNERS, "model": lambda out, config, console: {},
                                                failing: bad_table})
        out = tmp_path / failing
        result = CliRunner().invoke(app, ["run", "--simulator", "analytic", "--out", str(out)])
        assert result.exit_code == 2 and "no table here" in result.output
        assert out.exists() is kept
        if kept:
            assert (out / "model" / "stage.json").exists() and not (out / "tables" / "stage.json").exists()


def test_an_edited_model_file_or_a_new_physics_version_reruns_every_stage_from_the_model(tmp_path, monkeypatch):
    """Results never go stale: the digests hold the built-in model file's content hash, the
    physics version and the package version (the stages themselves are stand-ins here)."""
    from rich.console import Console

    import persival
    import persival.model.arm.defaults as defaults
    import persival.model.arm.model_file as arm_file
    from persival.pipeline import stages

    model = tmp_path / "default_arm.toml"
    model.write_text(defaults.default_model_path().read_text())
    monkeypatch.setattr(defaults, "default_model_path", lambda: model)
    ran = []
    monkeypatch.setattr(stages, "RUNNERS", {name: (lambda out, config, console, name=name: ran.append(name) or {})
                                            for name in stages.RUNNERS})
    config = RunConfig(simulator="analytic", fe_states=False)
    names = [s[0] for s in STAGES if s[0] != "fe"]

    def again() -> list[str]:
        ran.clear()
        run(tmp_path / "out", config, Console(quiet=True))
        return list(ran)

    assert again() == names
    assert again() == []
    model.write_text(model.read_text().replace("mass = 1.6", "mass = 1.7", 1))  # the forearm's geometry and load
    assert again() == names
    monkeypatch.setattr(arm_file, "PHYSICS_VERSION", arm_file.PHYSICS_VERSION + 1)
    assert again() == names
    assert again() == []
    monkeypatch.setattr(persival, "__version__", persival.__version__ + ".post1")
    assert again() == names
