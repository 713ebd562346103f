"""Campaign states on dask: chains of neighbouring states, one per worker thread in flight, each
chain's next state submitted to the worker that solved its previous one (a warm start); crashed,
lost and hung states recorded or left missing, a hung worker restarted (the driver's backstop
beyond the per-attempt time limit). persival.campaign.runner writes what comes back."""

from __future__ import annotations

import logging
import math
import time
import uuid
from collections import deque

import numpy as np

from persival.campaign.design import Design, chunks
from persival.campaign.execute import StateOutcome, StateTask, solve_state
from persival.cluster import local_cluster

__all__ = ["run_dask", "state_tasks"]

# Driver-side backstop beyond the per-attempt limits (worker start-up, queueing, cancel grace).
_BACKSTOP_GRACE_S = 60.0
_POLL_S = 0.5
log = logging.getLogger(__name__)


def state_tasks(design: Design, indices, chain: str, timeout_s, max_attempts):
    for i in indices:
        yield StateTask(index=int(i), state_id=int(design.ids[i]),
                        activations=np.array(design.points[i]), chain=chain,
                        timeout_s=timeout_s, max_attempts=max_attempts)



def run_dask(store, design, spec, factory, pending, record, tally, *, scheduler, n_workers,
              timeout_s, max_attempts, chunk_size) -> None:
    from distributed import Client

    cluster = None
    if scheduler is None:
        cluster = local_cluster(n_workers)
        client = Client(cluster)
    else:
        if n_workers is not None:
            log.warning("n_workers is ignored with an existing scheduler (%s)", scheduler)
        client = Client(scheduler, timeout="60s")
    try:
        _drive(client, design, spec, factory, pending, record, tally, timeout_s=timeout_s,
               max_attempts=max_attempts, chunk_size=chunk_size)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _drive(client, design, spec, factory, pending, record, tally, *, timeout_s, max_attempts,
           chunk_size) -> None:
    client.wait_for_workers(1, timeout=120)
    slots = max(1, sum(client.nthreads().values()))
    if chunk_size is None:
        # About four chains per worker thread: long enough for warm starts to pay, short enough
        # to balance states of unequal cost across workers.
        n_chains = min(len(pending), 4 * slots)
    else:
        n_chains = math.ceil(len(pending) / chunk_size)
    run_id = uuid.uuid4().hex[:12]
    queue = deque(
        deque(state_tasks(design, piece, f"{run_id}-{k}", timeout_s, max_attempts))
        for k, piece in enumerate(chunks(pending, n_chains))
    )
    backstop = None if timeout_s is None else max_attempts * timeout_s + _BACKSTOP_GRACE_S
    _ChainDriver(client, spec, factory, queue, record, tally, max_attempts).run(slots, backstop)


class _ChainDriver:
    """Chains of neighbouring states on dask workers: a worker that finishes a state gets the next
    one of its chain (a warm start), then a new chain; crashed, lost and hung states are recorded
    or left missing, and a hung worker is restarted."""

    def __init__(self, client, spec, factory, queue: deque, record, tally: dict, max_attempts: int):
        self.client, self.spec, self.factory, self.queue = client, spec, factory, queue
        self.record, self.tally, self.max_attempts = record, tally, max_attempts
        self.active: dict = {}  # future -> (chain deque, submit time, task)

    def run(self, slots: int, backstop: float | None) -> None:
        from distributed import wait

        for _ in range(slots):
            if self.queue:
                self.submit(self.queue.popleft(), None)
        while self.active:
            try:
                done, _ = wait(list(self.active), timeout=_POLL_S, return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = set()
            for fut in done:
                self.collect(fut)
            if backstop is not None:
                self.stop_hung(backstop)

    def submit(self, chain: deque, worker: str | None) -> None:
        task = chain.popleft()
        placement = {"workers": [worker], "allow_other_workers": True} if worker else {}
        fut = self.client.submit(solve_state, self.spec, self.factory, task, pure=False,
                                 key=f"persival-state-{task.index}-{uuid.uuid4().hex[:8]}", **placement)
        self.active[fut] = (chain, time.monotonic(), task)

    def next_chain(self, chain: deque | None, worker: str | None) -> None:
        if chain:
            self.submit(chain, worker)
        elif self.queue:
            self.submit(self.queue.popleft(), worker)

    def collect(self, fut) -> None:
        try:
            from distributed.scheduler import KilledWorker
        except ImportError:  # pragma: no cover - older distributed
            from distributed import KilledWorker

        chain, _, task = self.active.pop(fut)
        worker = None
        try:
            outcome = fut.result()
            worker = outcome.worker
        except KilledWorker as exc:
            outcome = StateOutcome(index=task.index, ok=False, attempts=self.max_attempts,
                                   reason=f"worker process died while solving this state "
                                          f"(crash or out of memory): {exc}")
        except Exception as exc:  # lost for another reason: leave it missing for a resume
            log.warning("state %d lost (%s: %s); it stays missing", task.index, type(exc).__name__, exc)
            self.tally["lost"] += 1
            self.next_chain(chain, None)
            return
        self.record(outcome)
        if outcome.hung and worker:
            # Only a new process stops a simulate() that ignores cancel().
            _restart(self.client, [worker])
            worker = None
        self.next_chain(chain, worker)

    def stop_hung(self, backstop: float) -> None:
        now = time.monotonic()
        for fut, (chain, started, task) in list(self.active.items()):
            if now - started <= backstop:
                continue
            holders = [w for w, keys in self.client.processing().items() if fut.key in keys]
            if not holders:
                # Still waiting for a worker (e.g. SLURM jobs queued): not running, not hung.
                self.active[fut] = (chain, now, task)
                continue
            fut.cancel()
            del self.active[fut]
            self.record(StateOutcome(index=task.index, ok=False, attempts=1, wall_time_s=now - started,
                                     reason=f"timeout: no answer from the worker after {now - started:.0f} s "
                                            "(worker unresponsive; restarted)"))
            _restart(self.client, holders)
            self.next_chain(chain, None)


def _restart(client, workers: list[str]) -> None:
    try:
        client.restart_workers(workers, timeout=120, raise_for_error=False)
    except Exception as exc:  # e.g. workers started without a nanny cannot be restarted
        log.warning("could not restart worker(s) %s (%s: %s); a hung solve may keep occupying "
                    "them", workers, type(exc).__name__, exc)
