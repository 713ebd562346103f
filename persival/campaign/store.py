"""The campaign store: one zarr (v3) directory holding a design, the reference surfaces and one
state per design point.

Layout: persival.campaign.store_layout.

Why a state cannot be half-written: every per-state array has exactly one chunk per state, zarr
writes each chunk file to a temporary file and renames it into place, and the status chunk is
written last. A process killed in the middle of a state leaves that state's status "missing"
(or its earlier "failed"), whatever arrived of its other chunks is ignored by every reader
(``surface_positions`` and ``elbow_angles`` mask states that are not done) and overwritten when
the state is recomputed. A finished state is never rewritten. Only one process writes (the
campaign driver; workers return results to it), enforced with an advisory lock that the
operating system releases when the process dies, so a kill -9 never leaves a stale lock.
"""

from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path

import numpy as np

import persival
from persival.campaign.design import Design
from persival.campaign.simulator import ReferenceGeometry, SimulatorSpec, SurfaceTopology
from persival.campaign.store_layout import (
    DONE,
    FAILED,
    FORMAT_NAME,
    FORMAT_VERSION,
    MISSING,
    STATUS_NAMES,
    StoreBusyError,
    StoreError,
    create_layout,
    dumps_json,
    take_writer_lock,
)
from persival.campaign.store_report import StateTable, state_table, store_summary

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "MISSING", "DONE", "FAILED", "STATUS_NAMES", "StoreError",
           "StoreVersionError", "CampaignMismatchError", "StoreBusyError", "CampaignStore"]


class StoreVersionError(StoreError):
    """A store written by another format version."""


class CampaignMismatchError(StoreError):
    """A store that belongs to another campaign (design or simulator differ)."""


class CampaignStore:
    """A campaign store opened for reading (``open``) or for writing (``create`` / ``open_for_writing``)."""

    def __init__(self, path: Path, group, writable: bool, lock_fd: int | None = None) -> None:
        self.path = path
        self._group = group
        self._writable = writable
        self._lock_fd = lock_fd
        attrs = dict(group.attrs)
        self._attrs = attrs
        self.surface_names: list[str] = list(attrs["surfaces"])
        # Array handles opened once: looking an array up in a zarr group reads its metadata.
        states = group["states"]
        self._states = {k: states[k] for k in ("status", "elbow_angle_deg", "wall_time_s",
                                                "finished_at", "attempts", "reason", "statistics")}
        self._positions = {name: states["positions"][name] for name in self.surface_names}
        self._status = self._states["status"]
        self.n_states = int(self._status.shape[0])

    # ---- creation / opening ------------------------------------------------------------------
    @classmethod
    def create(cls, path: str | Path, design: Design, spec: SimulatorSpec,
               reference: ReferenceGeometry) -> CampaignStore:
        """A new, empty store for ``design`` solved by ``spec``; refuses an existing path.

        Built in a temporary sibling directory and renamed into place, so a creation that is
        interrupted never leaves a store that looks valid.
        """
        path = Path(path)
        create_layout(path, design, spec, reference)
        return cls.open_for_writing(path)

    @classmethod
    def open(cls, path: str | Path) -> CampaignStore:
        """Open an existing store for reading."""
        return cls._open(Path(path), writable=False)

    @classmethod
    def open_for_writing(cls, path: str | Path) -> CampaignStore:
        """Open an existing store as its only writer (raises StoreBusyError if one is live)."""
        path = Path(path)
        cls._open(path, writable=False)  # validate format before taking the lock
        fd = take_writer_lock(path)
        try:
            return cls._open(path, writable=True, lock_fd=fd)
        except BaseException:
            os.close(fd)
            raise

    @classmethod
    def _open(cls, path: Path, writable: bool, lock_fd: int | None = None) -> CampaignStore:
        import zarr

        if not path.exists():
            raise StoreError(f"campaign store {path} does not exist")
        if not (path / "zarr.json").is_file():
            raise StoreError(f"{path} is not a campaign store (no zarr.json: not a zarr v3 group)")
        try:
            group = zarr.open_group(str(path), mode="r+" if writable else "r")
            attrs = dict(group.attrs)
        except Exception as exc:  # zarr raises various types for foreign / corrupt metadata
            raise StoreError(f"{path} is not a readable zarr group: {exc}") from None
        if attrs.get("format") != FORMAT_NAME:
            raise StoreError(f"{path} is a zarr group but not a PerSival campaign store")
        version = attrs.get("format_version")
        if version != FORMAT_VERSION:
            written_by = attrs.get("provenance", {}).get("persival_version", "unknown")
            raise StoreVersionError(
                f"{path} was written in campaign store format version {version} (persival "
                f"{written_by}); this persival ({persival.__version__}) reads version "
                f"{FORMAT_VERSION} only. Use the persival version that wrote it, or start a new "
                "store."
            )
        return cls(path, group, writable, lock_fd)

    def close(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the flock
            self._lock_fd = None
        self._writable = False

    def __enter__(self) -> CampaignStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass

    # ---- identity ----------------------------------------------------------------------------
    @property
    def provenance(self) -> dict:
        return dict(self._attrs["provenance"])

    @property
    def spec(self) -> SimulatorSpec:
        s = self._attrs["simulator"]
        return SimulatorSpec(s["kind"], s.get("options", {}))

    @property
    def design(self) -> Design:
        d = self._group["design"]
        return Design(d["activations"][:], d["ids"][:], dict(self._attrs["design"]))

    @property
    def reference(self) -> ReferenceGeometry:
        ref = self._group["reference"]
        surfaces = {}
        for name in self.surface_names:
            g = ref[name]
            node_ids = g["node_ids"][:] if "node_ids" in g else None
            surfaces[name] = SurfaceTopology(name, g["points"][:], g["triangles"][:], node_ids)
        prov = self.provenance
        return ReferenceGeometry(surfaces, prov["model_hash"], prov.get("model", {}))

    def check_matches(self, design: Design, spec: SimulatorSpec) -> None:
        """Refuse to continue this store with another design or another simulator."""
        problems = []
        if spec != self.spec:
            problems.append(f"simulator: store has {self.spec.to_json()}, requested {spec.to_json()}")
        stored = self.design
        if not stored.same_points(design):
            problems.append(
                f"design: store has {len(stored)} points ({stored.description}), requested "
                f"{len(design)} points ({design.description}) and they differ"
            )
        if problems:
            raise CampaignMismatchError(
                f"{self.path} belongs to another campaign; " + "; ".join(problems)
                + ". Use a new --store path, or rerun with the store's own design and simulator."
            )

    # ---- writing -----------------------------------------------------------------------------
    def _require_writable(self) -> None:
        if not self._writable:
            raise StoreError(f"{self.path} is open read-only")

    def _check_index(self, index: int) -> int:
        index = int(index)
        if not 0 <= index < self.n_states:
            raise IndexError(f"state index {index} out of range [0, {self.n_states})")
        if self._status[index] == DONE:
            raise StoreError(f"state {index} is already done; finished states are never rewritten")
        return index

    def write_done(self, index: int, elbow_angle_deg: float, positions: dict[str, np.ndarray],
                   statistics: dict, wall_time_s: float, attempts: int) -> None:
        """Record a solved state; its status flips to done last (see module doc)."""
        self._require_writable()
        index = self._check_index(index)
        if set(positions) != set(self.surface_names):
            raise ValueError(f"positions must have exactly the surfaces {self.surface_names}, "
                             f"got {sorted(positions)}")
        arrays = self._positions
        for name in self.surface_names:
            p = np.asarray(positions[name], dtype=np.float64)
            if p.shape != arrays[name].shape[1:]:
                raise ValueError(f"surface {name}: positions have shape {p.shape}, "
                                 f"the reference has {arrays[name].shape[1:]}")
            arrays[name][index] = p
        self._states["elbow_angle_deg"][index] = float(elbow_angle_deg)
        self._write_common(index, "", statistics, wall_time_s, attempts)
        self._status[index] = DONE

    def write_failed(self, index: int, reason: str, statistics: dict | None, wall_time_s: float,
                     attempts: int) -> None:
        """Record a state that failed for good, with its reason."""
        self._require_writable()
        index = self._check_index(index)
        self._states["elbow_angle_deg"][index] = np.nan
        self._write_common(index, reason or "unknown failure", statistics or {}, wall_time_s,
                           attempts)
        self._status[index] = FAILED

    def _write_common(self, index, reason, statistics, wall_time_s, attempts) -> None:
        st = self._states
        st["reason"][index] = str(reason)
        st["statistics"][index] = dumps_json(statistics)
        st["wall_time_s"][index] = float(wall_time_s)
        st["attempts"][index] = int(attempts)
        st["finished_at"][index] = _dt.datetime.now(_dt.UTC).timestamp()

    # ---- reading -----------------------------------------------------------------------------
    def status_codes(self) -> np.ndarray:
        """(n,) int8: 0 missing, 1 done, 2 failed."""
        return np.asarray(self._status[:])

    def done_mask(self) -> np.ndarray:
        return self.status_codes() == DONE

    def pending(self, retry_failed: bool = False) -> np.ndarray:
        """Indices of states still to compute: missing, plus failed if asked."""
        codes = self.status_codes()
        mask = codes == MISSING
        if retry_failed:
            mask |= codes == FAILED
        return np.flatnonzero(mask)

    def states(self) -> StateTable:
        """Every state of the store, one row per design point (persival.campaign.store_report)."""
        return state_table(self)

    @property
    def activations(self) -> np.ndarray:
        return np.asarray(self._group["design/activations"][:])

    @property
    def ids(self) -> np.ndarray:
        return np.asarray(self._group["design/ids"][:])

    def elbow_angles(self) -> np.ndarray:
        """(n,) elbow angles in degrees, NaN for states that are not done."""
        angles = np.asarray(self._states["elbow_angle_deg"][:], dtype=np.float64)
        angles[~self.done_mask()] = np.nan
        return angles

    def surface_positions(self, name: str, states=None) -> np.ndarray:
        """Current node positions (n_states, n_nodes, 3) of one surface, NaN where not done.

        ``states``: optional index array (rows in design order) to read only some states.
        """
        if name not in self.surface_names:
            raise KeyError(f"no surface {name!r}; the store has {self.surface_names}")
        arr = self._positions[name]
        done = self.done_mask()
        if states is None:
            out = np.asarray(arr[:], dtype=np.float64)
        else:
            states = np.atleast_1d(np.asarray(states, dtype=np.int64))
            out = np.asarray(arr.get_orthogonal_selection((states, slice(None), slice(None))))
            done = done[states]
        out[~done] = np.nan
        return out

    def summary(self) -> dict:
        """Counts of done / failed / missing, failure reasons, and wall-time figures."""
        return store_summary(self)
