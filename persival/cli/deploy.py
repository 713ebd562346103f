"""CLI commands of the deploy stage's server: `persival serve` and `persival bench serve`."""

from __future__ import annotations

import ipaddress
import json
from pathlib import Path

import typer


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def serve(
    artifacts: Path = typer.Option(..., "--artifacts", help="Export folder (metadata.json + ONNX models)."),
    host: str = typer.Option("127.0.0.1", "--host", help="Address to bind; loopback unless you mean to share it."),
    port: int = typer.Option(8000, "--port", min=0, max=65535, help="TCP port."),
    log_level: str = typer.Option("info", "--log-level", help="uvicorn log level."),
) -> None:
    """Serve the web viewer, the exported models and the inference API (REST + WebSocket)."""
    import uvicorn
    from rich.console import Console

    from persival.cli.errors import user_errors
    from persival.deploy.artifacts import ArtifactError
    from persival.deploy.server import WEB_DIST, create_app

    console = Console(stderr=True)
    with user_errors(ArtifactError):
        web_app = create_app(artifacts)
    if not _is_loopback(host):
        console.print(f"[yellow]warning:[/yellow] binding {host}: the server is reachable from other machines")
    if not (WEB_DIST / "index.html").is_file():
        console.print("[yellow]warning:[/yellow] the web viewer is not built (`make web`); serving the API only")
    console.print(f"PerSival viewer: http://{host}:{port}/  (artifacts {Path(artifacts).resolve()})")
    # ws_max_size bounds a WebSocket message before it is buffered; the app bounds it again.
    uvicorn.run(web_app, host=host, port=port, log_level=log_level, ws_max_size=65536,
                limit_concurrency=256, timeout_keep_alive=5, h11_max_incomplete_event_size=16384)


def export(
    network: Path = typer.Option(..., "--network", help="Trained network folder (persival train) or structured "
                                 "surrogate folder (persival surrogate fit-structured)."),
    out: Path = typer.Option(..., "--out", help="Export folder (ONNX tiers + metadata.json); replaced if it exists."),
    activation_model: Path = typer.Option(None, "--activation-model", help="activation_model.json (persival inverse --out)."),
) -> None:
    """Export a trained network (float32, float16, int8) or the structured surrogate (float32) to ONNX with metadata.json."""
    from persival.cli.errors import check_output_dir, user_errors
    from persival.deploy.export import export_model
    from persival.surrogate.activation_model import AngleActivationModel
    from persival.surrogate.open import load_surrogate

    with user_errors():
        check_output_dir(out)
        surrogate = load_surrogate(network)
        if not hasattr(surrogate, "deployable"):
            raise ValueError(f"{network} holds a {surrogate.kind} surrogate; export takes a trained network or a "
                             "structured surrogate")
        model = AngleActivationModel.load(activation_model) if activation_model is not None else None
        meta = export_model(surrogate, out, activation_model=model)
    for tier, v in meta["models"]["deformation"]["variants"].items():
        typer.echo(f"{tier:8s} {v['file']:26s} {v['bytes'] / 1e6:6.3f} MB  |ONNX - torch| <= "
                   f"{v['max_abs_diff_vs_torch']['positions']:.1e} mm")
    typer.echo(f"wrote {out}/metadata.json ({meta['n_nodes']} nodes); serve it: persival serve --artifacts {out}")


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


def register(app: typer.Typer, bench_app: typer.Typer, motion_app: typer.Typer | None = None) -> None:
    """Attach `export` and `serve` to the main app, `serve` and `viewer` to the benchmark group and
    `play` to the `motion` group."""
    app.command("export")(export)
    app.command("serve")(serve)
    if motion_app is not None:
        motion_app.command("play")(play)
    bench_app.command("viewer")(bench_viewer)
    bench_app.command("serve")(bench_serve)


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
