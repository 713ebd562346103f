"""CLI of the FE arm as a data engine: ``persival tables``, ``persival simulate`` and ``persival moments``.

The response tables are built in parallel with dask; ``simulate`` answers from them (the exact
path of persival.tables.table_solve) when they exist, and FE-arm campaigns read them.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import typer

from persival.cli.errors import check_output_dir, check_output_file, user_errors
from persival.cli.values import parse_activations, parse_grid
from persival.model.arm.defaults import MODEL_HELP, profiles_help
from persival.tables.response_table import DEFAULT_LEVELS
from persival.vocabulary import MUSCLES, N_ACTIVATIONS

ACTIVATIONS_HELP = f"{N_ACTIVATIONS} comma-separated activations in [0, 1], in the order {', '.join(MUSCLES)}; e.g. 0.5,0,0,0,0."


def register(app: typer.Typer) -> None:
    """Attach ``tables``, ``simulate`` and ``moments`` (the per-muscle FE moment table, docs/theory.md
    4.5) to the main app."""
    app.command("moments")(moments)
    app.command("tables")(tables)
    app.command()(simulate)


def tables(
    profile: str = typer.Option("quick", "--profile", help=profiles_help()),
    model: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    out: Path | None = typer.Option(None, "--out", help="Table folder (default: the model's state cache)."),
    moments_out: Path | None = typer.Option(None, "--moments-out",
                                            help="Also write the moments as a moment table (.npz, for `persival motion`)."),
    angles: str = typer.Option("-10:185:5", "--angles",
                              help="Elbow angles, deg: START:STOP:STEP or a list (--angles=-10:185:5 when negative)."),
    levels: str = typer.Option(",".join(f"{v:g}" for v in DEFAULT_LEVELS), "--levels",
                               help="Activation levels from 0 to 1."),
    scheduler: str | None = typer.Option(None, "--scheduler",
                                         help="Dask scheduler address, or 'inline'; default: a LocalCluster."),
    workers: int | None = typer.Option(None, "--workers", help="LocalCluster worker processes (default: one per core)."),
) -> None:
    """Per-muscle FE response tables over (elbow angle, activation): moments, forces, node states.

    Built once per model and mesh (resumable: a killed build keeps its finished columns);
    `persival simulate` and FE-arm campaigns answer from them.
    """
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

    from persival.cli.progress import rich_progress_bar as progress_bar
    from persival.model.arm.body import ArmBody
    from persival.tables.moment_table import TableMismatchError, check_grids
    from persival.tables.open import ensure_tables

    console = Console()
    with user_errors(TableMismatchError):
        grid = check_grids(parse_grid(angles, "--angles"), parse_grid(levels, "--levels"))
        ArmBody.frame(model, profile)  # the model file, its profile and its own surfaces
        if moments_out is not None and moments_out.suffix != ".npz":
            raise ValueError(f"--moments-out must name a .npz file, got {moments_out}")
        if out is not None and out.exists() and not (out / "header.json").is_file() and \
                (out.is_file() or any(out.iterdir())):
            raise TableMismatchError(f"{out} exists and is not a response table (no header.json); pick an empty folder")
        t0 = time.perf_counter()
        bar = progress_bar(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                       console=console)
        with bar:
            task = bar.add_task("meshing, rest states", total=None)

            def report(done, total):
                bar.update(task, completed=done, total=total, description="response table columns")

            table = ensure_tables(model, profile, str(out) if out else None, report, scheduler, workers, *grid)
        if moments_out is not None:
            moments_out.parent.mkdir(parents=True, exist_ok=True)
            table.moment_table().save(moments_out)
    _print_table(console, table, time.perf_counter() - t0)
    if moments_out is not None:
        console.print(f"wrote the moment table {moments_out}")


def simulate(
    activations: str = typer.Option(..., "--activations", "-a", help=ACTIVATIONS_HELP),
    model: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    profile: str = typer.Option("quick", "--profile", help=profiles_help()),
    method: str = typer.Option("auto", "--method",
                               help="tables (from `persival tables`), direct (coupled continuation) or auto "
                                    "(tables when built)."),
    out: Path = typer.Option(Path("results/simulate"), "--out", help="Output directory (state.json + VTU)."),
    angle: float | None = typer.Option(None, "--angle", help="Hold the elbow at this angle (deg; an isometric "
                                       "state: each muscle's FE equilibrium there, a brace takes the joint's moment; "
                                       "solved directly)."),
    load: float = typer.Option(0.0, "--load", help="kg held in the hand (at the forearm's hand_distance); the "
                               "joint's equilibrium carries it."),
) -> None:
    """Solve the FE arm for one activation vector (or hold it at --angle); write state.json and VTU files."""
    from rich.console import Console

    from persival.model.arm.body import ArmBody
    from persival.vocabulary import check_activation_vector

    console = Console()
    with user_errors():  # every input is checked before the meshing and solve
        alpha = check_activation_vector(parse_activations(activations)).tolist()
        spec = ArmBody.frame(model, profile).spec  # the model file, its profile and its own surfaces
        lower, upper = spec.joint.limits_deg
        if angle is not None and not lower <= angle <= upper:
            raise ValueError(f"--angle must lie within the joint limits [{lower:g}, {upper:g}] deg, got {angle:g}")
        if method not in ("auto", "tables", "direct"):
            raise ValueError(f"--method must be auto, tables or direct, got {method!r}")
        if not (np.isfinite(load) and load >= 0.0):
            raise ValueError(f"--load must be a finite number of kg >= 0, got {load:g}")
        check_output_dir(out)
    with user_errors(out=out):
        if angle is None:
            state, arm, path = _solve_one(console, model, profile, method, alpha, load)
        else:
            state, arm = _hold_one(console, model, profile, alpha, angle, load)
            path = "held by a brace: the residual is its moment"
        from persival.model.arm.output import write_state

        write_state(arm, state, out)
    console.print(
        f"elbow angle [bold]{state.elbow_angle_deg:.2f} deg[/bold] ({path}), moment residual "
        f"{state.moment_residual:.2e} N mm, {state.statistics['iterations']} Newton iterations, "
        f"{state.wall_time_s:.1f} s solve, max |J-1| {state.max_volume_change:.2e}"
    )
    console.print(f"wrote {out}/state.json and VTU files (open {out}/*.vtu in ParaView)")


def _solve_one(console, model, profile: str, method: str, alpha, load: float = 0.0):
    """(state, arm, 'tables' | 'direct') for one activation vector; a failed solve is a typer.Exit(3)."""
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.progress import ConsoleProgress
    from persival.model.fe.solver import ConvergenceError
    from persival.tables.open import open_tables
    from persival.tables.table_solve import TableSolver

    with console.status("meshing the arm (gmsh, cached after the first run)"):
        arm = ArmModel(model, profile)
    with console.status("the hanging arm (activations 0)") as status, \
            ConsoleProgress(console, status, "the hanging arm") as report:
        try:
            arm.base_state(progress=report)  # with its progress shown; the table solve reads it
        except ConvergenceError as exc:
            typer.echo(f"error: the hanging arm (activations 0) did not converge: {exc}; nothing was written", err=True)
            raise typer.Exit(3) from None
    arm.hand_load_kg = load  # after the hanging arm, the unloaded start every state continues from
    table = None
    if method != "direct":
        try:
            table = open_tables(arm)
        except (FileNotFoundError, ValueError) as exc:
            if method == "tables":
                raise
            console.print(f"[dim]{exc}; solving directly (minutes)[/dim]")
    with console.status(f"solving activations {alpha}") as status, \
            ConsoleProgress(console, status, f"activations {alpha}") as report:
        try:
            if table is not None:
                return TableSolver(arm, table).solve(alpha, progress=report), arm, "tables"
            return arm.solve(alpha, progress=report), arm, "direct"
        except ConvergenceError as exc:
            typer.echo(f"error: the FE solve did not converge: {exc}; nothing was written", err=True)
            raise typer.Exit(3) from None


def _hold_one(console, model, profile: str, alpha, angle: float, load: float = 0.0):
    """(state, arm) of the arm held at ``angle`` (the brace also takes the hand's load); a failed solve is a typer.Exit(3)."""
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.progress import ConsoleProgress
    from persival.model.fe.solver import ConvergenceError

    with console.status("meshing the arm (gmsh, cached after the first run)"):
        arm = ArmModel(model, profile)
    arm.hand_load_kg = load
    with console.status(f"activations {alpha} held at {angle:g} deg") as status, \
            ConsoleProgress(console, status, f"activations {alpha}") as report:
        try:
            return arm.hold(alpha, angle, progress=report), arm
        except ConvergenceError as exc:
            typer.echo(f"error: the FE solve did not converge: {exc}; nothing was written", err=True)
            raise typer.Exit(3) from None


def _print_table(console, table, seconds: float) -> None:
    moments = table.moment_table()
    print_moment_table(console, moments, seconds, table.root)
    lo, hi = moments.finite_range_deg()
    console.print(f"{int(table.done.sum())} of {table.done.size} columns, angles {lo:g} to {hi:g} deg converged at every level")


def moments(
    out: Path = typer.Option(..., "--out", help="Table file (.npz); an unfinished one of the same grid is resumed."),
    profile: str = typer.Option("quick", "--profile", help="Mesh profile (coarse, quick, paper)."),
    model: Path = typer.Option(None, "--model", help=MODEL_HELP),
    angles: str = typer.Option("0:160:10", "--angles", help="Elbow angles, deg: START:STOP:STEP or a list."),
    levels: str = typer.Option("0,0.25,0.5,0.75,1", "--levels", help="Activation levels from 0 to 1."),
) -> None:
    """Per-muscle FE moment tables over (elbow angle, activation), by continuation along the angle."""
    import time

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

    from persival.cli.progress import rich_progress_bar as progress_bar
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.model_file import load_model_file
    from persival.tables.moment_table import build_moment_table, check_grids, resumable

    console = Console()
    with user_errors(out=out):  # every check before the meshing; a new file is removed on a user error
        grid = check_grids(parse_grid(angles, "--angles"), parse_grid(levels, "--levels"))
        spec, model_hash = load_model_file(model)
        spec.profile(profile)
        check_output_file(out)
        resumable(out, model_hash, profile, *grid)
        arm = ArmModel(model, profile)
    t0 = time.perf_counter()
    bar = progress_bar(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                       console=console)
    with bar, user_errors():
        task = bar.add_task("moment table", total=5 * len(grid[1]))
        table = build_moment_table(arm, *grid, out=out, progress=lambda done, total, label: bar.update(
            task, completed=done, description=label))
    print_moment_table(console, table, time.perf_counter() - t0, out)


def print_moment_table(console, table, seconds: float, out: Path) -> None:
    """Fully active moments at a few angles, failed solves and compute seconds per muscle."""
    import numpy as np
    from rich.table import Table

    from persival.vocabulary import MUSCLES

    t = Table(title=f"fully active moments (N mm) and failed solves; {seconds:.0f} s this run, {out}")
    t.add_column("muscle")
    picks = [k for k in range(len(table.angles_deg)) if k % max(1, len(table.angles_deg) // 4) == 0]
    for k in picks:
        t.add_column(f"{table.angles_deg[k]:g} deg", justify="right")
    t.add_column("NaN", justify="right")
    t.add_column("s", justify="right")
    moments = table.moments
    for m, name in enumerate(MUSCLES):
        secs = sum(s for s in table.meta["column_seconds"][m] if s is not None)
        t.add_row(name, *[f"{moments[m, k, -1]:.0f}" for k in picks], str(int(np.isnan(moments[m]).sum())), f"{secs:.0f}")
    console.print(t)
