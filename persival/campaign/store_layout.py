"""The campaign store's layout on disk (one zarr v3 directory), and its creation.

Layout (``n`` design points, one group per concern)::

    <store>/zarr.json            attributes: format marker + version, provenance, simulator spec,
                                 design description, surface names
    design/ids            (n,)            int64
    design/activations    (n, 5)          float64
    reference/<surface>/points     (m, 3) float64 mm
    reference/<surface>/triangles  (k, 3) int64
    reference/<surface>/node_ids   (m,) int64, optional: the surface's node set in the full mesh
    states/status         (n,)  int8     0 missing, 1 done, 2 failed     -- chunk = 1 state
    states/elbow_angle_deg, wall_time_s, finished_at (n,) float64        -- chunk = 1 state
    states/attempts       (n,)  int16                                    -- chunk = 1 state
    states/reason, states/statistics (n,) str (statistics: json)         -- chunk = 1 state
    states/positions/<surface> (n, m, 3) float64                         -- chunk = 1 state
    writer.lock                  held (flock) by the one process that writes
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import json
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np

import persival
from persival.campaign.design import Design
from persival.campaign.simulator import ReferenceGeometry, SimulatorSpec

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "MISSING", "DONE", "FAILED", "STATUS_NAMES", "StoreError", "StoreBusyError",
           "create_layout", "dumps_json", "now", "take_writer_lock"]

FORMAT_NAME = "persival-campaign"
FORMAT_VERSION = 1
MISSING, DONE, FAILED = 0, 1, 2
STATUS_NAMES = {MISSING: "missing", DONE: "done", FAILED: "failed"}


class StoreError(RuntimeError):
    """A path that is not a usable campaign store."""


class StoreBusyError(StoreError):
    """Another live process is writing to the store."""


_LOCK_NAME = "writer.lock"


def take_writer_lock(path: Path) -> int:
    """The store's advisory writer lock (the operating system releases it when the process dies,
    so a kill -9 never leaves a stale lock); its file descriptor. StoreBusyError while another live
    process holds it. Removes what a killed writer left half-written."""
    fd = os.open(path / _LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
        os.close(fd)
        raise StoreBusyError(
            f"{path} is being written by another live process (pid {holder}); "
            "wait for it to finish or stop it first"
        ) from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, str(os.getpid()).encode(), 0)
    # zarr writes each chunk to "<chunk>.<uuid>.partial" and renames it; a writer killed
    # in between leaves the temporary file behind. Only the writer may remove them.
    for leftover in path.rglob("*.partial"):
        leftover.unlink(missing_ok=True)
    return fd


def _json_default(obj: Any):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def dumps_json(obj: Any) -> str:
    """JSON of a state's statistics (numpy scalars and arrays as numbers and lists), keys sorted."""
    return json.dumps(obj, default=_json_default, sort_keys=True)


def now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def create_layout(path: Path, design: Design, spec: SimulatorSpec, reference: ReferenceGeometry) -> None:
    """A new, empty store at ``path`` (refused where something exists), built in a temporary
    sibling directory and renamed into place, so an interrupted creation never leaves a store
    that looks valid."""
    import zarr

    path = Path(path)
    if path.exists():
        raise StoreError(f"{path} already exists")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise StoreError(f"cannot create {path}: a file is in the way of its folder {path.parent}") from None
    except OSError as exc:
        raise StoreError(f"cannot create the parent directory of {path}: {(exc.strerror or str(exc)).lower()}") from None
    tmp = path.with_name(f".{path.name}.creating-{os.getpid()}")
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        root = zarr.open_group(str(tmp), mode="w-", zarr_format=3)
        root.attrs.update({
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "surfaces": reference.names,
            "simulator": json.loads(spec.to_json()),
            "design": design.description,
            "provenance": {
                "model_hash": reference.model_hash,
                "model": reference.description,
                "persival_version": persival.__version__,
                "design_sha256": design.digest(),
                "simulator_sha256": spec.digest(),
                "created": now(),
            },
        })
        _create_arrays(root, design, reference)
        os.rename(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _create_arrays(root, design: Design, reference: ReferenceGeometry) -> None:
    """The design, the reference surfaces and the empty per-state arrays (one chunk per state)."""
    n = len(design)
    d = root.create_group("design")
    d.create_array("ids", data=np.asarray(design.ids, dtype=np.int64))
    d.create_array("activations", data=np.asarray(design.points, dtype=np.float64))
    ref = root.create_group("reference")
    for name, surf in reference.surfaces.items():
        g = ref.create_group(name)
        g.create_array("points", data=surf.reference_points)
        g.create_array("triangles", data=surf.triangles)
        if surf.node_ids is not None:
            g.create_array("node_ids", data=surf.node_ids)
    st = root.create_group("states")
    # One chunk per state everywhere: concurrent or interrupted writes of different
    # states never touch the same file. Flat chunk names ("c.17.0.0") rather than
    # nested directories halve the number of inodes a campaign creates.
    flat = {"chunk_key_encoding": {"name": "default", "separator": "."}}
    st.create_array("status", shape=(n,), chunks=(1,), dtype="i1", fill_value=MISSING, **flat)
    for key in ("elbow_angle_deg", "wall_time_s", "finished_at"):
        st.create_array(key, shape=(n,), chunks=(1,), dtype="f8", fill_value=np.nan, **flat)
    st.create_array("attempts", shape=(n,), chunks=(1,), dtype="i2", fill_value=0, **flat)
    for key in ("reason", "statistics"):
        st.create_array(key, shape=(n,), chunks=(1,), dtype=str, fill_value="", **flat)
    pos = st.create_group("positions")
    for name, surf in reference.surfaces.items():
        m = surf.n_nodes
        pos.create_array(name, shape=(n, m, 3), chunks=(1, m, 3), dtype="f8",
                         fill_value=np.nan, **flat)
