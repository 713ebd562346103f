"""The local dask cluster that campaigns and the response tables run on: one single-threaded
worker process per core."""

from __future__ import annotations

import logging
import os


def available_cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


# dask's nanny already sets OMP/MKL/OpenBLAS threads to 1 in its workers; numba's own pool is
# not covered and took one thread per core in every worker (2 workers x 2 threads on 2 cores,
# measured with numba.get_num_threads() in the workers): the FE kernels then fight for the cores.
WORKER_ENV = {"NUMBA_NUM_THREADS": "1"}


def local_cluster(n_workers: int | None = None):
    """A LocalCluster of single-threaded worker processes (one per core by default)."""
    from distributed import LocalCluster

    return LocalCluster(n_workers=n_workers or available_cores(), threads_per_worker=1, processes=True,
                        dashboard_address=None, silence_logs=logging.CRITICAL, env=WORKER_ENV)
