"""CLI commands of the evaluation stage (benchmarks, tables, figures)."""

from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    """Attach this stage's commands to the main app and the benchmark group."""

    @app.command()
    def render(
        states: list[Path] = typer.Argument(..., help="State directories written by `persival simulate`."),
        out: Path = typer.Option(Path("results/arm.png"), "--out", help="PNG file to write."),
    ) -> None:
        """Render solved arm states side by side (off-screen pyvista), coloured by displacement."""
        from rich.console import Console

        from persival.evaluate.render import render_states

        console = Console()
        try:
            path = render_states(states, out)
        except (FileNotFoundError, ValueError) as exc:
            console.print(f"[red]error:[/red] {exc}")
            raise typer.Exit(2) from None
        console.print(f"wrote {path}")

    @bench_app.command("fe")
    def bench_fe(
        mesh_size: float = typer.Option(6.3, help="Element size of the 40 x 300 mm spindle (mm)."),
        activation: float = typer.Option(1.0, min=0.0, max=1.0, help="Activation of the benchmark state."),
        repeats: int = typer.Option(5, min=1, help="Repetitions per timing (best is kept)."),
        backend: str = typer.Option("auto", help="Sparse solver: auto, pardiso or scipy."),
    ) -> None:
        """Newton iteration vs sparse factorization on the paper-size spindle (target ratio <= 1.5)."""
        from persival.evaluate.bench_fe import print_fe_benchmark, run_fe_benchmark

        print_fe_benchmark(run_fe_benchmark(mesh_size, activation, repeats, backend))
