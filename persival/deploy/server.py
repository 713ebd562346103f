"""The inference server: the web viewer, the export folder's files and the inference API.

`create_app(artifacts_dir)` returns a FastAPI app (`persival serve` runs it with uvicorn):

- ``GET /health``, ``POST /api/predict`` and the WebSocket ``/ws`` (requests: protocol.py);
- the WebSocket ``/ws/tracker``, a relay from a motion tracker to the pages (tracker_relay.py);
- ``GET /`` and the built viewer's files (persival/deploy/web/dist), ``GET /artifacts/<file>``.

Files are served from an allowlist made at start-up (every file of the built viewer, and the
artifact files metadata.json names), not by joining a request path to a folder: a path that
is not in the list is a 404 however it is spelled or encoded, so no traversal can reach
anything else on the machine.
"""

from __future__ import annotations

import asyncio
import mimetypes
from pathlib import Path

from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse

from persival.deploy import protocol
from persival.deploy.artifacts import DeployedModel
from persival.deploy.protocol import RequestError, TokenBucket
from persival.deploy.tracker_relay import add_tracker_relay

__all__ = ["create_app", "WEB_DIST", "ServerLimits"]

WEB_DIST = Path(__file__).resolve().parent / "web" / "dist"
_TYPES = {".wasm": "application/wasm", ".mjs": "text/javascript", ".js": "text/javascript",
          ".onnx": "application/octet-stream", ".json": "application/json", ".html": "text/html",
          ".css": "text/css", ".png": "image/png", ".svg": "image/svg+xml", ".map": "application/json",
          # the pose tracker's model and graph files (dist/mediapipe/)
          ".tflite": "application/octet-stream", ".binarypb": "application/octet-stream",
          ".data": "application/octet-stream"}
# Same-origin everything; 'wasm-unsafe-eval' lets onnxruntime-web compile its WebAssembly.
_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Opener-Policy": "same-origin",
    "Cross-Origin-Embedder-Policy": "require-corp",
    "Content-Security-Policy": ("default-src 'self'; script-src 'self' 'wasm-unsafe-eval'; "
                                "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
                                "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"),
}


class ServerLimits:
    """Request bounds; the defaults leave room for a viewer at 120 states/s per connection."""

    def __init__(self, max_body_bytes: int = 4096, http_rate: float = 500.0, http_burst: float = 200.0,
                 ws_rate: float = 300.0, ws_burst: float = 100.0, max_ws_clients: int = 64) -> None:
        self.max_body_bytes = max_body_bytes
        self.http_rate, self.http_burst = http_rate, http_burst
        self.ws_rate, self.ws_burst = ws_rate, ws_burst
        self.max_ws_clients = max_ws_clients


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message, "status": status}, status_code=status)


def _allowlist(model: DeployedModel, web_dir: Path | None) -> dict[str, Path]:
    files = {f"/artifacts/{name}": path for name, path in model.files().items()}
    if web_dir is not None and web_dir.is_dir():
        for path in sorted(web_dir.rglob("*")):
            if path.is_file() and not path.is_symlink():
                files["/" + path.relative_to(web_dir).as_posix()] = path
        if "/index.html" in files:
            files["/"] = files["/index.html"]
    return files


async def _read_body(request: Request, limit: int) -> bytes:
    declared = request.headers.get("content-length")
    if declared is not None and (not declared.isdigit() or int(declared) > limit):
        raise RequestError(413, f"request body larger than {limit} bytes")
    body = bytearray()
    async for chunk in request.stream():  # chunked bodies have no length: count as they come
        body += chunk
        if len(body) > limit:
            raise RequestError(413, f"request body larger than {limit} bytes")
    return bytes(body)


def _reply(payload: dict, model: DeployedModel):
    activations, load, tier, echo = protocol.parse_request(payload, model)
    positions, angle = protocol.answer(activations, load, tier, model)
    if echo["encoding"] == "binary":
        return protocol.encode_binary(activations, positions, angle, echo)
    return protocol.encode_json(activations, positions, angle, tier, model, echo)


def _add_http_routes(app: FastAPI, model: DeployedModel, limits: ServerLimits, files: dict) -> None:
    buckets: dict[str, TokenBucket] = {}

    @app.get("/health")
    def health() -> dict:
        meta = model.metadata
        return {"status": "ok", "n_nodes": model.n_nodes, "muscles": model.muscles, "tiers": model.tiers,
                "angle_range_deg": list(model.angle_range) if model.angle_range else None,
                "has_angle": model.has_angle, "motion": model.motion is not None,
                "max_load_kg": model.max_load_kg, "format_version": meta["format_version"]}

    @app.post("/api/predict")
    async def predict(request: Request):
        host = request.client.host if request.client else "?"
        if len(buckets) > 10_000:  # bounded memory if many addresses come and go
            buckets.clear()
        bucket = buckets.setdefault(host, TokenBucket(limits.http_rate, limits.http_burst))
        try:
            if not bucket.take():
                raise RequestError(429, "too many requests; slow down")
            payload = protocol.decode(await _read_body(request, limits.max_body_bytes), limits.max_body_bytes)
            if payload.get("encoding", "json") != "json":
                raise RequestError(422, "encoding 'binary' is for the WebSocket only")
            return _reply(payload, model)
        except RequestError as exc:
            return _error(exc.status, str(exc))

    @app.get("/{path:path}")
    def static(path: str, request: Request):
        target = files.get(request.url.path)
        if target is None:
            if request.url.path == "/":
                return _error(503, "the web viewer is not built: run `make web`")
            return _error(404, "not found")
        suffix = target.suffix.lower()
        return FileResponse(target, media_type=_TYPES.get(suffix) or mimetypes.guess_type(target.name)[0])


async def _serve_socket(ws: WebSocket, model: DeployedModel, limits: ServerLimits) -> None:
    bucket = TokenBucket(limits.ws_rate, limits.ws_burst)
    while True:
        message = await ws.receive()
        if message["type"] == "websocket.disconnect":
            return
        data = message.get("text") if message.get("text") is not None else message.get("bytes")
        try:
            if not bucket.take():
                raise RequestError(429, "too many requests on this connection; slow down")
            reply = _reply(protocol.decode(data or "", limits.max_body_bytes), model)
        except RequestError as exc:
            await ws.send_json({"error": str(exc), "status": exc.status})
            continue
        if isinstance(reply, bytes):
            await ws.send_bytes(reply)
        else:
            await ws.send_json(reply)


def _add_socket(app: FastAPI, model: DeployedModel, limits: ServerLimits) -> None:
    clients = {"n": 0}

    @app.websocket("/ws")
    async def socket(ws: WebSocket) -> None:
        if clients["n"] >= limits.max_ws_clients:
            await ws.close(code=1013, reason="too many connections")
            return
        clients["n"] += 1
        await ws.accept()
        try:
            await _serve_socket(ws, model, limits)
        except (WebSocketDisconnect, asyncio.CancelledError):
            pass
        finally:
            clients["n"] -= 1


def create_app(artifacts_dir: str | Path, web_dir: str | Path | None = WEB_DIST,
               limits: ServerLimits | None = None) -> FastAPI:
    """The server app for one export folder; raises ArtifactError if the folder cannot be served."""
    model = DeployedModel(artifacts_dir)
    limits = limits or ServerLimits()
    app = FastAPI(title="PerSival inference server", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.model = model

    @app.middleware("http")
    async def security_headers(request: Request, call_next):
        response = await call_next(request)
        response.headers.update(_HEADERS)
        return response

    @app.exception_handler(Exception)
    async def internal(request: Request, exc: Exception):  # the server stays up; the client learns why
        return _error(500, f"internal error: {type(exc).__name__}")

    _add_socket(app, model, limits)
    add_tracker_relay(app)
    _add_http_routes(app, model, limits, _allowlist(model, Path(web_dir) if web_dir else None))
    return app
