"""CLI commands of the surrogate stage."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli.errors import check_output_dir, fail, user_errors
from persival.cli.help import FullHelpGroup
from persival.cli.values import parse_numbers
from persival.model.arm.defaults import MODEL_HELP


def register(app: typer.Typer) -> None:
    """Attach this stage's commands to the main app (the motion model's: persival.cli.motion)."""
    surrogate_app = typer.Typer(cls=FullHelpGroup, help="Surrogates fitted to campaign stores.", no_args_is_help=True)
    app.add_typer(surrogate_app, name="surrogate")
    surrogate_app.command("fit-sg")(fit_sg)
    surrogate_app.command("fit-structured")(fit_structured_command)
    surrogate_app.command("adapt")(adapt)
    app.command("inverse")(inverse)
    app.command("data")(data)
    app.command("train")(train)


def fit_sg(
    store: Path = typer.Option(..., "--store", help="Campaign store (zarr) with a sparse-grid design."),
    out: Path = typer.Option(Path("results/sg"), "--out", help="Output directory."),
    muscle: str = typer.Option("biceps", "--muscle", help="Surfaces to interpolate: a name, a comma-separated "
                               "list, or all."),
    degree: int = typer.Option(3, "--degree", help="Odd B-spline degree."),
) -> None:
    """Fit the B-spline sparse grid (surface positions + elbow angle) to a finished campaign."""
    from rich.console import Console

    from persival.campaign.store import StoreError
    from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate

    console = Console()
    with user_errors(StoreError, out=out):
        check_output_dir(out)
        from persival.surrogate.build import parse_muscles

        surrogate = SparseGridSurrogate(parse_muscles(muscle), degree).fit(store)
        surrogate.save(out)
    meta = surrogate.metadata
    console.print(f"fitted level-{meta['level']} grid ({meta['grid_points']} points) to {surrogate.n_nodes} "
                  f"{surrogate.muscle} nodes + elbow angle; wrote {out}")


def fit_structured_command(
    store: Path = typer.Option(..., "--store", help="Campaign store of the FE arm: the surfaces to answer."),
    out: Path = typer.Option(Path("results/structured"), "--out", help="Output directory."),
    profile: str = typer.Option("quick", "--profile", help="Mesh profile of the arm (its response tables)."),
    model: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    tables: Path | None = typer.Option(None, "--tables", help="Response-table folder (default: the model's cache)."),
    tolerance: float | None = typer.Option(None, "--tolerance", min=1e-6, help="POD truncation, mm: every tabulated "
                                           "surface kept within it [default: 0.2]."),
    frame: str = typer.Option("world", "--frame", help="Reduce each muscle's surfaces in the world frame (one product "
                              "per muscle in the exported graph) or in its own frame ('own': fewer modes, turned by Q)."),
) -> None:
    """Fit the structured surrogate (per-muscle shape and moment models + the elbow's equilibrium) to the response tables."""
    from rich.console import Console

    from persival.campaign.store import StoreError
    from persival.surrogate.build import fit_structured

    console = Console()
    if frame not in ("world", "own"):
        fail(f"--frame must be 'world' or 'own', not {frame!r}")
    with user_errors(StoreError, out=out):
        check_output_dir(out)
        surrogate = fit_structured(store, out, profile, model, tables, tolerance, frame)
    meta = surrogate.metadata
    console.print(f"fitted {len(meta['muscles'])} muscles from the tables in {meta['fit_seconds']:.1f} s: POD modes "
                  + ", ".join(f"{k} {v}" for k, v in meta["modes"].items())
                  + f"; {meta['parameters']} parameters; wrote {out}")


def adapt(
    out: Path = typer.Option(
        ..., "--out", help="Output directory: stores/ (one campaign store per step), surrogate/, adaptive.json."),
    max_points: int = typer.Option(..., "--max-points", min=1, help="FE budget: grid points of the final grid."),
    simulator: str = typer.Option("arm", "--simulator", help="Simulator kind: arm or analytic."),
    option: list[str] = typer.Option([], "--option", help="Simulator option KEY=VALUE (e.g. profile=quick), repeatable."),
    seed_store: list[Path] = typer.Option(
        [], "--seed-store", help="Campaign store whose done states are reused when the grid asks for their points "
        "(same model), repeatable."),
    initial_level: int = typer.Option(
        0, "--initial-level", min=0, help="Start grid: 0 = the 32 corners, L >= 1 = regular level L."),
    refinements: int = typer.Option(
        2, "--refinements-per-step", min=1, help="Points refined per step (each brings its children and their ancestors)."),
    norm: str = typer.Option("max", "--norm", help="Refinement indicator over a point's surplus row: max or l2."),
    tol: float = typer.Option(
        0.0, "--tol", min=0.0, help="Stop when no refinable point's indicator (mm or deg) reaches this."),
    muscle: str = typer.Option("biceps", "--muscle", help="Surface to interpolate."),
    degree: int = typer.Option(3, "--degree", help="Odd B-spline degree."),
    scheduler: str = typer.Option(
        "inline", "--scheduler", help="inline (default: the simulator stays warm between steps), a dask address, "
        "or 'local' for a LocalCluster per step."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show progress bars."),
) -> None:
    """Grow a spatially adaptive sparse grid: refine where surpluses are largest, solve only the new points."""
    from rich.console import Console

    from persival.campaign.design import DesignError
    from persival.campaign.options import build_spec
    from persival.campaign.simulator import UnknownSimulatorError
    from persival.campaign.store import StoreError
    from persival.surrogate.adaptive_campaign import run_adaptive_campaign

    console = Console()
    if simulator not in ("arm", "analytic"):
        fail(f"--simulator must be arm or analytic, got {simulator!r}")
    # No out=: a failure after some steps keeps their stores, which a rerun reuses.
    # RuntimeError: failed FE states end the run with the command that retries them.
    with user_errors(DesignError, StoreError, UnknownSimulatorError, RuntimeError):
        check_output_dir(out)
        spec = build_spec(simulator, option, None, None, None, [], None)
        result = run_adaptive_campaign(
            out, spec, max_points=max_points, muscle=muscle, degree=degree, initial_level=initial_level,
            refinements_per_step=refinements, norm=norm, tol=tol, seed_stores=seed_store,
            scheduler=None if scheduler == "local" else scheduler, progress=progress, log=console.print,
        )
    console.print(
        f"adaptive grid of {result.surrogate.grid.n_points} points after {len(result.steps)} steps "
        f"({result.stop_reason}); {result.simulated} states solved, {result.reused} reused; "
        f"{result.wall_time_s:.0f} s; wrote {out / 'surrogate'}"
    )


def _angles(text: str) -> list[float]:
    return parse_numbers(text, "--angles", "deg")


def _progress_bar(description: str):
    """A rich progress bar and an ``advance(done, total, ...)`` callback for the stage functions."""
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

    from persival.cli.progress import rich_progress_bar as progress_bar

    bar = progress_bar(TextColumn(description), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                   TextColumn("{task.fields[info]}"))
    task = bar.add_task(description, total=None, info="")

    def advance(done, total, *info):
        # training: (val loss, MAE per coordinate, "fold f/F epoch e/E"); other stages: nothing
        text = (f"{info[2]}, val loss {info[0]:.4g}, MAE {', '.join(f'{v:.3f}' for v in info[1])} mm"
                if len(info) == 3 else "")
        bar.update(task, completed=done if done > 1 or total is None else bar.tasks[0].completed + done,
                   total=total, info=text)

    return bar, advance


def inverse(
    surrogate: Path = typer.Option(..., "--surrogate", help="Sparse-grid surrogate folder (persival surrogate fit-sg)."),
    angles: str = typer.Option("20,60,100,140", "--angles", help="Target elbow angles, deg, comma-separated."),
    as_json: bool = typer.Option(False, "--json", help="Print the solutions as JSON."),
    out: Path = typer.Option(None, "--out", help="Also build the activation model Theta -> alpha_opt: "
                             "OUT/activation_model.json and .png."),
) -> None:
    """Least-effort activations for elbow angles on the SG; optionally the activation model."""
    import json

    from rich.console import Console
    from rich.table import Table

    from persival.surrogate.build import build_activation_model, solve_inverse
    from persival.vocabulary import ABBREVIATIONS

    with user_errors(out=out):
        targets = _angles(angles)
        if out is not None:
            check_output_dir(out)
        solution, problem = solve_inverse(surrogate, targets)
        lo, hi = problem.reachable_range()
        if out is not None:
            bar, advance = _progress_bar("activation model")
            with bar:
                out.mkdir(parents=True, exist_ok=True)
                model = build_activation_model(surrogate, out / "activation_model.json", advance)
    if as_json:
        typer.echo(json.dumps(solution.rows(), indent=1))
        return
    console = Console()
    table = Table(title=f"alpha_opt (angles in deg; reachable {lo:.2f} to {hi:.2f} deg)")
    for col in ["target", *ABBREVIATIONS, "achieved", "obj.", "reach"]:
        table.add_column(col, justify="right")
    for r in solution.rows():
        table.add_row(f"{r['target_deg']:.1f}", *[f"{a:.3f}" for a in r["activations"]], f"{r['achieved_deg']:.3f}",
                      f"{r['objective']:.4f}", "yes" if r["reachable"] else "[red]no[/red]")
    console.print(table)
    if out is not None:
        console.print(f"activation model: {len(model.knots)} knots over {model.range_deg[0]:.2f}-{model.range_deg[1]:.2f} "
                      f"deg, {len(model.branch_notes)} branch notes; wrote {out}/activation_model.json and .png")


def data(
    surrogate: Path = typer.Option(..., "--surrogate", help="Sparse-grid surrogate folder."),
    activation_model: Path = typer.Option(..., "--activation-model", help="activation_model.json (persival inverse --out)."),
    out: Path = typer.Option(..., "--out", help="Training-data folder (zarr chunks + training_data.json)."),
    samples: int = typer.Option(4000, "--samples", min=1, help="Number of states."),
    angle_fraction: float = typer.Option(0.5, "--angle-fraction", min=0.0, max=1.0,
                                         help="Share of states at alpha_opt(Theta); the rest at random alpha."),
    seed: int = typer.Option(0, "--seed", help="Random seed (same seed, same data)."),
) -> None:
    """SG training data for the networks: states at alpha_opt(Theta) and at random activations."""
    from persival.surrogate.build import make_training_data

    with user_errors(out=out):
        check_output_dir(out)
        bar, advance = _progress_bar("training data")
        with bar:
            make_training_data(surrogate, activation_model, out, samples, angle_fraction, seed, advance)
    typer.echo(f"wrote {samples} states ({angle_fraction:.0%} at alpha_opt(Theta)) to {out}")


def train(
    data: Path = typer.Option(..., "--data", help="Training-data folder (persival data)."),
    out: Path = typer.Option(..., "--out", help="Network folder; a checkpoint there is resumed."),
    arch: str = typer.Option("pod", "--arch", help="paper (the paper's exponential nets) or pod (POD network)."),
    muscle: str = typer.Option("all", "--muscle", help="Muscles to learn: all, or a comma-separated list."),
    folds: int = typer.Option(5, "--folds", min=1, help="Cross-validation folds."),
    epochs: int = typer.Option(400, "--epochs", min=1, help="Epochs per fold."),
    activation: str = typer.Option("relu", "--activation", help="relu (default: best by validation), tanh, silu or elu."),
    batch_size: int = typer.Option(64, "--batch-size", min=1),
    learning_rate: float = typer.Option(1e-3, "--learning-rate", min=0.0),
    rank: int = typer.Option(None, "--rank", min=1, help="POD rank (default: by the energy criterion)."),
    device: str = typer.Option("auto", "--device", help="auto (CUDA when present, else CPU), cpu or cuda."),
) -> None:
    """Train the paper network or the POD network (k-fold CV, best by validation loss)."""
    from persival.surrogate.build import parse_muscles, train_network
    from persival.surrogate.training import TrainingConfig

    with user_errors(out=out):
        check_output_dir(out)
        config = TrainingConfig(arch=arch, folds=folds, epochs=epochs, activation=activation, batch_size=batch_size,
                                learning_rate=learning_rate, rank=rank)
        from persival.surrogate.training import resolve_device

        resolve_device(device)  # a wrong --device is refused before the data is read
        bar, advance = _progress_bar(f"training ({arch})")
        with bar:
            surrogate = train_network(data, out, config, parse_muscles(muscle), advance, device)
    best = surrogate.metadata["training"]["best"]
    typer.echo(f"best validation loss {best['val_loss']:.4g} (fold {best['fold']}, epoch {best['epoch']}), "
               f"{surrogate.metadata['parameters']} parameters; wrote {out} (history.png)")


