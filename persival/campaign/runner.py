"""Running a campaign: every pending design point of a store, solved by a simulator, on dask or
in-process, each finished state written to the store as soon as it arrives.

Who writes: only the driver (this process). Workers return each state's outcome to it and the
driver writes it; so exactly one process has the store open for writing (enforced by the
store's lock), writes never race, and "written" means "in the store", whatever happens to the
workers afterwards. The price is that each state's surfaces travel once over the dask
connection (tens of kB to a few MB per state, negligible beside an FE solve).

Scheduling (persival.campaign.dask_chains): the pending points are laid along a short path
(``design.solve_order``) and cut into contiguous chains. The driver keeps one chain per worker thread in flight and submits a
chain's next state only when its previous one returned, pinned (softly) to the same worker, so
that worker's cached simulator can warm-start from its neighbour. A chain that moves to
another worker (the first died or was restarted) simply starts cold there.

Time limits: ``timeout_s`` bounds each attempt. The attempt runs in a helper thread; on timeout
the simulator's ``cancel()`` is called when it has one (the external-command simulator kills
its process group), the state is recorded as failed ("timeout ...") and not retried. An
in-process simulator without ``cancel()`` cannot be stopped from Python: on dask the worker
process is restarted by its nanny; in-process (``scheduler="inline"``) the attempt is abandoned
in a daemon thread and later states use a fresh simulator instance. A worker so stuck that it
cannot even report (a solve holding the GIL) is caught by the driver's backstop limit and
restarted. Without ``timeout_s`` nothing bounds a solve.
"""

from __future__ import annotations

import logging
import math
import time
import uuid
from pathlib import Path

import numpy as np

from persival.campaign.dask_chains import run_dask, state_tasks
from persival.campaign.design import Design, solve_order
from persival.campaign.execute import StateOutcome, solve_state
from persival.campaign.simulator import SimulatorSpec, cached_simulator, simulator_factory
from persival.campaign.store import CampaignStore

__all__ = ["run_campaign", "CampaignIncomplete", "INLINE"]

INLINE = "inline"
log = logging.getLogger(__name__)


class CampaignIncomplete(RuntimeError):
    """A campaign that must be complete (a sparse grid needs every state) has failed or missing
    states; its store is kept, and running it again retries them."""


def _check_args(design, spec, timeout_s, max_attempts, n_workers, chunk_size) -> None:
    if not isinstance(design, Design):
        raise TypeError(f"design must be a persival.campaign.design.Design, got {type(design).__name__}")
    if not isinstance(spec, SimulatorSpec):
        raise TypeError(f"spec must be a SimulatorSpec, got {type(spec).__name__}")
    if timeout_s is not None and not (isinstance(timeout_s, (int, float)) and timeout_s > 0
                                      and math.isfinite(timeout_s)):
        raise ValueError(f"timeout_s must be a positive number of seconds or None, got {timeout_s!r}")
    if isinstance(max_attempts, bool) or not isinstance(max_attempts, int) or max_attempts < 1:
        raise ValueError(f"max_attempts must be an integer >= 1, got {max_attempts!r}")
    if n_workers is not None and (not isinstance(n_workers, int) or n_workers < 1):
        raise ValueError(f"n_workers must be an integer >= 1, got {n_workers!r}")
    if chunk_size is not None and (not isinstance(chunk_size, int) or chunk_size < 1):
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")


def run_campaign(
    store_path: str | Path,
    design: Design,
    spec: SimulatorSpec,
    scheduler: str | None = None,
    n_workers: int | None = None,
    timeout_s: float | None = None,
    max_attempts: int = 3,
    retry_failed: bool = False,
    progress: bool = True,
    chunk_size: int | None = None,
) -> dict:
    """Solve every pending state of the campaign ``design`` x ``spec`` into ``store_path``.

    A new path creates the store; an existing store must belong to the same design and
    simulator (else CampaignMismatchError) and only its missing states (plus failed ones with
    ``retry_failed``) are computed. ``scheduler``: None starts a dask LocalCluster with
    ``n_workers`` single-threaded worker processes (default: one per available core), an
    address ("tcp://host:8786") uses an existing dask cluster, ``"inline"`` solves in this
    process without dask. Returns the store summary plus figures of this run.
    """
    _check_args(design, spec, timeout_s, max_attempts, n_workers, chunk_size)
    factory = simulator_factory(spec.kind)  # unknown kind: clear error before anything is written
    store = _open_or_create(Path(store_path), design, spec, factory)
    t0 = time.perf_counter()
    try:
        pending = _in_solve_order(store.pending(retry_failed), design)
        tally = {"done": 0, "failed": 0, "lost": 0}
        if len(pending):
            with _Progress(len(pending), enabled=progress) as bar:
                def record(outcome: StateOutcome) -> None:
                    _write(store, outcome)
                    tally["done" if outcome.ok else "failed"] += 1
                    bar.advance(tally)

                run = _run_inline if scheduler == INLINE else run_dask
                run(store, design, spec, factory, pending, record, tally, scheduler=scheduler,
                    n_workers=n_workers, timeout_s=timeout_s, max_attempts=max_attempts,
                    chunk_size=chunk_size)
        elapsed = time.perf_counter() - t0
        summary = store.summary()
        n_run = tally["done"] + tally["failed"]
        summary["this_run"] = {
            "computed": n_run, "done": tally["done"], "failed": tally["failed"],
            "lost": tally["lost"], "elapsed_s": elapsed,
            "states_per_hour": 3600.0 * n_run / elapsed if n_run and elapsed > 0 else None,
        }
        return summary
    finally:
        store.close()


def _open_or_create(store_path: Path, design: Design, spec: SimulatorSpec, factory) -> CampaignStore:
    """The store to write: an existing one checked against the campaign (read-only first, so a
    mismatch leaves it untouched, then again under the writer's lock), else a new one."""
    if not store_path.exists():
        return CampaignStore.create(store_path, design, spec, cached_simulator(spec, factory).reference())
    with CampaignStore.open(store_path) as existing:
        existing.check_matches(design, spec)
    store = CampaignStore.open_for_writing(store_path)
    try:
        store.check_matches(design, spec)
    except BaseException:
        store.close()
        raise
    return store


def _in_solve_order(pending: np.ndarray, design: Design) -> np.ndarray:
    """The pending states in the design's solve order (neighbours one after another)."""
    order = solve_order(design.points)
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    return pending[np.argsort(rank[pending], kind="stable")]


def _write(store: CampaignStore, o: StateOutcome) -> None:
    stats = dict(o.statistics)
    if o.worker:
        stats.setdefault("worker", o.worker)
    if o.ok:
        store.write_done(o.index, o.elbow_angle_deg, o.positions, stats, o.wall_time_s, o.attempts)
    else:
        store.write_failed(o.index, o.reason, stats, o.wall_time_s, o.attempts)


def _run_inline(store, design, spec, factory, pending, record, tally, *, timeout_s, max_attempts,
                **_ignored) -> None:
    # One chain along the whole path: every state can warm-start from the previous one.
    chain = uuid.uuid4().hex
    for task in state_tasks(design, pending, chain, timeout_s, max_attempts):
        outcome = solve_state(spec, factory, task)
        if outcome.hung:
            log.warning("state %d: a hung attempt is left running in a daemon thread "
                        "(in-process mode cannot stop it)", task.index)
        record(outcome)


class _Progress:
    """A progress bar with rate and ETA (persival.progress), or nothing."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total, self.enabled = total, enabled
        self._progress = None

    def __enter__(self) -> _Progress:
        if self.enabled:
            from persival.progress import progress_bar

            self._progress = progress_bar()
            self._progress.__enter__()
            self._task = self._progress.add_task("campaign", total=self.total, info="", rate_unit="states/h")
        return self

    def advance(self, tally: dict) -> None:
        if self._progress is not None:
            info = f"{tally['done']} done, {tally['failed']} failed"
            self._progress.update(self._task, advance=1, info=info)

    def __exit__(self, *exc) -> None:
        if self._progress is not None:
            self._progress.__exit__(*exc)
