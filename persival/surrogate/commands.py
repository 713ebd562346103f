"""CLI commands of the surrogate stage."""

from __future__ import annotations

from pathlib import Path

import typer


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

        from persival.surrogate.surface_surrogate import SurfaceSurrogate

        console = Console()
        try:
            surrogate = SurfaceSurrogate(muscle, degree).fit(store)
        except (ValueError, FileNotFoundError) as exc:
            console.print(f"[red]error:[/red] {exc}")
            raise typer.Exit(2) from None
        surrogate.save(out)
        meta = surrogate.metadata
        console.print(f"fitted level-{meta['level']} grid ({meta['grid_points']} points) to {surrogate.n_nodes} {muscle} nodes + elbow angle; wrote {out}")

    @bench_app.command("sg")
    def bench_sg(
        dim: int = typer.Option(5, help="Input dimension (activations)."),
        level: int = typer.Option(2, help="Regular sparse-grid level."),
        degree: int = typer.Option(3, help="Odd B-spline degree."),
        n_out: int = typer.Option(2809 * 3 + 1, help="Outputs per state (surface xyz + angle)."),
        batch: int = typer.Option(1000, help="Large batch size."),
        reps: int = typer.Option(300, help="Repetitions at batch 1 (after warmup)."),
    ) -> None:
        """Seconds per whole-surface state of the sparse-grid surrogate, batch 1 and large batch."""
        # Heavy imports stay inside the command so that `persival --help` stays fast.
        from persival.evaluate.bench_sparse_grid import print_benchmark, run_benchmark

        print_benchmark(
            run_benchmark(dim=dim, level=level, degree=degree, n_out=n_out, batch=batch,
                          reps_single=reps)
        )
