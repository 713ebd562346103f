"""`persival bench viewer`: the web viewer's frame rate in headless Chromium, and where the time goes.

The export is served on loopback (`persival serve`, its own process), Chromium opens the page at
the given window size with software GL (SwiftShader, `--disable-gpu`), starts the flexion-
extension cycle (the angle, the state and every vertex change every frame) and measures two
phases after a warm-up: the page as shipped (its resolution adapting to the frame rate) and at
full resolution. Per phase: frames per second, the CPU time of all Chromium processes per frame
(the work, which hardly depends on what else the machine runs), the page's own breakdown (JS per
state and per frame) and, for the shipped phase, a Chrome trace summarised per thread.
The browser side is persival/deploy/web/bench.mjs (playwright-core from the viewer's npm setup).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

from persival.deploy.bench_serve import LoadTestError, _free_port, _start_server
from persival.deploy.server import WEB_DIST

__all__ = ["ViewerBenchError", "run_viewer_bench", "CHROMIUM"]

CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")
_SCRIPT = WEB_DIST.parent / "bench.mjs"


class ViewerBenchError(RuntimeError):
    """The benchmark cannot run here (no browser, no built viewer) or the page failed."""


def _check_tools() -> None:
    missing = [what for what, ok in [
        (f"Chromium at {CHROMIUM} (apt-get install chromium, or set CHROMIUM)", Path(CHROMIUM).exists()),
        ("node (apt-get install nodejs)", shutil.which("node") is not None),
        ("the built viewer (make web)", (WEB_DIST / "index.html").is_file()),
        ("playwright-core (make web: npm ci in persival/deploy/web)",
         (WEB_DIST.parent / "node_modules" / "playwright-core").is_dir())] if not ok]
    if missing:
        raise ViewerBenchError(f"bench viewer needs {', '.join(missing)}")


def run_viewer_bench(artifacts: str | Path, seconds: float = 8.0, width: int = 1280, height: int = 800,
                     trace: bool = True, warmup: float = 3.0, screenshot: str | Path | None = None) -> dict:
    """Serve the export, drive the page, return the browser script's result (see the module doc)."""
    from persival.deploy.artifacts import DeployedModel

    model = DeployedModel(artifacts)  # an unservable folder is an ArtifactError before any browser starts
    _check_tools()
    port = _free_port()
    try:
        server = _start_server(Path(artifacts), port, quiet=True)
    except LoadTestError as exc:
        raise ViewerBenchError(str(exc)) from None
    options = {"url": f"http://127.0.0.1:{port}/", "seconds": seconds, "width": width, "height": height,
               "trace": trace, "warmup": warmup, "screenshot": str(Path(screenshot).resolve()) if screenshot else None}
    try:
        proc = subprocess.run(["node", str(_SCRIPT), json.dumps(options)], capture_output=True, text=True,
                              timeout=120 + 3 * (seconds + warmup), cwd=_SCRIPT.parent)
    finally:
        server.terminate()
        server.wait(timeout=30)
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        raise ViewerBenchError(f"the browser script failed: {(proc.stderr or proc.stdout)[-500:]}")
    result = json.loads(lines[-1])
    if not result.get("ok"):
        raise ViewerBenchError(f"the page failed: {str(result.get('error'))[:500]}")
    result["export"] = {"folder": str(model.folder), "n_nodes": model.n_nodes,
                        "architecture": model.metadata["models"]["deformation"].get("architecture")}
    result["machine"] = {"cpus": os.cpu_count(), "load_average": list(os.getloadavg())}
    return result
