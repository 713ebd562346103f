"""Speed of the sparse-grid surrogate on the paper's configuration (docs/theory.md, 5.4; target in docs/benchmarks.md).

d = 5 activations, regular level 2, cubic B-splines: 1053 grid points; one "state" is the
whole biceps surface (2809 nodes x 3 coordinates) plus the elbow angle = 8428 outputs.
Random outputs suffice: evaluation cost does not depend on the values.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from persival.surrogate.sparse_grid import SparseGrid

N_OUT_PAPER = 2809 * 3 + 1


@dataclass
class BenchRow:
    what: str
    dtype: str
    batch: int
    seconds_per_state: float  # mean over the repetitions
    median_seconds_per_state: float  # robust to other processes stealing the (shared) cores
    repetitions: int


@dataclass
class BenchResult:
    n_points: int
    n_out: int
    fit_factorize_s: float
    fit_solve_s: float
    rows: list[BenchRow]


def _time_per_call(fn, reps: int, warmup: int) -> tuple[float, float]:
    """(mean, median) seconds per call after ``warmup`` untimed calls."""
    for _ in range(warmup):
        fn()
    times = np.empty(reps)
    for k in range(reps):
        t0 = time.perf_counter()
        fn()
        times[k] = time.perf_counter() - t0
    return float(times.mean()), float(np.median(times))


def run_benchmark(
    dim: int = 5,
    level: int = 2,
    degree: int = 3,
    n_out: int = N_OUT_PAPER,
    batch: int = 1000,
    reps_single: int = 300,
    reps_batch: int = 5,
    seed: int = 0,
) -> BenchResult:
    """Fit timing (factorization, solve) and seconds per state at batch 1 and ``batch``."""
    rng = np.random.default_rng(seed)
    grid = SparseGrid(dim, level, degree)
    values = rng.standard_normal((grid.n_points, n_out))

    t0 = time.perf_counter()
    grid.factorize()  # timed apart from the solve: the factorization is shared by all outputs
    t1 = time.perf_counter()
    grid.fit(values)
    t2 = time.perf_counter()

    # Fresh points per call so no result is reused; pools are drawn before timing.
    pool1 = rng.random((reps_single + 50, 1, dim))
    poolb = rng.random((reps_batch + 2, batch, dim))
    rows: list[BenchRow] = []
    for dt in (np.float32, np.float64):
        grid.predict(pool1[0], dtype=dt)  # casts the coefficients once, outside the timing
        for what, fn in (("predict", grid.predict), ("gradient", grid.gradient)):
            it1 = iter(range(len(pool1)))
            s1, m1 = _time_per_call(lambda fn=fn, it=it1, dt=dt: fn(pool1[next(it)], dtype=dt), reps_single, 20)
            rows.append(BenchRow(what, np.dtype(dt).name, 1, s1, m1, reps_single))
            if what == "gradient":
                continue  # batch gradients are (batch, 8428, 5): memory, not a per-state story
            itb = iter(range(len(poolb)))
            sb, mb = _time_per_call(lambda fn=fn, it=itb, dt=dt: fn(poolb[next(it)], dtype=dt), reps_batch, 1)
            rows.append(BenchRow(what, np.dtype(dt).name, batch, sb / batch, mb / batch, reps_batch))
    return BenchResult(grid.n_points, n_out, t1 - t0, t2 - t1, rows)


