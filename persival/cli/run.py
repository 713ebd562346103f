"""`persival run`: the end-to-end job. Its wiring lives here, above every stage, because it
drives all of them (persival.pipeline); no stage's commands.py imports the pipeline."""

from __future__ import annotations

import shutil
from pathlib import Path

import typer

from persival.cli.errors import check_output_dir, fail, user_errors
from persival.model.arm.defaults import profiles_help, resolve_model_path


def register(app: typer.Typer) -> None:
    @app.command()
    def run(
        out: Path = typer.Option(Path("results"), "--out", help="Results directory (resumed stage by stage)."),
        model: Path | None = typer.Option(None, "--model", help="Model file (TOML; `persival model init` writes one to "
                                          "edit) or a packaged model's name; default: $PERSIVAL_MODEL, else the built-in arm."),
        profile: str = typer.Option(
            "quick", "--profile", help=profiles_help()),
        simulator: str = typer.Option(
            "arm", "--simulator", help="Campaign simulator: arm (the FE arm, from its response tables, built once "
            "per model) or analytic (closed-form stand-in for tests, seconds)."),
        level: int = typer.Option(1, "--level", min=1, max=3, help="Sparse-grid level of the campaign (1: 243, 2: 1053)."),
        campaign_store: Path = typer.Option(None, "--campaign-store", help="Reuse a finished sparse-grid campaign store."),
        held_out_store: Path = typer.Option(None, "--held-out-store", help="Reuse a finished held-out campaign store."),
        moment_table: Path = typer.Option(None, "--moment-table", help="FE moment table of the same arm (default: "
                                          "the tables stage's; needed with --simulator analytic for the motion model)."),
        held_out: int = typer.Option(25, "--held-out", min=1, help="Random held-out states of the campaign's simulator."),
        samples: int = typer.Option(4000, "--samples", min=10, help="SG training states for the networks."),
        pod_epochs: int = typer.Option(100, "--pod-epochs", min=1, help="POD network: epochs per fold (5 folds)."),
        paper_epochs: int = typer.Option(8, "--paper-epochs", min=1, help="Paper network: epochs (1 fold; the paper: 5 x 400)."),
        fe_states: bool = typer.Option(True, "--fe-states/--no-fe-states", help="Solve the three showcase FE states."),
        state_timeout: float = typer.Option(
            900.0, "--state-timeout", min=0.0, help="Seconds per campaign state before it is recorded as failed "
            "(0: no limit). A run with failed sparse-grid states stops after the campaign and resumes from it."),
    ) -> None:
        """End to end: model -> FE -> campaign -> anatomy -> SG -> inverse -> data -> train -> export -> evaluate -> report."""
        from rich.console import Console

        from persival.campaign.runner import CampaignIncomplete
        from persival.model.arm.body import ArmBody
        from persival.pipeline import RunConfig
        from persival.pipeline import run as run_pipeline

        with user_errors():  # before anything is written
            frame = ArmBody.frame(model, profile)  # the model file, its profile and its own surfaces
            check_output_dir(out)
            if simulator not in ("analytic", "arm"):
                raise ValueError(f"--simulator must be analytic or arm, got {simulator!r}")
            if moment_table is not None and not moment_table.exists():
                raise FileNotFoundError(f"--moment-table {moment_table}: no such file")
            for given in (campaign_store, held_out_store):
                if given is not None and not (given / "zarr.json").is_file():
                    raise FileNotFoundError(f"{given}: not a campaign store (no zarr.json)")
            if model is not None and simulator != "arm":
                raise ValueError("--model needs --simulator arm (the analytic stand-in has no model file)")
            config = RunConfig(profile=profile, simulator=simulator,
                               model=None if model is None else str(resolve_model_path(model).resolve()),
                               model_hash=frame.model_hash, level=level, held_out=held_out,
                               campaign_store=None if campaign_store is None else str(campaign_store.resolve()),
                               held_out_store=None if held_out_store is None else str(held_out_store.resolve()),
                               moment_table=None if moment_table is None else str(moment_table.resolve()),
                               samples=samples, pod_epochs=pod_epochs, paper_epochs=paper_epochs, fe_states=fe_states,
                               state_timeout_s=state_timeout or None)
        # A user error before any stage finished removes an output folder this run created; after
        # one, what finished stays, as after an internal error (for --debug) or a stage that could
        # not finish: the next run resumes from it.
        created = not out.exists()
        try:
            with user_errors():
                run_pipeline(out, config, Console())  # rich: rules, markup and live bars on a terminal
        except CampaignIncomplete as exc:
            fail(str(exc))
        except typer.Exit as exc:
            if exc.exit_code and created and not any(out.glob("*/stage.json")):
                shutil.rmtree(out, ignore_errors=True)
            raise
