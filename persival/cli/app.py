"""The `persival` command line: one subcommand per pipeline stage, plus `run` (end to end).

Each pipeline stage has its module of commands here (persival.cli.model, .tables, ...); this file
only wires them together. The command line is a thin layer over the Python API: no library module
imports typer. Errors take one path (persival.cli.errors).
"""

from __future__ import annotations

import typer

from persival.cli.errors import ErrorReportingGroup
from persival.cli.help import FullHelpGroup

app = typer.Typer(
    cls=ErrorReportingGroup,
    help="PerSival: FE upper-limb model -> sparse-grid / neural surrogates -> real-time deployment.",
    no_args_is_help=True,
    pretty_exceptions_show_locals=False,
    rich_markup_mode=None,  # plain help, wrapped, never cut (persival.cli.help)
)
bench_app = typer.Typer(cls=FullHelpGroup, help="Speed benchmarks (print tables).", no_args_is_help=True)
app.add_typer(bench_app, name="bench")


@app.callback()
def main(
    debug: bool = typer.Option(False, "--debug", help="Show the traceback of an internal error (a bug) instead of one line."),
) -> None:
    """PerSival: FE upper-limb model -> sparse-grid / neural surrogates -> real-time deployment."""
    # ErrorReportingGroup reads --debug from the context; nothing to do here.


def _register() -> None:
    from persival.cli import progress

    progress.install()  # the library's long calls draw rich bars on a terminal
    # Imported here so that `persival --help` stays fast and each stage stays independent.
    from persival.cli import bench as bench_commands
    from persival.cli import campaign as campaign_commands
    from persival.cli import deploy as deploy_commands
    from persival.cli import evaluate as evaluate_commands
    from persival.cli import inspect as inspect_commands
    from persival.cli import model as model_commands
    from persival.cli import motion as motion_commands
    from persival.cli import run as run_command
    from persival.cli import surrogate as surrogate_commands
    from persival.cli import tables as tables_commands

    run_command.register(app)
    model_commands.register(app)
    campaign_commands.register(app)
    tables_commands.register(app)
    surrogate_commands.register(app)
    motion_commands.register(app)
    evaluate_commands.register(app)
    inspect_commands.register(app)
    deploy_commands.register(app)
    bench_commands.register(bench_app)


_register()

if __name__ == "__main__":  # pragma: no cover
    app()
