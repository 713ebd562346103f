"""`persival bench serve`: a loopback WebSocket load test of the inference server.

The server runs as its own process (`persival serve`), as it would in use, so its peak memory
is its own and the clients' JSON decoding does not share its interpreter. Each client keeps one
request in flight at a time at a fixed rate (a viewer frame clock), and every `bad_every`-th
request is malformed: it must come back as an error reply and the good ones around it must not
be disturbed. Counts and duration are bounded so the benchmark cannot flood the machine.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["LoadTestError", "LoadResult", "run_load_test", "MAX_CLIENTS", "MAX_RATE", "MAX_DURATION_S"]

MAX_CLIENTS, MAX_RATE, MAX_DURATION_S = 64, 240.0, 120.0
_BAD = ['{"activations": [0, 0, 0, 0, 2]}', "not json", '{"angle_deg": 1e9}', '{"activations": "x"}',
        '{"activations": [0, 0, 0, 0, 0], "extra": 1}']


class LoadTestError(RuntimeError):
    """The server under test could not be started."""


@dataclass
class LoadResult:
    clients: int
    rate_per_client: float
    duration_s: float
    encoding: str = "binary"
    latencies_ms: list = field(default_factory=list)
    good: int = 0
    bad_sent: int = 0
    bad_refused: int = 0
    errors: list = field(default_factory=list)
    peak_rss_mb: float = 0.0
    wall_s: float = 0.0

    def summary(self) -> dict:
        lat = np.asarray(self.latencies_ms) if self.latencies_ms else np.array([np.nan])
        return {"clients": self.clients, "rate_per_client": self.rate_per_client, "duration_s": self.duration_s,
                "encoding": self.encoding, "offered_per_s": self.clients * self.rate_per_client,
                "states": self.good, "states_per_s": self.good / self.wall_s if self.wall_s else 0.0,
                "p50_ms": float(np.percentile(lat, 50)), "p99_ms": float(np.percentile(lat, 99)),
                "max_ms": float(lat.max()), "bad_sent": self.bad_sent, "bad_refused": self.bad_refused,
                "errors": len(self.errors), "first_errors": self.errors[:5], "server_peak_rss_mb": self.peak_rss_mb}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _good_reply(reply, n: int) -> bool:
    if isinstance(reply, bytes):  # binary: the id leads the header (protocol.BINARY_HEADER)
        return len(reply) > 28 and int.from_bytes(reply[:4], "little") == n
    reply = json.loads(reply)
    return reply.get("id") == n and "muscles" in reply


async def _client(url: str, k: int, rate: float, until: float, bad_every: int, res: LoadResult) -> None:
    import websockets

    period, n = 1.0 / rate, 0
    async with websockets.connect(url, max_size=2**24) as ws:
        next_t = time.perf_counter()
        while time.perf_counter() < until:
            await asyncio.sleep(max(0.0, next_t - time.perf_counter()))
            # a late reply skips the slots it missed (a frame clock does not burst to catch up)
            next_t = max(next_t + period, time.perf_counter())
            n += 1
            bad = bad_every > 0 and (n + k) % bad_every == 0
            alpha = [round((np.sin(0.05 * n + j + k) + 1) / 2, 6) for j in range(5)]
            msg = _BAD[(n + k) % len(_BAD)] if bad else json.dumps({"id": n, "activations": alpha,
                                                                     "encoding": res.encoding})
            t0 = time.perf_counter()
            await ws.send(msg)
            raw = await ws.recv()
            dt = (time.perf_counter() - t0) * 1e3
            if bad:
                reply = json.loads(raw) if isinstance(raw, str) else {}
                res.bad_sent += 1
                ok = 400 <= int(reply.get("status", 0)) < 500 and "error" in reply
                res.bad_refused += ok
                if not ok:
                    res.errors.append(f"client {k}: bad request {msg!r} was answered {str(reply)[:80]}")
            elif _good_reply(raw, n):
                res.good += 1
                res.latencies_ms.append(dt)
            else:
                res.errors.append(f"client {k}: request {n} got {str(raw)[:120]}")


async def _sample_rss(pid: int, res: LoadResult, stop: asyncio.Event) -> None:
    import psutil

    proc = psutil.Process(pid)
    while not stop.is_set():
        res.peak_rss_mb = max(res.peak_rss_mb, proc.memory_info().rss / 2**20)
        await asyncio.sleep(0.1)


def _start_server(artifacts: Path, port: int, quiet: bool = False) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "persival.cli", "serve", "--artifacts", str(artifacts), "--port", str(port),
           "--log-level", "warning"]
    out = subprocess.DEVNULL if quiet else None  # quiet: the caller prints its own table
    proc = subprocess.Popen(cmd, env={**os.environ, "PYTHONUNBUFFERED": "1"}, stdout=out, stderr=out)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise LoadTestError(f"the server exited with {proc.returncode} before it listened")
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return proc
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise LoadTestError("the server did not listen within 60 s")


async def _run(url: str, pid: int, res: LoadResult, bad_every: int) -> None:
    stop = asyncio.Event()
    sampler = asyncio.create_task(_sample_rss(pid, res, stop))
    t0 = time.perf_counter()
    until = t0 + res.duration_s
    tasks = [_client(url, k, res.rate_per_client, until, bad_every, res) for k in range(res.clients)]
    outcomes = await asyncio.gather(*tasks, return_exceptions=True)
    res.wall_s = time.perf_counter() - t0
    res.errors += [f"client {k}: {type(o).__name__}: {o}" for k, o in enumerate(outcomes) if isinstance(o, Exception)]
    stop.set()
    await sampler


def run_load_test(artifacts: str | Path, clients: int = 8, rate: float = 60.0, duration_s: float = 10.0,
                  bad_every: int = 25, encoding: str = "binary") -> LoadResult:
    """Start a server on a free loopback port, load it, stop it; raises ValueError on bad bounds."""
    if not 1 <= clients <= MAX_CLIENTS or not 1 <= rate <= MAX_RATE or not 1 <= duration_s <= MAX_DURATION_S:
        raise ValueError(f"need 1 <= clients <= {MAX_CLIENTS}, 1 <= rate <= {MAX_RATE}, "
                         f"1 <= duration <= {MAX_DURATION_S} s")
    from persival.deploy.artifacts import DeployedModel

    DeployedModel(artifacts)  # a broken folder is reported here, not as a server that never listens
    port = _free_port()
    proc = _start_server(Path(artifacts), port)
    if encoding not in ("binary", "json"):
        raise ValueError("encoding must be 'binary' (what the viewer uses) or 'json'")
    res = LoadResult(clients, float(rate), float(duration_s), encoding)
    try:
        asyncio.run(_run(f"ws://127.0.0.1:{port}/ws", proc.pid, res, bad_every))
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
    return res
