"""`persival bench ...`: every speed benchmark in one place (each prints a table; the measuring
code lives with what it measures: persival.evaluate.bench_* and persival.deploy.bench_*)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from persival.cli.errors import check_output_dir, check_output_file, user_errors


def register(bench_app: typer.Typer) -> None:
    """Attach the benchmarks to ``persival bench``."""
    bench_app.command("fe")(bench_fe)
    bench_app.command("arm")(bench_arm)
    bench_app.command("deployed")(bench_deployed)
    bench_app.command("sg")(bench_sg)
    bench_app.command("nn")(bench_nn)
    bench_app.command("serve")(bench_serve)
    bench_app.command("viewer")(bench_viewer)


def bench_fe(
    mesh_size: float = typer.Option(6.3, min=1.0, help="Element size of the 40 x 300 mm spindle (mm)."),
    activation: float = typer.Option(1.0, min=0.0, max=1.0, help="Activation of the benchmark state."),
    repeats: int = typer.Option(5, min=1, help="Repetitions per timing (best is kept)."),
    backend: str = typer.Option("auto", help="Sparse solver: auto, pardiso or scipy."),
) -> None:
    """Newton iteration vs sparse factorization on the paper-size spindle (target ratio <= 1.5)."""
    from persival.cli.show import print_fe_benchmark
    from persival.evaluate.bench_fe import run_fe_benchmark
    from persival.model.fe.linear_solver import SparseSymmetricSolver

    with user_errors(RuntimeError):  # RuntimeError: pardiso asked for but not installed
        SparseSymmetricSolver(backend)  # an unknown backend fails here, before the meshing
        result = run_fe_benchmark(mesh_size, activation, repeats, backend)
    print_fe_benchmark(result)


def bench_arm(
    profile: str = typer.Option("quick", "--profile", help="Mesh profile of the built-in arm."),
    states: int = typer.Option(10, "--states", min=1, help="Random activation vectors for the per-state timings."),
    direct: int = typer.Option(0, "--direct", min=0, help="Of those, also solve this many by the direct coupled solve "
                               "(minutes each) and compare."),
    campaign_level: int = typer.Option(2, "--campaign-level", min=0, max=3,
                                       help="Run a sparse-grid campaign of this level through the runner (0: none)."),
    out: Path | None = typer.Option(None, "--out", help="Also write the figures as JSON here."),
) -> None:
    """The FE arm at campaign scale: response tables, exact and table-only states, a campaign."""
    import json

    from rich.console import Console

    from persival.cli.show import print_arm_benchmark
    from persival.evaluate.bench_arm import run_arm_benchmark
    from persival.model.arm.model_file import load_model_file

    with user_errors():
        load_model_file()[0].profile(profile)
        if out is not None:
            check_output_file(out)
    console = Console()
    with console.status("FE arm benchmark") as status:
        result = run_arm_benchmark(profile, states, min(direct, states), campaign_level,
                                   progress=lambda text: status.update(f"FE arm benchmark: {text}"))
    print_arm_benchmark(result)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result, indent=1, default=float))
        console.print(f"wrote {out}")


def bench_deployed(
    run: Path = typer.Option(Path("results"), "--run", help="Run folder (persival run --out) of the FE arm."),
    states: int = typer.Option(200, "--states", min=1, help="Random activation vectors solved by the exact FE path."),
    seed: int = typer.Option(11, "--seed", help="Seed of the random activations (another than the run's held-out)."),
) -> None:
    """Every surrogate of a run against N more exact FE states (a resumable store under RUN/bench/)."""
    import json

    from persival.cli.show import print_deployed_benchmark
    from persival.evaluate.bench_deployed import run_deployed_benchmark

    with user_errors():
        result = run_deployed_benchmark(run, states, seed)
    markdown = print_deployed_benchmark(result)
    folder = Path(run) / "bench"
    (folder / "deployed.json").write_text(json.dumps(result, indent=1, default=float))
    (folder / "deployed.md").write_text(markdown)
    typer.echo(f"wrote {folder / 'deployed.json'} and {folder / 'deployed.md'}")


def bench_sg(
    dim: int = typer.Option(5, min=1, help="Input dimension (activations)."),
    level: int = typer.Option(2, min=1, help="Regular sparse-grid level."),
    degree: int = typer.Option(3, min=1, help="Odd B-spline degree."),
    n_out: int = typer.Option(2809 * 3 + 1, min=1, help="Outputs per state (surface xyz + angle)."),
    batch: int = typer.Option(1000, min=1, help="Large batch size."),
    reps: int = typer.Option(300, min=1, help="Repetitions at batch 1 (after warmup)."),
) -> None:
    """Seconds per whole-surface state of the sparse-grid surrogate, batch 1 and large batch."""
    from persival.cli.show import print_sg_benchmark
    from persival.evaluate.bench_sparse_grid import run_benchmark

    with user_errors():
        result = run_benchmark(dim=dim, level=level, degree=degree, n_out=n_out, batch=batch, reps_single=reps)
    print_sg_benchmark(result)


def bench_nn(
    run: Path = typer.Option(Path("results"), "--run", help="Run folder written by `persival run --out`."),
    reps: int = typer.Option(1000, "--reps", min=10, help="Calls per row (after warm-up)."),
    budget: float = typer.Option(4.0, "--budget", min=0.1, help="Seconds per row at most (then fewer calls)."),
    peer: bool = typer.Option(True, "--peer/--no-peer", help="Time the Keras/TFLite peer if installed."),
) -> None:
    """Speed of every network variant, the deployed ONNX tiers and the SG: RUN/evaluate/bench_nn.*"""
    from rich.console import Console

    from persival.campaign.store import StoreError
    from persival.cli.show import to_rich
    from persival.evaluate.bench_nn import TERMINAL_COLUMNS
    from persival.evaluate.evaluation import run_bench
    from persival.evaluate.run_layout import RunLayout

    console = Console()
    layout = RunLayout(run)
    with user_errors(StoreError, out=layout.evaluate):
        layout.check()
        check_output_dir(layout.evaluate)
        table = run_bench(run, progress=True, reps=reps, budget_s=budget, peer=peer, console=console)
    console.print(to_rich(table, TERMINAL_COLUMNS))
    for note in table["notes"]:
        console.print(f"  {note}", markup=False)
    console.print(f"wrote {layout.evaluate / 'bench_nn.md'} (every column) and {layout.evaluate / 'bench_nn.json'}")


def bench_serve(
    artifacts: Path = typer.Option(..., "--artifacts", help="Export folder to serve."),
    clients: int = typer.Option(8, "--clients", min=1, max=64, help="Concurrent WebSocket clients."),
    rate: float = typer.Option(60.0, "--rate", min=1, max=240, help="States per second per client."),
    duration: float = typer.Option(10.0, "--duration", min=1, max=120, help="Seconds of load."),
    bad_every: int = typer.Option(25, "--bad-every", min=0, help="Every k-th request is malformed (0: none)."),
    encoding: str = typer.Option("binary", "--encoding", help="Reply encoding: binary (the viewer's) or json."),
    json_out: Path = typer.Option(None, "--json", help="Also write the figures to this file."),
) -> None:
    """Load-test the server on loopback: N WebSocket clients at M states/s; latency, throughput, errors."""
    import json

    from rich.console import Console
    from rich.table import Table

    from persival.cli.errors import user_errors
    from persival.deploy.artifacts import ArtifactError
    from persival.deploy.bench_serve import LoadTestError, run_load_test

    console = Console()
    with user_errors(ArtifactError, LoadTestError):
        summary = run_load_test(artifacts, clients, rate, duration, bad_every, encoding).summary()
    table = Table(title=f"persival serve: {clients} clients x {rate:g} states/s, {duration:g} s, {encoding}")
    table.add_column("what")
    table.add_column("value", justify="right")
    for key in ("offered_per_s", "states", "states_per_s", "p50_ms", "p99_ms", "max_ms", "bad_sent", "bad_refused",
                "errors", "server_peak_rss_mb"):
        value = summary[key]
        table.add_row(key, f"{value:.3g}" if isinstance(value, float) else str(value))
    console.print(table)
    for line in summary["first_errors"]:
        console.print(f"[red]{line}[/red]")
    if json_out:
        json_out.write_text(json.dumps(summary, indent=2))
    if summary["errors"]:
        raise typer.Exit(1)


def bench_viewer(
    artifacts: Path = typer.Option(Path("results/export"), "--artifacts", help="Export folder to view."),
    seconds: float = typer.Option(8.0, "--seconds", min=1.0, max=60.0, help="Measured seconds per phase."),
    width: int = typer.Option(1280, "--width", min=320, max=3840, help="Window width, px."),
    height: int = typer.Option(800, "--height", min=240, max=2160, help="Window height, px."),
    trace: bool = typer.Option(True, "--trace/--no-trace", help="Record a Chrome trace of the shipped phase."),
    json_out: Path = typer.Option(None, "--json", help="Also write the result to this file."),
    screenshot: Path = typer.Option(None, "--screenshot", help="Also save the default view as a PNG (the report "
                                    "shows RUN/evaluate/viewer.png)."),
) -> None:
    """Frame rate of the web viewer in headless Chromium (software GL) while the arm moves every
    frame, with the frame's profile (the page's own timings and a Chrome trace per thread)."""
    from rich.console import Console
    from rich.table import Table

    from persival.cli.errors import check_output_file, user_errors
    from persival.deploy.artifacts import ArtifactError
    from persival.deploy.bench_viewer import ViewerBenchError, run_viewer_bench

    with user_errors(ArtifactError, ViewerBenchError):
        for path, what in ((json_out, "--json"), (screenshot, "--screenshot")):
            if path is not None:
                check_output_file(path, what)
        result = run_viewer_bench(artifacts, seconds, width, height, trace, screenshot=screenshot)
    console = Console()
    table = Table(title=f"viewer, headless Chromium {result.get('chromium', '')}, software GL, {width} x {height}, "
                        f"{result['export']['n_nodes']} nodes; load average {result['machine']['load_average'][0]:.1f}")
    for col in ("phase", "fps", "CPU ms / frame", "render scale", "JS ms / state", "JS ms / frame"):
        table.add_column(col, justify="left" if col == "phase" else "right")
    for p in result["phases"]:
        js_state = sum(p["perState"].values())
        table.add_row(p["phase"], f"{p['fps']:.1f}", f"{p['cpuMsPerFrame']:.1f}", f"{p['renderScale']:.2f}",
                      f"{js_state:.2f}", f"{p['perFrame']['tickMs']:.2f}")
    console.print(table)
    for t in result["phases"][0].get("trace", []):
        top = "; ".join(f"{e['name']} {e['msPerFrame']:.2f}" for e in t["top"][:3])
        console.print(f"  {t['thread']}: busy {t['busyMsPerFrame']:.2f} ms/frame ({top})", markup=False)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(result, indent=1))
        console.print(f"wrote {json_out}")
    if screenshot is not None:
        console.print(f"wrote {screenshot}")
