"""Commands that look at the solved arm: `persival render` (side views), `sections` (cross-sections),
`curves` (moments and moment arms against published bands) and `anatomy` (bodies inside each other)."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli.errors import check_output_dir, check_output_file, user_errors
from persival.cli.values import parse_numbers
from persival.model.arm.defaults import MODEL_HELP, profiles_help


def register(app: typer.Typer) -> None:
    """Attach the arm's inspection commands to the main app."""
    for command in (render, sections, curves, anatomy):
        app.command()(command)


def render(
    states: list[Path] = typer.Argument(..., help="State directories written by `persival simulate`."),
    out: Path = typer.Option(Path("results/arm.png"), "--out", help="PNG file to write."),
    muscles: str | None = typer.Option(None, "--muscles", help="Comma-separated muscles to draw (default: all)."),
) -> None:
    """Render solved arm states side by side (off-screen pyvista), coloured by displacement."""
    from rich.console import Console

    from persival.evaluate.render import render_states

    console = Console()
    with user_errors(out=out):
        check_output_file(out)
        path = render_states(states, out, muscles=muscles)
    console.print(f"wrote {path}")


def sections(
    states: list[Path] = typer.Argument(..., help="State directories written by `persival simulate`."),
    heights: str = typer.Option("100,150,200,250", "--heights", help="Comma-separated heights along the humerus (mm)."),
    muscles: str | None = typer.Option(None, "--muscles", help="Comma-separated muscles to draw (default: all)."),
    out: Path = typer.Option(Path("results/sections.png"), "--out", help="PNG file to write."),
) -> None:
    """Transverse sections of solved arm states: muscle and bone outlines across the upper arm."""
    from rich.console import Console

    from persival.evaluate.sections import render_sections

    console = Console()
    with user_errors(out=out):
        check_output_file(out)
        levels = parse_numbers(heights, "--heights", "mm")
        path = render_sections(states, levels, out, muscles)
    console.print(f"wrote {path}")


def curves(
    model: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    profile: str = typer.Option("quick", "--profile", help=profiles_help()),
    out: Path = typer.Option(Path("results/curves"), "--out", help="Output directory (curves.json, curves.png)."),
) -> None:
    """Every muscle's passive and active moment against the elbow angle, and the equilibria they predict."""
    import json

    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from persival.cli.progress import rich_progress_bar as progress_bar
    from persival.evaluate.muscle_curves import REPORTED_SETS, band_check, muscle_curves, plot_curves, predicted_equilibrium
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.model_file import load_model_file

    console = Console()
    with user_errors():  # before the meshing
        load_model_file(model)[0].profile(profile)
        check_output_dir(out)
        arm = ArmModel(model, profile)
    tables = _curve_tables(console, arm)
    with progress_bar(console=console) as bar:
        task = bar.add_task("muscle sweeps", total=10)
        data = muscle_curves(
            arm, progress=lambda name, a: bar.update(task, advance=1, description=f"{name} at activation {a:g}"),
            tables=tables)
    table = Table(title="equilibria predicted by the curves (persival simulate solves them exactly)")
    table.add_column("activations")
    table.add_column("elbow angle (deg)", justify="right")
    predicted = {}
    for label, acts in REPORTED_SETS.items():
        predicted[label] = predicted_equilibrium(data, acts)
        table.add_row(label, f"{predicted[label]:.1f}")
    console.print(table)
    bands = band_check(data)
    arms = Table(title="moment arms (mm, flexion +) against the physiological bands")
    for column in ("muscle", "angles (deg)", "band", "model", "inside"):
        arms.add_column(column)
    for row in bands:
        low, high = row["band_mm"]
        arms.add_row(row["muscle"], "{:g} to {:g}".format(*row["angles_deg"]),
                     f"{low:g} to {high:g}" if high is not None else f">= {low:g}",
                     "{:.1f} to {:.1f}".format(*row["model_mm"]),
                     {True: "yes", False: "[red]no[/red]", None: "not solved"}[row["inside"]])
    console.print(arms)
    out.mkdir(parents=True, exist_ok=True)
    serial = {k: (v.tolist() if isinstance(v, np.ndarray) else {kk: vv.tolist() for kk, vv in v.items()})
              for k, v in data.items()}
    (out / "curves.json").write_text(json.dumps({"profile": profile, "curves": serial, "predicted_deg": predicted,
                                                 "moment_arm_bands": bands}, indent=1))
    console.print(f"wrote {out / 'curves.json'} and {plot_curves({**data, 'profile': profile}, out / 'curves.png')}")


def anatomy(
    states: list[Path] = typer.Argument(None, help="State directories written by the FE stage or `persival simulate`."),
    store: Path | None = typer.Option(None, "--store", help="Campaign store of the FE arm (instead of state directories)."),
    model: Path | None = typer.Option(None, "--model", help="Model file the states were computed with "
                                      "(default: a store's own, else the built-in arm)."),
    attachment: float = typer.Option(10.0, "--attachment-mm", min=0.0, help="Leave out nodes this close to a "
                                     "muscle's ends (its attachments)."),
    outlines: bool = typer.Option(False, "--outlines", help="Instead: the model file's muscle outlines across the "
                                  "humerus at 10/30/50/70/90 %, checked as polygons (no states needed)."),
    run: Path | None = typer.Option(None, "--run", help="Instead: a run folder's FE and held-out states, as `persival "
                                    "run`'s anatomy stage measures them (RUN/anatomy/)."),
    out: Path | None = typer.Option(None, "--out", help="JSON file to write (every state, and the worst per pair)."),
) -> None:
    """Overlap between bodies (surface nodes inside another body, deepest penetration) and each muscle's gap to its bed."""
    from rich.console import Console
    from rich.progress import Progress

    from persival.campaign.store import StoreError
    from persival.cli.show import check_outlines_table, print_anatomy_tables
    from persival.evaluate.anatomy import check_state_dirs, check_store, write_json

    console = Console()
    with user_errors(StoreError, out=out):
        if out is not None:
            check_output_file(out)
        if bool(states) + (store is not None) + outlines + (run is not None) != 1:
            raise ValueError("give state directories, --store STORE, --run RUN or --outlines (one of the four)")
        if outlines:
            check_outlines_table(console, model, out)
            return
        if run is not None:
            from persival.cli.show import to_rich
            from persival.evaluate.anatomy_run import measure_run

            table = measure_run(run, model)
            console.print(to_rich(table))
            console.print(f"{table['notes'][0]}; wrote {run / 'anatomy'}/")
            return
        if store is not None:
            with Progress(console=console, transient=True) as bar:
                task = bar.add_task("anatomy of the store's states", total=None)
                results = check_store(store, model, attachment,
                                      progress=lambda done, total: bar.update(task, completed=done, total=total))
        else:
            results = check_state_dirs(states, model, attachment)
        if not results:
            raise ValueError(f"{store}: no finished states to measure")
        print_anatomy_tables(console, results)
        if out is not None:
            write_json(results, out, str(store) if store is not None else ", ".join(map(str, states)), attachment)
            console.print(f"wrote {out}")


def _curve_tables(console, arm):
    """The arm's response tables as a TableSolver when built (their levels run from 0 to 1), else None (sweeps)."""
    from persival.tables.open import open_tables
    from persival.tables.table_solve import TableSolver

    try:
        table = open_tables(arm)
    except (FileNotFoundError, ValueError):
        console.print("[dim]no response tables of this model: sweeping every muscle (minutes; "
                      "`persival tables` makes this seconds)[/dim]")
        return None
    console.print(f"[dim]states from the response tables at {table.root}[/dim]")
    return TableSolver(arm, table)
