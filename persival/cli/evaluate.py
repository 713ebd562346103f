"""CLI commands of the evaluation stage (benchmarks, tables, figures)."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli.errors import check_output_dir, user_errors
from persival.cli.help import FullHelpGroup


def register(app: typer.Typer) -> None:
    """Attach this stage's commands to the main app (its benchmarks: persival.cli.bench)."""
    for command in (accuracy, evaluate):
        app.command()(command)
    # `persival report --run RUN` writes the report; `persival report readme` copies its numbers into the docs
    report_app = typer.Typer(cls=FullHelpGroup, help="One self-contained HTML page of a run (every table and figure, "
                             "provenance): RUN/report/index.html; `report readme`: its numbers into README.md and "
                             "docs/benchmarks.md.")
    app.add_typer(report_app, name="report")
    report_app.callback(invoke_without_command=True)(report)
    report_app.command("readme")(readme)


def accuracy(
    test: Path = typer.Option(..., "--test", help="Campaign store of held-out states (e.g. a random design)."),
    surrogate: list[str] = typer.Option(
        ..., "--surrogate", help="LABEL=DIR of a fitted surface surrogate (fit-sg or adapt), repeatable."),
    out: Path = typer.Option(Path("results/accuracy"), "--out", help="Output directory (accuracy.json, accuracy.png)."),
) -> None:
    """Surrogates vs held-out states (FE or analytic: the report says which): MaxAE, MAE, MaxRE, MRE, angle error."""
    import json

    from rich.console import Console
    from rich.table import Table

    from persival.campaign.store import StoreError
    from persival.evaluate.surrogate_accuracy import accuracy_report, plot_accuracy

    console = Console()
    with user_errors(StoreError):
        check_output_dir(out)
        labelled = {}
        for item in surrogate:
            label, sep, path = item.partition("=")
            if not sep or not label or not path:
                raise ValueError(f"--surrogate expects LABEL=DIR, got {item!r}")
            if not (Path(path) / "surrogate.json").is_file():
                raise ValueError(f"--surrogate {item}: {path} is not a fitted surrogate (no surrogate.json; "
                                 "make one with `persival surrogate fit-sg` or `surrogate adapt`)")
            labelled[label] = Path(path)
        report = accuracy_report(labelled, test)
    table = Table(title=f"surface surrogates vs {report['test_source']['label']} held out ({test})")
    columns = [("training states", "states", "{:d}"), ("MaxAE mm", "max MaxAE_mm", "{:.3f}"),
               ("MAE mm", "mean MAE_mm", "{:.3f}"), ("MaxRE %", "max MaxRE_pct", "{:.2f}"),
               ("MRE %", "mean MRE_pct", "{:.3f}"), ("max angle err deg", "max angle_error_deg", "{:.3f}"),
               ("mean angle err deg", "mean angle_error_deg", "{:.3f}")]
    table.add_column("surrogate")
    table.add_column("grid")
    for name, _, _ in columns:
        table.add_column(name, justify="right")
    for label, row in report["surrogates"].items():
        table.add_row(label, row["kind"], *(fmt.format(row[key]) for _, key, fmt in columns))
    console.print(table)
    out.mkdir(parents=True, exist_ok=True)
    (out / "accuracy.json").write_text(json.dumps(report, indent=1))
    console.print(f"wrote {out / 'accuracy.json'} and {plot_accuracy(report, out / 'accuracy.png')}")


def evaluate(
    run: Path = typer.Option(Path("results"), "--run", help="Run folder written by `persival run --out`."),
    bench: bool = typer.Option(True, "--bench/--no-bench", help="Also the speed table (persival bench nn)."),
    peer: bool = typer.Option(True, "--peer/--no-peer", help="Time the Keras/TFLite peer if installed."),
    max_draws: int = typer.Option(20000, "--max-draws", min=300, help="Cap of the 300-draw stopping rule."),
    states: int = typer.Option(25, "--states", min=1, help="Held-out states of the error-propagation table."),
) -> None:
    """The paper's accuracy tables and figures on a run: RUN/evaluate/*.md, *.json, *.png."""
    from rich.console import Console

    from persival.campaign.store import StoreError
    from persival.cli.show import to_rich
    from persival.evaluate.evaluation import evaluate_run
    from persival.evaluate.run_layout import RunLayout

    console = Console()
    layout = RunLayout(run)
    with user_errors(StoreError, out=layout.evaluate):
        layout.check()
        check_output_dir(layout.evaluate)
        result = evaluate_run(run, progress=True, bench=bench, peer=peer, max_draws=max_draws, n_states=states,
                              console=console)
    from rich.markup import escape

    from persival.evaluate.bench_nn import TERMINAL_COLUMNS

    for name, table in result["tables"].items():
        console.print(to_rich(table, TERMINAL_COLUMNS if name == "bench_nn" else None))
    for name, why in result["skipped"].items():
        console.print(f"[yellow]skipped {name}:[/yellow] {escape(str(why))}")
    console.print(f"wrote {layout.evaluate}/ ({len(result['tables'])} tables, {len(result['figures'])} figures) "
                  f"in {result['wall_time_s']:.0f} s; next: persival report --run {run}")


def report(
    ctx: typer.Context,
    run: Path = typer.Option(Path("results"), "--run", help="Run folder with RUN/evaluate (persival evaluate)."),
) -> None:
    """One self-contained HTML page of a run (every table and figure, provenance): RUN/report/index.html."""
    if ctx.invoked_subcommand is not None:
        return
    from rich.console import Console

    from persival.evaluate.report import write_report

    out = Path(run) / "report"
    with user_errors(out=out):
        if not Path(run).is_dir():
            raise FileNotFoundError(f"--run {run}: no such run folder")
        check_output_dir(out)
        index = write_report(run)
    Console().print(f"wrote {index} and {index.parent / 'results.json'}")


def readme(
    results: Path = typer.Option(Path("docs/results.json"), "--results",
                                 help="A run's results.json (RUN/report/results.json; the committed copy: docs/results.json)."),
    files: list[Path] = typer.Option(None, "--file", help="Markdown file with result blocks (<!-- results:NAME --> ... "
                                     "<!-- /results:NAME -->); repeat it. Default: README.md and docs/benchmarks.md."),
    check: bool = typer.Option(False, "--check", help="Write nothing; exit 1 when a block differs from its rendering."),
) -> None:
    """Rewrite the result blocks of README.md and docs/benchmarks.md from a run's results.json."""
    from persival.evaluate.readme_blocks import DEFAULT_FILES, load_results, rewrite_file

    paths = [Path(f) for f in (files or DEFAULT_FILES)]
    with user_errors():
        data = load_results(results)
        for path in paths:  # every file is checked before the first is written
            rewrite_file(path, data, check=True)
        statuses = {path: rewrite_file(path, data, check=check) for path in paths}
    differ = False
    for path, status in statuses.items():
        for name, what in status.items():
            shown = "differs" if check and what == "changed" else what
            typer.echo(f"{path}: results:{name} {shown}" + (" (kept as written)" if what == "no numbers" else ""))
            differ |= what == "changed"
    if check and differ:
        raise typer.Exit(1)


