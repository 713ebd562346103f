"""The dataset every surrogate's ``fit`` takes (EZyRB's Database, for muscle surfaces).

A :class:`Dataset` holds states of one model: activations (n, 5), surface node positions of
several muscles concatenated (n, N, 3) in mm, elbow angles (n,) in degrees, the concatenated
display surfaces (:class:`Surfaces`) and ``source``, the provenance that every number measured
on it must carry (which simulator, which profile, how many states).

It comes from a campaign store (:meth:`Dataset.from_store`, FE or analytic states) or from a
training-data file written by :mod:`persival.surrogate.training_data` (SG states).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Surfaces", "Dataset", "describe_source"]


@dataclass
class _Topology:  # the fields of SurfaceTopology that Surfaces.from_topologies reads
    name: str
    reference_points: np.ndarray
    triangles: np.ndarray


@dataclass
class Surfaces:
    """Several muscles' display surfaces as one node list: muscle m owns a contiguous node range."""

    names: tuple[str, ...]
    node_counts: tuple[int, ...]
    reference_points: np.ndarray  # (N, 3) mm, all muscles
    triangles: np.ndarray  # (K, 3) global node indices
    triangle_counts: tuple[int, ...]

    @classmethod
    def from_topologies(cls, topologies) -> Surfaces:
        """From :class:`persival.campaign.simulator.SurfaceTopology` objects, in order."""
        points, triangles, offset = [], [], 0
        for t in topologies:
            points.append(np.asarray(t.reference_points, dtype=np.float64))
            triangles.append(np.asarray(t.triangles, dtype=np.int64) + offset)
            offset += len(t.reference_points)
        return cls(tuple(t.name for t in topologies), tuple(len(p) for p in points), np.concatenate(points),
                   np.concatenate(triangles), tuple(len(t) for t in triangles))

    @property
    def n_nodes(self) -> int:
        return int(sum(self.node_counts))

    @property
    def node_starts(self) -> tuple[int, ...]:
        return tuple(int(s) for s in np.concatenate([[0], np.cumsum(self.node_counts)[:-1]]))

    @property
    def triangle_starts(self) -> tuple[int, ...]:
        return tuple(int(s) for s in np.concatenate([[0], np.cumsum(self.triangle_counts)[:-1]]))

    def nodes_of(self, name: str) -> slice:
        if name not in self.names:
            raise KeyError(f"no surface {name!r}; there are {list(self.names)}")
        k = self.names.index(name)
        return slice(self.node_starts[k], self.node_starts[k] + self.node_counts[k])

    def ranges(self) -> list[dict]:
        """Per muscle: node and triangle ranges (the export metadata's ``surfaces``)."""
        return [{"name": n, "node_start": ns, "node_count": nc, "triangle_start": ts, "triangle_count": tc}
                for n, ns, nc, ts, tc in zip(self.names, self.node_starts, self.node_counts,
                                             self.triangle_starts, self.triangle_counts)]

    def save(self, path: str | Path) -> None:
        np.savez(path, names=np.array(self.names), node_counts=np.array(self.node_counts),
                 reference_points=self.reference_points, triangles=self.triangles,
                 triangle_counts=np.array(self.triangle_counts))

    @classmethod
    def load(cls, path: str | Path) -> Surfaces:
        with np.load(path, allow_pickle=False) as z:
            return cls(tuple(str(n) for n in z["names"]), tuple(int(c) for c in z["node_counts"]),
                       z["reference_points"], z["triangles"], tuple(int(c) for c in z["triangle_counts"]))


def describe_source(summary: dict, description: dict, n_states: int) -> dict:
    """The provenance line of a campaign: simulator kind, profile and state count."""
    kind = summary.get("simulator", "unknown")
    label = {"arm": "FE arm", "analytic": "analytic stand-in", "external": "external FE code"}.get(kind, kind)
    profile = description.get("profile")
    return {"simulator": kind, "profile": profile, "states": int(n_states),
            "label": f"{label}{f' ({profile} profile)' if profile else ''}, {n_states} states"}


@dataclass
class Dataset:
    """States of one model: activations (n, 5), the surface positions (n, N, 3) mm of the muscles
    in ``surfaces``, elbow angles (n,) deg and their provenance (``source``).

    >>> surfaces = Surfaces(("biceps",), (3,), np.eye(3), np.array([[0, 1, 2]]), (1,))
    >>> data = Dataset(np.zeros((2, 5)), np.stack([np.eye(3), 2 * np.eye(3)]), np.array([30.0, 90.0]), surfaces)
    >>> len(data), data.displacements[1, 0].tolist()  # u = x - X
    (2, [1.0, 0.0, 0.0])
    >>> data.surfaces.nodes_of("biceps")
    slice(0, 3, None)
    """

    activations: np.ndarray  # (n, 5)
    positions: np.ndarray  # (n, N, 3) mm
    elbow_angles: np.ndarray  # (n,) deg
    surfaces: Surfaces
    source: dict = field(default_factory=dict)  # simulator, profile, states, label, model_hash, store
    target_deg: np.ndarray | None = None  # (n,) training data: the angle a sample solves, NaN for random alpha

    def __post_init__(self) -> None:
        self.activations = np.asarray(self.activations, dtype=np.float64)
        n, N = len(self.activations), self.surfaces.n_nodes
        if self.activations.shape != (n, 5) or self.positions.shape != (n, N, 3) or np.shape(self.elbow_angles) != (n,):
            raise ValueError(f"inconsistent dataset: activations {self.activations.shape}, positions "
                             f"{self.positions.shape} for {N} nodes, angles {np.shape(self.elbow_angles)}")

    def __len__(self) -> int:
        return len(self.activations)

    @property
    def displacements(self) -> np.ndarray:
        """u = x - X (n, N, 3) mm, from the reference configuration of the surfaces."""
        return self.positions - self.surfaces.reference_points

    @property
    def model_hash(self) -> str | None:
        return self.source.get("model_hash")

    def require_model(self, model_hash: str) -> None:
        """Refuse states of another arm model than the response tables' (``model_hash``)."""
        if self.model_hash is not None and self.model_hash != model_hash:
            raise ValueError(f"the dataset's states come from model {self.model_hash[:12]}, the response tables "
                             f"from model {model_hash[:12]}: fit on states of the same arm "
                             "(the model file of their campaign: --model)")

    def subset(self, rows) -> Dataset:
        rows = np.asarray(rows)
        return Dataset(self.activations[rows], self.positions[rows], self.elbow_angles[rows], self.surfaces,
                       {**self.source, "states": int(len(self.activations[rows]))},
                       None if self.target_deg is None else self.target_deg[rows])

    def select(self, muscles) -> Dataset:
        """The same states with only some muscles' surfaces (e.g. the paper's biceps)."""
        names = [muscles] if isinstance(muscles, str) else list(muscles)
        slices = [self.surfaces.nodes_of(n) for n in names]
        topologies = []
        for name, sl in zip(names, slices):
            k = self.surfaces.names.index(name)
            t0 = self.surfaces.triangle_starts[k]
            tri = self.surfaces.triangles[t0 : t0 + self.surfaces.triangle_counts[k]] - sl.start
            topologies.append(_Topology(name, self.surfaces.reference_points[sl], tri))
        positions = np.concatenate([self.positions[:, sl] for sl in slices], axis=1)
        return Dataset(self.activations, positions, self.elbow_angles, Surfaces.from_topologies(topologies),
                       self.source, self.target_deg)

    def digest(self) -> str:
        """sha256 of the inputs and outputs (provenance of anything trained on it)."""
        h = hashlib.sha256()
        for a in (self.activations, np.asarray(self.positions, np.float32), np.asarray(self.elbow_angles, np.float64)):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    @classmethod
    def from_store(cls, path: str | Path, muscles=None) -> Dataset:
        """The done states of a campaign store; ``muscles`` defaults to every surface it has."""
        from persival.campaign.store import CampaignStore

        with CampaignStore.open(path) as store:
            reference = store.reference
            names = list(reference.surfaces) if muscles is None else [muscles] if isinstance(muscles, str) else list(muscles)
            missing = [m for m in names if m not in reference.surfaces]
            if missing:
                raise ValueError(f"{path} has no surface {missing[0]!r}; it has {sorted(reference.surfaces)}")
            done = np.flatnonzero(store.done_mask())
            if not len(done):
                raise ValueError(f"{path} has no finished state")
            positions = np.concatenate([store.surface_positions(m, done) for m in names], axis=1)
            source = {**describe_source(store.summary(), reference.description, len(done)),
                      "model_hash": reference.model_hash, "store": str(path),
                      "simulator_options": dict(store.spec.options)}
            return cls(store.activations[done], positions, store.elbow_angles()[done],
                       Surfaces.from_topologies([reference.surfaces[m] for m in names]), source)

    def save(self, path: str | Path) -> Path:
        """A folder: arrays (.npz, positions float32) + source.json."""
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        np.savez(path / "states.npz", activations=self.activations, positions=np.asarray(self.positions, np.float32),
                 elbow_angles=self.elbow_angles)
        self.surfaces.save(path / "surfaces.npz")
        (path / "source.json").write_text(json.dumps(self.source, indent=2))
        return path

    @classmethod
    def load(cls, path: str | Path) -> Dataset:
        """A folder written by :meth:`save` (training data: :func:`persival.surrogate.training_data.open_dataset`)."""
        path = Path(path)
        if (path / "training_data.json").exists():
            raise ValueError(f"{path} holds training data: open it with persival.surrogate.training_data.open_dataset")
        if not (path / "states.npz").exists():
            raise FileNotFoundError(f"{path} is not a dataset folder (no states.npz or training_data.json)")
        with np.load(path / "states.npz", allow_pickle=False) as z:
            arrays = z["activations"], z["positions"], z["elbow_angles"]
        return cls(*arrays, Surfaces.load(path / "surfaces.npz"), json.loads((path / "source.json").read_text()))
