"""`persival run`: the end-to-end job. Its wiring lives here, above every stage, because it
drives all of them (persival.pipeline); no stage's commands.py imports the pipeline."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli_errors import check_output_dir, user_errors
from persival.model.defaults import profiles_help


def register(app: typer.Typer) -> None:
    @app.command()
    def run(
        out: Path = typer.Option(Path("results"), "--out", help="Results directory."),
        profile: str = typer.Option(
            "quick", "--profile", help=profiles_help("Mesh profile of the built-in arm", model_option=False)),
    ) -> None:
        """End to end over the stages that exist: model -> FE -> campaign -> surrogate -> evaluate."""
        from persival.model.arm_file import load_model_file
        from persival.pipeline import run as run_pipeline

        with user_errors():  # before anything is written
            load_model_file()[0].profile(profile)
            check_output_dir(out)
        # A user error half-way (e.g. a bad store) removes an output folder this run created;
        # an internal error keeps what was written, for --debug.
        with user_errors(out=out):
            run_pipeline(out, profile)
