"""CLI of the model stage: ``persival model init`` (the built-in model file, to edit) and
``persival mesh`` (a model's muscles meshed, with fibres and a repair report, for inspection)."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli_errors import check_output_file, user_errors
from persival.cli_help import FullHelpGroup


def register(app: typer.Typer) -> None:
    """Attach ``model init`` and ``mesh`` to the main app."""
    model_app = typer.Typer(cls=FullHelpGroup, help="The model file: write the built-in one for editing.",
                            no_args_is_help=True)
    app.add_typer(model_app, name="model")

    @model_app.command("init")
    def init(
        out: Path = typer.Option(Path("my_arm.toml"), "--out", help="Model file to write (TOML); an existing file is "
                                 "never overwritten."),
    ) -> None:
        """Write the built-in model file (bones, joint, five muscles, mesh profiles) for editing."""
        from rich.console import Console

        from persival.model.defaults import default_model_path

        with user_errors():
            check_output_file(out)
            if out.exists():
                raise FileExistsError(f"--out {out} exists; pick a new name (it is never overwritten)")
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(default_model_path().read_text())
        Console().print(f"wrote {out}: the built-in model. Use it with --model {out} (persival simulate, tables, mesh); "
                        "a muscle can take its shape from a surface file (docs/own_anatomy.md).")
