"""Small helpers for timing and for PyTorch's thread count.

On a 2-core machine that runs anything else, PyTorch's default of one thread per core makes
every small operation wait for the busy core (10x slower training measured here), so the
evaluation stage computes with one thread and the benchmark says which count it timed.
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import numpy as np

__all__ = ["torch_threads", "blas_threads", "time_calls"]


@contextmanager
def torch_threads(n: int):
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(int(n))
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _openblas_controls():
    """(get, set) of the OpenBLAS that numpy loaded, through ctypes, or None (no threadpoolctl here)."""
    import ctypes

    try:
        with open("/proc/self/maps") as maps:
            libs = sorted({line.split()[-1] for line in maps if "openblas" in line.lower() and line.split()[-1].startswith("/")})
    except OSError:
        return None
    for path in libs:
        lib = ctypes.CDLL(path)
        for suffix in ("64_", ""):
            for prefix in ("scipy_openblas", "openblas"):
                get, put = f"{prefix}_get_num_threads{suffix}", f"{prefix}_set_num_threads{suffix}"
                if hasattr(lib, get) and hasattr(lib, put):
                    return getattr(lib, get), getattr(lib, put)
    return None


@contextmanager
def blas_threads(n: int):
    """numpy's BLAS with ``n`` threads inside the block (a no-op where it cannot be controlled)."""
    controls = _openblas_controls()
    if controls is None:
        yield
        return
    get, put = controls
    before = int(get())
    put(int(n))
    try:
        yield
    finally:
        put(before)


def time_calls(fn, reps: int = 1000, warmup: int = 20, budget_s: float | None = None) -> dict:
    """Mean and median seconds per call after ``warmup`` untimed calls.

    ``budget_s``: fewer repetitions (at least 50) when ``reps`` calls would take longer; the
    count used is returned as ``calls``.
    """
    t0 = time.perf_counter()
    for _ in range(warmup):
        fn()
    per_call = (time.perf_counter() - t0) / max(warmup, 1)
    if budget_s is not None and per_call * reps > budget_s:
        reps = max(50, int(budget_s / max(per_call, 1e-9)))
    times = np.empty(reps)
    for k in range(reps):
        t = time.perf_counter()
        fn()
        times[k] = time.perf_counter() - t
    return {"mean_s": float(times.mean()), "median_s": float(np.median(times)), "calls": int(reps)}
