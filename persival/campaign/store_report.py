"""What a campaign store holds, read as a whole: every state as one table (status, angle, wall
time, attempts, failure reason, statistics per design point) and the counts of a summary."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from persival.campaign.store_layout import DONE, FAILED, MISSING, STATUS_NAMES

__all__ = ["StateTable", "state_table", "store_summary", "store_size_bytes"]


@dataclass
class StateTable:
    """Every state of a store, one row per design point, in design order."""

    ids: np.ndarray  # (n,) int64
    activations: np.ndarray  # (n, 5)
    status: np.ndarray  # (n,) str: done / failed / missing
    elbow_angle_deg: np.ndarray  # (n,) NaN unless done
    wall_time_s: np.ndarray  # (n,) NaN if never attempted
    attempts: np.ndarray  # (n,) int
    reason: list[str]  # failure reason ("" unless failed)
    statistics: list[dict | None]  # simulator statistics (None if never attempted)

    def __len__(self) -> int:
        return len(self.ids)


def state_table(store) -> StateTable:
    """Every state of an open :class:`~persival.campaign.store.CampaignStore`, in design order."""
    codes = store.status_codes()
    st = store._states
    stats = [json.loads(s) if s else None for s in st["statistics"][:].tolist()]
    angles = np.asarray(st["elbow_angle_deg"][:], dtype=np.float64)
    angles[codes != DONE] = np.nan
    d = store._group["design"]
    return StateTable(
        ids=np.asarray(d["ids"][:]),
        activations=np.asarray(d["activations"][:]),
        status=np.array([STATUS_NAMES[int(c)] for c in codes]),
        elbow_angle_deg=angles,
        wall_time_s=np.asarray(st["wall_time_s"][:], dtype=np.float64),
        attempts=np.asarray(st["attempts"][:], dtype=np.int64),
        reason=[str(r) if c == FAILED else "" for r, c in zip(st["reason"][:].tolist(), codes)],
        statistics=stats,
    )


def store_summary(store) -> dict:
    """Counts of done / failed / missing, failure reasons, and wall-time figures of an open store."""
    codes = store.status_codes()
    wall = np.asarray(store._states["wall_time_s"][:], dtype=np.float64)
    reasons: dict[str, int] = {}
    failed = np.flatnonzero(codes == FAILED)
    if len(failed):
        for r in store._states["reason"].get_orthogonal_selection((failed,)).tolist():
            key = str(r).splitlines()[0][:120] if r else "unknown"
            reasons[key] = reasons.get(key, 0) + 1
    done = codes == DONE
    return {
        "path": str(store.path),
        "total": int(len(codes)),
        "done": int(done.sum()),
        "failed": int((codes == FAILED).sum()),
        "missing": int((codes == MISSING).sum()),
        "failure_reasons": reasons,
        "wall_time_s_total": float(np.nansum(wall)),
        "wall_time_s_mean_done": float(wall[done].mean()) if done.any() else None,
        "store_bytes": store_size_bytes(store.path),
        "simulator": store._attrs["simulator"]["kind"],
        "model_hash": store.provenance["model_hash"],
    }


def store_size_bytes(path: str | Path) -> int:
    return sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file())
