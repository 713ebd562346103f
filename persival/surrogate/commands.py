"""CLI commands of the surrogate stage."""

from __future__ import annotations

import typer


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    """Attach this stage's commands to the main app and the benchmark group."""

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
