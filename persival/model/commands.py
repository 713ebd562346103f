"""CLI commands of the model (physics) stage."""

from __future__ import annotations

from pathlib import Path

import typer


def parse_activations(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise typer.BadParameter("activations must be 5 comma-separated numbers, e.g. 0.5,0,0,0,0") from None
    if len(values) != 5:
        raise typer.BadParameter(f"need 5 activations (biceps, brachialis, brachioradialis, triceps, anconeus), got {len(values)}")
    return values


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    """Attach this stage's commands to the main app and the benchmark group."""

    @app.command()
    def run(
        out: Path = typer.Option(Path("results"), "--out", help="Results directory."),
        profile: str = typer.Option("quick", "--profile", help="Mesh profile of the arm: quick or paper."),
    ) -> None:
        """End to end over the stages that exist: model -> FE -> campaign -> sparse-grid surrogate."""
        from persival.pipeline import run as run_pipeline

        run_pipeline(out, profile)

    @app.command()
    def simulate(
        activations: str = typer.Option(..., "--activations", "-a", help="biceps,brachialis,brachioradialis,triceps,anconeus in [0,1]"),
        model: Path | None = typer.Option(None, "--model", help="Model file (TOML); default: the built-in arm."),
        profile: str = typer.Option("quick", "--profile", help="Mesh profile: quick or paper."),
        out: Path = typer.Option(Path("results/simulate"), "--out", help="Output directory (state.json + VTU)."),
    ) -> None:
        """Solve the FE arm for one activation vector; write state.json and VTU files."""
        from rich.console import Console

        from persival.model.arm import ArmModel
        from persival.model.arm_file import ModelFileError
        from persival.model.output import write_state
        from persival.model.solver import ConvergenceError

        console = Console()
        alpha = parse_activations(activations)
        try:
            ArmModel.validate_activations(alpha)
            with console.status("meshing the arm (gmsh)"):
                arm = ArmModel(model, profile)
            with console.status("solving the hanging arm (activations 0)"):
                arm.base_state()
            with console.status(f"solving activations {alpha}"):
                state = arm.solve(alpha)
        except (ModelFileError, ValueError) as exc:
            console.print(f"[red]error:[/red] {exc}")
            raise typer.Exit(2) from None
        except ConvergenceError as exc:
            console.print(f"[red]the FE solve did not converge:[/red] {exc}; nothing was written")
            raise typer.Exit(3) from None
        write_state(arm, state, out)
        console.print(
            f"elbow angle [bold]{state.elbow_angle_deg:.2f} deg[/bold], moment residual {state.moment_residual:.2e} N mm, "
            f"{state.statistics['iterations']} Newton iterations, {state.wall_time_s:.1f} s, max |J-1| {state.max_volume_change:.2e}"
        )
        console.print(f"wrote {out}/state.json and VTU files (open {out}/*.vtu in ParaView)")
