"""Designs: the activation vectors a campaign solves, with stable ids, and their solve order.

A design is validated once, when it is made: every point is five finite numbers in [0, 1]
(the activation check of persival.vocabulary), ids are unique non-negative integers. ``solve_order`` then lays the points
along a short path through [0, 1]^5 so that consecutive states are neighbours and a simulator
can warm-start each solve from the previous one; ``chunks`` cuts that path into contiguous
pieces, one per worker at a time.
"""

from __future__ import annotations

import csv
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from persival.grid_points import level_index_points, regular_levels_indices
from persival.vocabulary import MUSCLES, N_ACTIVATIONS, check_activations

__all__ = ["Design", "DesignError", "solve_order", "chunks"]


class DesignError(ValueError):
    """A design that cannot be run (bad shape, non-finite or out-of-range points, bad ids)."""


@dataclass(frozen=True, eq=False)
class Design:
    """``points`` (n, 5) activation vectors with integer ``ids`` (n,) and how they were made."""

    points: np.ndarray
    ids: np.ndarray
    description: dict = field(default_factory=dict)  # json-able: kind, level, seed, file

    def __post_init__(self) -> None:
        points = _validate_points(self.points)
        ids = _validate_ids(self.ids, len(points))
        points.setflags(write=False)
        ids.setflags(write=False)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "ids", ids)

    def __len__(self) -> int:
        return len(self.points)

    def digest(self) -> str:
        """sha256 of ids and points (exact bits): the identity of a design in a store."""
        h = hashlib.sha256()
        h.update(self.ids.astype("<i8").tobytes())
        h.update(self.points.astype("<f8").tobytes())
        return h.hexdigest()

    def same_points(self, other: Design) -> bool:
        return np.array_equal(self.ids, other.ids) and np.array_equal(self.points, other.points)

    # ---- constructors ------------------------------------------------------------------------
    @classmethod
    def sparse_grid(cls, level: int, degree: int = 3) -> Design:
        """The points of the regular B-spline boundary sparse grid (docs/theory.md, 5.2), in the
        surrogate's point order (``degree`` is recorded only: the points do not depend on it).

        >>> len(Design.sparse_grid(1)), len(Design.sparse_grid(2))
        (243, 1053)
        """
        if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or level < 1:
            raise DesignError(f"sparse-grid level must be an integer >= 1, got {level!r}")
        points = level_index_points(*regular_levels_indices(N_ACTIVATIONS, int(level)))
        return cls(points, np.arange(len(points)),
                   {"kind": "sparse-grid", "level": int(level), "degree": int(degree)})

    @classmethod
    def random(cls, n: int, seed: int = 0) -> Design:
        """``n`` points drawn uniformly from [0, 1]^5 with numpy's PCG64 seeded by ``seed``."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise DesignError(f"number of random points must be an integer >= 1, got {n!r}")
        rng = np.random.default_rng(seed)
        return cls(rng.random((int(n), N_ACTIVATIONS)), np.arange(int(n)),
                   {"kind": "random", "n": int(n), "seed": int(seed)})

    @classmethod
    def from_file(cls, path: str | Path) -> Design:
        """A design from ``.npy`` ((n, 5) array) or ``.csv``.

        CSV: five numeric columns, optionally a header row; a header may name an ``id`` column
        and the five muscles (any other header is read positionally).
        """
        path = Path(path)
        if not path.is_file():
            raise DesignError(f"design file {path} does not exist")
        suffix = path.suffix.lower()
        if suffix == ".npy":
            try:
                points = np.load(path, allow_pickle=False)
            except ValueError as exc:
                raise DesignError(f"{path}: not a plain numeric .npy array ({exc})") from None
            ids = np.arange(len(points)) if np.ndim(points) >= 1 else np.arange(0)
        elif suffix in (".csv", ".txt"):
            points, ids = _read_csv(path)
        else:
            raise DesignError(f"{path}: design files must be .csv or .npy, got {suffix or 'no suffix'}")
        try:
            return cls(points, ids, {"kind": "file", "file": str(path.resolve())})
        except DesignError as exc:
            raise DesignError(f"{path}: {exc}") from None

    def to_csv(self, path: str | Path) -> Path:
        path = Path(path)
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["id", *MUSCLES])
            for i, p in zip(self.ids, self.points):
                w.writerow([int(i), *(repr(float(v)) for v in p)])
        return path


def _validate_points(points) -> np.ndarray:
    # A design is a batch of activation vectors: the vocabulary's check, as a DesignError.
    try:
        return check_activations(points, what="design points")
    except ValueError as exc:
        raise DesignError(str(exc)) from None


def _validate_ids(ids, n: int) -> np.ndarray:
    arr = np.asarray(ids)
    if arr.shape != (n,):
        raise DesignError(f"design ids must have shape ({n},), got {arr.shape}")
    if arr.dtype.kind == "f" and np.isfinite(arr).all() and np.array_equal(arr, np.round(arr)):
        arr = arr.astype(np.int64)
    if arr.dtype.kind not in "iu":
        raise DesignError(f"design ids must be integers, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if arr.min() < 0:
        raise DesignError("design ids must be >= 0")
    uniq, counts = np.unique(arr, return_counts=True)
    if (counts > 1).any():
        raise DesignError(f"design ids must be unique; duplicated: {uniq[counts > 1][:5].tolist()}")
    return arr


def _read_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    with path.open(newline="") as f:
        rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    if not rows:
        raise DesignError(f"{path}: the design file is empty")
    header = None
    try:
        [float(c) for c in rows[0]]
    except ValueError:
        header, rows = [c.strip().lower() for c in rows[0]], rows[1:]
    id_col = header.index("id") if header and "id" in header else None
    if header and all(m in header for m in MUSCLES):
        cols = [header.index(m) for m in MUSCLES]
    else:
        cols = [c for c in range(len(rows[0]) if rows else 0) if c != id_col]
    points, ids = [], []
    for lineno, row in enumerate(rows, start=2 if header else 1):
        try:
            points.append([float(row[c]) for c in cols])
            if id_col is not None:
                ids.append(int(row[id_col]))
        except (ValueError, IndexError):
            raise DesignError(f"{path}, line {lineno}: expected numbers, got {row}") from None
    if len({len(p) for p in points}) > 1:
        raise DesignError(f"{path}: rows have different numbers of columns")
    ids_arr = np.asarray(ids, dtype=np.int64) if id_col is not None else np.arange(len(points))
    return np.asarray(points, dtype=np.float64).reshape(len(points), -1), ids_arr


def solve_order(points: np.ndarray) -> np.ndarray:
    """Indices of ``points`` along a short path: greedy nearest neighbour from alpha = 0.

    Greedy nearest neighbour is within a log factor of the shortest tour and costs O(n^2)
    (1053 points: a few ms), which is all a warm start needs: each state's predecessor is one of
    its nearest solved neighbours. Ties go to the lowest index, so the order is deterministic.
    """
    points = np.asarray(points, dtype=np.float64)
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    left = np.ones(n, dtype=bool)
    current = int(np.argmin(np.einsum("ij,ij->i", points, points)))
    for k in range(n):
        order[k] = current
        left[current] = False
        if k == n - 1:
            break
        d = np.einsum("ij,ij->i", points - points[current], points - points[current])
        d[~left] = np.inf
        current = int(np.argmin(d))
    return order


def chunks(order: np.ndarray, n_chunks: int) -> list[np.ndarray]:
    """Cut a solve order into at most ``n_chunks`` contiguous pieces of near-equal length."""
    order = np.asarray(order)
    n_chunks = max(1, min(int(n_chunks), len(order)))
    return [c for c in np.array_split(order, n_chunks) if len(c)]
