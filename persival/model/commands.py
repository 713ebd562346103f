"""CLI commands of the model (physics) stage."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli_errors import check_output_dir, user_errors
from persival.model.defaults import profiles_help
from persival.vocabulary import MUSCLES, N_ACTIVATIONS

ACTIVATIONS_HELP = f"{N_ACTIVATIONS} comma-separated activations in [0, 1], in the order {', '.join(MUSCLES)}; e.g. 0.5,0,0,0,0."


def parse_activations(text: str) -> list[float]:
    """The --activations option: malformed text is typer's usage error (the range: check_activations)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise typer.BadParameter(f"activations must be {N_ACTIVATIONS} comma-separated numbers, e.g. 0.5,0,0,0,0") from None
    if len(values) != N_ACTIVATIONS:
        raise typer.BadParameter(f"need {N_ACTIVATIONS} activations ({', '.join(MUSCLES)}), got {len(values)}")
    return values


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    """Attach this stage's commands to the main app and the benchmark group."""

    @app.command()
    def simulate(
        activations: str = typer.Option(..., "--activations", "-a", help=ACTIVATIONS_HELP),
        model: Path | None = typer.Option(None, "--model", help="Model file (TOML); default: the built-in arm."),
        profile: str = typer.Option("quick", "--profile", help=profiles_help()),
        out: Path = typer.Option(Path("results/simulate"), "--out", help="Output directory (state.json + VTU)."),
    ) -> None:
        """Solve the FE arm for one activation vector; write state.json and VTU files."""
        from rich.console import Console

        from persival.model.arm import ArmModel
        from persival.model.arm_file import load_model_file
        from persival.model.output import write_state
        from persival.model.progress import ConsoleProgress
        from persival.model.solver import ConvergenceError
        from persival.vocabulary import check_activation_vector

        console = Console()
        alpha = parse_activations(activations)
        with user_errors():  # every input is checked before the (minutes long) meshing and solve
            alpha = check_activation_vector(alpha).tolist()
            load_model_file(model)[0].profile(profile)
            check_output_dir(out)
        with user_errors(out=out):
            with console.status("meshing the arm (gmsh)"):
                arm = ArmModel(model, profile)
            with console.status("solving the hanging arm (activations 0)") as status, \
                    ConsoleProgress(console, status, "the hanging arm") as report:
                arm.base_state(progress=report)
            with console.status(f"solving activations {alpha}") as status, \
                    ConsoleProgress(console, status, f"activations {alpha}") as report:
                try:
                    state = arm.solve(alpha, progress=report)
                except ConvergenceError as exc:
                    typer.echo(f"error: the FE solve did not converge: {exc}; nothing was written", err=True)
                    raise typer.Exit(3) from None
            write_state(arm, state, out)
        console.print(
            f"elbow angle [bold]{state.elbow_angle_deg:.2f} deg[/bold], moment residual {state.moment_residual:.2e} N mm, "
            f"{state.statistics['iterations']} Newton iterations, {state.wall_time_s:.1f} s, "
            f"max |J-1| {state.max_volume_change:.2e}"
        )
        console.print(f"wrote {out}/state.json and VTU files (open {out}/*.vtu in ParaView)")
