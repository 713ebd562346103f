"""CLI commands of the surrogate stage."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli_errors import check_output_dir, fail, user_errors


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    """Attach this stage's commands to the main app and the benchmark group."""
    surrogate_app = typer.Typer(help="Surrogates fitted to campaign stores.", no_args_is_help=True)
    app.add_typer(surrogate_app, name="surrogate")

    @surrogate_app.command("fit-sg")
    def fit_sg(
        store: Path = typer.Option(..., "--store", help="Campaign store (zarr) with a sparse-grid design."),
        out: Path = typer.Option(Path("results/sg"), "--out", help="Output directory."),
        muscle: str = typer.Option("biceps", "--muscle", help="Surface to interpolate."),
        degree: int = typer.Option(3, "--degree", help="Odd B-spline degree."),
    ) -> None:
        """Fit the B-spline sparse grid (surface positions + elbow angle) to a finished campaign."""
        from rich.console import Console

        from persival.campaign.store import StoreError
        from persival.surrogate.surface_surrogate import SurfaceSurrogate

        console = Console()
        with user_errors(StoreError, out=out):
            check_output_dir(out)
            surrogate = SurfaceSurrogate(muscle, degree).fit(store)
            surrogate.save(out)
        meta = surrogate.metadata
        console.print(f"fitted level-{meta['level']} grid ({meta['grid_points']} points) to {surrogate.n_nodes} {muscle} "
                      f"nodes + elbow angle; wrote {out}")

    @surrogate_app.command("adapt")
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
