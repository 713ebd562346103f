"""Building the response tables: every unfinished column of each muscle, by continuation along
the elbow angle from the previous level's longest state, inline or one dask task per muscle
(docs/fe_tables.md)."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from persival.model.arm.muscle_state import MuscleState
from persival.model.arm.state_cache import mesh_fingerprint
from persival.tables.column_reuse import reuse_columns, table_headers
from persival.tables.continuation import sweep_muscle
from persival.tables.response_table import DEFAULT_ANGLES, DEFAULT_LEVELS, VERSION, ResponseTable, default_table_dir
from persival.vocabulary import MUSCLES

__all__ = ["build_muscle_columns", "build_response_table"]

log = logging.getLogger(__name__)


def _longest_state(table: ResponseTable, muscle: str, level: int) -> MuscleState | None:
    """A finished column's state at the muscle's longest table length (the next level's start)."""
    return table.state(muscle, int(np.argmax(table.lengths(muscle))), level)


def build_muscle_columns(model_file, profile: str, root: str, muscle: str) -> dict:
    """Compute every unfinished column of one muscle (a dask task, or inline). Returns timings."""
    from persival.model.arm.arm_model import ArmModel

    t0 = time.perf_counter()
    arm = ArmModel(model_file, profile)
    table = ResponseTable.open(root, arm.model_hash, arm.profile, mesh_fingerprint(arm.mesh))
    arm.load_cached_rest_states()  # each muscle's rest state from the state cache, when there
    spec = arm.spec.muscle(muscle)
    computed = 0
    start = None
    for j, a in enumerate(table.levels):
        if table.is_done(muscle, j):
            start = None
            continue
        if start is None and j > 0:
            start = _longest_state(table, muscle, j - 1)
        t1 = time.perf_counter()
        sweep = sweep_muscle(arm, spec, table.angles_deg, float(a), max_step_deg=10.0, start=start)
        table.write_column(muscle, j, sweep, time.perf_counter() - t1)
        start = sweep["longest_state"]
        computed += 1
    return {"muscle": muscle, "columns": computed, "seconds": time.perf_counter() - t0}


def build_response_table(arm, root: str | Path | None = None, angles=DEFAULT_ANGLES, levels=DEFAULT_LEVELS,
                         model_file=None, scheduler: str | None = None, n_workers: int | None = None,
                         progress=None, muscles=None, reuse_from=None) -> ResponseTable:
    """Build (or finish) the response tables of ``arm`` under ``root`` (default: the state cache).

    ``scheduler``: None starts a dask LocalCluster of ``n_workers`` single-threaded processes
    (default: one per core, at most one per muscle), ``"inline"`` computes here, an address uses
    a running cluster. ``progress(done_columns, total_columns)`` is called as columns finish.
    ``muscles``: compute only these muscles' columns (the others stay unfinished). A muscle whose
    columns another table holds under the same muscle key (persival.tables.column_reuse; by default
    any table in the cache, or the table folders ``reuse_from``) takes them over instead.
    """
    root = Path(root) if root is not None else default_table_dir(arm)
    table = ResponseTable.create_or_open(root, arm, angles, levels)
    asked = MUSCLES if muscles is None else muscles
    reused = reuse_columns(table, asked, table_headers(VERSION, reuse_from))
    if reused:
        log.info("columns taken over from tables with the same muscle keys: %s", reused)
    todo = [m for m in asked if not all(table.is_done(m, j) for j in range(len(table.levels)))]
    total = table.done.size

    def report():
        if progress is not None:
            progress(int(table.done.sum()), total)

    report()
    if not todo:
        return table
    model = str(model_file) if model_file is not None else None
    if scheduler == "inline":
        for muscle in todo:
            build_muscle_columns(model, arm.profile, str(root), muscle)
            report()
        return table
    _build_on_dask(table, todo, model, arm.profile, root, scheduler, n_workers, report)
    report()
    return table


def _build_on_dask(table, todo: list[str], model: str | None, profile: str, root: Path, scheduler: str | None,
                   n_workers: int | None, report) -> None:
    """One dask task per muscle (all of its columns), the largest muscles first."""
    from distributed import Client, wait

    from persival.cluster import available_cores, local_cluster

    cluster = None
    if scheduler is None:
        cluster = local_cluster(min(n_workers or available_cores(), len(todo)))
        client = Client(cluster)
    else:
        client = Client(scheduler, timeout="60s")
    try:
        # The largest muscles first, and never more tasks in flight than worker threads: a task
        # submitted ahead is placed at once, and dask put the short ones behind each other on
        # one worker while the biceps' worker idled at the end (105 s of a 307 s quick build).
        todo = sorted(todo, key=lambda m: -table.header["n_nodes"][m])
        slots = max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()))
        queue, pending, futures = list(todo), set(), []
        while queue or pending:
            while queue and len(pending) < slots:
                muscle = queue.pop(0)
                futures.append(client.submit(build_muscle_columns, model, profile, str(root), muscle,
                                             key=f"table-{muscle}", pure=False))
                pending.add(futures[-1])
            try:  # columns finish inside a task: the folder is polled for them
                _, pending = wait(pending, timeout=2.0, return_when="FIRST_COMPLETED")
            except TimeoutError:
                pass
            report()
        for f in futures:
            f.result()  # raise a worker's error here
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
