"""`persival motion`: the motion-and-load activation model built from a moment table, and
`persival motion play`: a recorded movement played through a deployed export."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli.errors import check_output_dir, fail, user_errors
from persival.cli.help import FullHelpGroup
from persival.cli.values import parse_numbers


def register(app: typer.Typer) -> None:
    """Attach the `motion` group: building the model (its options), `motion play` (a recording)."""
    motion_app = typer.Typer(cls=FullHelpGroup, help="The motion-and-load activation model (docs/theory.md 6.4): build it "
                             "from a moment table (options below), or play a recorded movement (motion play).")
    app.add_typer(motion_app, name="motion")
    motion_app.callback(invoke_without_command=True)(motion)
    motion_app.command("play")(play)


def _loads(text: str) -> list[float]:
    return parse_numbers(text, "--loads", "kg", minimum=0.0)


def motion(
    ctx: typer.Context,
    table: Path = typer.Option(None, "--table", help="Moment table (persival moments --out)."),
    out: Path = typer.Option(None, "--out", help="Output folder: motion_model.json/.npz, motion_model.png, "
                             "activation_motion.onnx."),
    model: Path = typer.Option(None, "--model", help="Model file the table must belong to; default: $PERSIVAL_MODEL, "
                             "else the built-in arm."),
    angles: str = typer.Option("30,60,90,120", "--angles", help="Elbow angles (deg) of the printed table."),
    loads: str = typer.Option("0,1,2,5", "--loads", help="Hand loads (kg) of the printed table."),
) -> None:
    """The motion-and-load activation model from a moment table: build, plot, ONNX."""
    if ctx.invoked_subcommand is not None:
        return
    if table is None or out is None:
        fail("persival motion needs --table and --out (build the model), or a subcommand: motion play --input FILE")
    _build_motion(table, out, model, angles, loads)


def _build_motion(table: Path, out: Path, model: Path | None, angles: str, loads: str) -> None:
    import numpy as np
    from rich.console import Console

    from persival.model.arm.model_file import load_model_file
    from persival.surrogate.motion_model import MotionActivationModel
    from persival.surrogate.motion_plot import plot_motion_model
    from persival.tables.moment_table import MomentTable

    with user_errors(out=out):
        targets, masses = parse_numbers(angles, "--angles", "deg"), _loads(loads)
        if not np.isfinite(targets).all():
            raise ValueError(f"--angles must be finite, got {angles!r}")
        check_output_dir(out)
        spec, model_hash = load_model_file(model)
        model_ = MotionActivationModel.from_table(MomentTable.load(table, model_hash, complete=True), spec)
        rows = np.array([[t, 0.0, 0.0, m] for t in targets for m in masses])
        activations, feasible = model_.predict(rows)  # angles outside the range: a user error
        out.mkdir(parents=True, exist_ok=True)
        model_.save(out)
        entry = model_.export_onnx(out)
        plot = plot_motion_model(model_, out / "motion_model.png")
    _print_motion(Console(), model_, rows, activations, feasible, entry, plot)


def _print_motion(console, model, rows, activations, feasible, entry, plot) -> None:
    import numpy as np
    from rich.table import Table

    from persival.vocabulary import ABBREVIATIONS

    t = Table(title=f"least-effort activations, zero velocity and acceleration (range {model.range_deg[0]:.0f}-"
              f"{model.range_deg[1]:.0f} deg)")
    for col in ["angle", "load kg", "M_req N mm", *ABBREVIATIONS, "holds"]:
        t.add_column(col, justify="right")
    for r, a, ok, req in zip(rows, activations, feasible, model.required_moment(rows)):
        t.add_row(f"{r[0]:g}", f"{r[3]:g}", f"{req:.0f}", *[f"{v:.3f}" for v in a], "yes" if ok else "[red]no[/red]")
    console.print(t)
    angles = np.arange(np.ceil(model.range_deg[0] / 10) * 10, model.range_deg[1] + 1e-9, 10.0)
    held = model.holdable_load_kg(angles)
    console.print("holdable load (kg): " + ", ".join(f"{a:g} deg {h:.2f}" for a, h in zip(angles, held) if np.isfinite(h)))
    console.print(f"ONNX vs Python {entry['max_abs_diff_vs_python']:.1e}; wrote {plot} and the model files")


def play(
    input_: Path = typer.Option(..., "--input", help="Recorded movement: CSV (time s, elbow angle deg, optional "
                                "load kg) or OpenSim .mot / .sto."),
    out: Path = typer.Option(..., "--out", help="Output folder: activations.csv, motion.png, summary.json."),
    column: str = typer.Option(None, "--column", help="The elbow-angle column (default: found by name, e.g. "
                               "r_elbow_flex, elbow_flex_r, elbow_angle_deg)."),
    load: float = typer.Option(None, "--load", min=0.0, help="Load in the hand, kg, for every frame (default: the "
                               "file's load column, else 0)."),
    artifacts: Path = typer.Option(Path("results/export"), "--artifacts", help="Export folder (persival export)."),
) -> None:
    """Play a recorded elbow movement through the exported models: activations per frame, target vs
    achieved angle, frames clamped to the reachable range and frames whose load cannot be held."""
    from persival.cli.errors import check_output_dir, user_errors
    from persival.deploy.artifacts import ArtifactError, DeployedModel
    from persival.deploy.motion_play import play_recording, write_outputs
    from persival.deploy.recording import read_recording

    with user_errors(ArtifactError, out=out):
        recording = read_recording(input_, column)
        check_output_dir(out)
        model = DeployedModel(artifacts)
        frames, summary = play_recording(model, recording, load)
        files = write_outputs(out, frames, summary, model.muscles)
    peak = ", ".join(f"{m} {v:.2f}" for m, v in summary["peak_activations"].items())
    typer.echo(f"{summary['frames']} frames over {summary['duration_s']:.2f} s ({recording.column}, "
               f"{summary['input_frames']} in the file); {summary['frames_clamped']} clamped to "
               f"{summary['range_deg'][0]:.1f}-{summary['range_deg'][1]:.1f} deg; {summary['frames_not_holdable']} "
               f"where the muscles cannot hold the load")
    typer.echo(f"achieved vs target angle: max {summary['angle_error_deg']['max']:.2f} deg, mean "
               f"{summary['angle_error_deg']['mean']:.2f} deg; peak activations: {peak}")
    typer.echo(f"wrote {', '.join(str(f) for f in files)}")
