"""CLI commands of the deploy stage's server: `persival serve` and `persival bench serve`."""

from __future__ import annotations

import ipaddress
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


def register(app: typer.Typer) -> None:
    """Attach `export` and `serve` to the main app."""
    app.command("export")(export)
    app.command("serve")(serve)


