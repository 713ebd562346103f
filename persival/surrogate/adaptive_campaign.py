"""Spatially adaptive sparse grid grown on a real campaign (docs/theory.md, 5.5, beyond the paper).

:func:`persival.surrogate.adaptive.refine_adaptive` decides which points to add; this module
supplies its ``simulate`` callback: every point it asks for is looked up among the done states
already on disk (earlier steps, a resumed run, or seed stores such as a regular campaign of the
same model), and only the points found nowhere go through the campaign runner, into one new
store per step. The result is a :class:`SparseGridSurrogate` like the regular one, whose metadata
records the refinement history (grid size after every step), so the accuracy stage can replay
the error against the number of FE states without solving anything again.

Stores of an adaptive run are named by the digest of their design: re-running the same command
after an interruption finds every done state in the pool and only solves what is still missing.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from persival.campaign.design import Design
from persival.campaign.simulator import SimulatorSpec, SurfaceTopology
from persival.campaign.store import CampaignStore
from persival.surrogate.adaptive import refine_adaptive
from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate

__all__ = ["StatePool", "AdaptiveCampaignResult", "run_adaptive_campaign"]


def _key(point: np.ndarray) -> bytes:
    # Grid points are dyadic rationals, computed the same way everywhere: exact bits match.
    return np.asarray(point, dtype="<f8").tobytes()


class StatePool:
    """Done states of one model (one muscle's surface + elbow angle) gathered from several stores."""

    def __init__(self, muscle: str) -> None:
        self.muscle = muscle
        self.surface: SurfaceTopology | None = None
        self.model_hash: str | None = None
        self.spec: SimulatorSpec | None = None
        self._values: dict[bytes, np.ndarray] = {}
        self.stores: list[str] = []

    def __len__(self) -> int:
        return len(self._values)

    def add_store(self, path: str | Path) -> int:
        """Read every done state of ``path``; returns how many were new to the pool."""
        with CampaignStore.open(path) as store:
            reference = store.reference
            if self.muscle not in reference.surfaces:
                raise ValueError(f"{path} has no surface {self.muscle!r}; it has {sorted(reference.surfaces)}")
            if self.model_hash is None:
                self.model_hash, self.spec = reference.model_hash, store.spec
                self.surface = reference.surfaces[self.muscle]
            elif reference.model_hash != self.model_hash or store.spec != self.spec:
                raise ValueError(
                    f"{path} was computed by another model or simulator ({store.spec}, model "
                    f"{reference.model_hash[:12]}) than the pool ({self.spec}, model {self.model_hash[:12]})"
                )
            done = np.flatnonzero(store.done_mask())
            points = store.activations[done]
            positions = store.surface_positions(self.muscle, done) if len(done) else np.empty((0, 0, 3))
            angles = store.elbow_angles()[done]
        added = 0
        for p, x, a in zip(points, positions, angles):
            k = _key(p)
            if k not in self._values:
                self._values[k] = np.append(x.ravel(), a)
                added += 1
        self.stores.append(str(path))
        return added

    def lookup(self, points: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """(values (k, 3 n_nodes + 1) with NaN rows where missing, found mask (k,))."""
        found = np.array([_key(p) in self._values for p in points], dtype=bool)
        if not found.any():
            return None, found
        n_out = len(next(iter(self._values.values())))
        values = np.full((len(points), n_out), np.nan)
        for r in np.flatnonzero(found):
            values[r] = self._values[_key(points[r])]
        return values, found


@dataclass
class AdaptiveCampaignResult:
    surrogate: SparseGridSurrogate
    steps: list[dict]  # per refinement: grid size, points simulated, points reused, store
    simulated: int  # states solved by this run
    reused: int  # grid points found in the pool (earlier runs or seed stores)
    stop_reason: str
    wall_time_s: float


def run_adaptive_campaign(
    out: str | Path,
    spec: SimulatorSpec,
    *,
    max_points: int,
    muscle: str = "biceps",
    degree: int = 3,
    initial_level: int = 0,
    refinements_per_step: int = 2,
    norm: str = "max",
    tol: float = 0.0,
    seed_stores: Sequence[str | Path] = (),
    scheduler: str | None = "inline",
    n_workers: int | None = None,
    timeout_s: float | None = None,
    max_attempts: int = 3,
    progress: bool = True,
    log: Callable[[str], None] = lambda message: None,
) -> AdaptiveCampaignResult:
    """Grow an adaptive grid to ``max_points`` FE states (or until no refinable point's indicator
    reaches ``tol``, in mm / deg) and save its surrogate in ``out/surrogate``.

    The refinement indicator is the ``norm`` ("max" or "l2") of each point's hierarchical
    surplus row over every surface coordinate (mm) and the elbow angle (deg): "max" refines
    where some node or the angle is worst interpolated, matching the MaxAE metric (docs/theory.md, 8.1).
    ``scheduler`` defaults to in-process so that the simulator, its meshes and its solved
    states stay warm from one step to the next.
    """
    t0 = time.perf_counter()
    out = Path(out)
    pool = StatePool(muscle)
    for path in [*seed_stores, *sorted((out / "stores").glob("*.zarr"))]:
        pool.add_store(path)
    if pool.spec is not None and pool.spec != spec:
        raise ValueError(f"the seed stores / earlier steps were computed with {pool.spec}, not {spec}")
    simulate = _StepSimulator(pool, spec, out / "stores", muscle, log,
                              dict(scheduler=scheduler, n_workers=n_workers, timeout_s=timeout_s,
                                   max_attempts=max_attempts, progress=progress))
    result = refine_adaptive(
        simulate, 5, max_points=max_points, degree=degree, initial_level=initial_level,
        refinements_per_step=refinements_per_step, norm=norm, tol=tol, center=True,
    )
    steps = simulate.steps
    for step, n in zip(steps, np.cumsum([s["new_points"] for s in steps])):
        step["grid_points"] = int(n)
    surrogate = _fit_surrogate(result, pool, spec, muscle, degree, {
        "grid_points_per_step": [s["grid_points"] for s in steps], "norm": norm, "initial_level": initial_level,
        "refinements_per_step": refinements_per_step, "max_points": max_points, "tol": tol,
        "stop_reason": result.stop_reason})
    surrogate.save(out / "surrogate")
    res = AdaptiveCampaignResult(surrogate, steps, simulate.simulated, simulate.reused,
                                 result.stop_reason, time.perf_counter() - t0)
    (out / "adaptive.json").write_text(json.dumps(
        {"steps": steps, "simulated": res.simulated, "reused": res.reused,
         "stop_reason": res.stop_reason, "wall_time_s": res.wall_time_s,
         "grid_points": surrogate.grid.n_points}, indent=1))
    return res


def _fit_surrogate(result, pool: StatePool, spec: SimulatorSpec, muscle: str, degree: int,
                   adaptive: dict) -> SparseGridSurrogate:
    """The adaptive grid's surrogate of ``muscle`` (surface and elbow angle), with its provenance."""
    return SparseGridSurrogate(muscle, degree).fit_values(
        result.grid, result.values[:, :-1].reshape(len(result.values), -1, 3), result.values[:, -1],
        pool.surface,
        {"store": [str(s) for s in pool.stores], "model_hash": pool.model_hash,
         "simulator": json.loads(spec.to_json()), "adaptive": adaptive},
    )


class _StepSimulator:
    """The refinement's simulator: each step's new grid points, those already solved (in the seed
    stores or an earlier step) looked up, the others solved into a store of their own."""

    def __init__(self, pool: StatePool, spec: SimulatorSpec, stores_dir: Path, muscle: str,
                 log: Callable[[str], None], campaign_options: dict):
        self.pool, self.spec, self.stores_dir, self.muscle, self.log = pool, spec, stores_dir, muscle, log
        self.campaign_options = campaign_options
        self.steps: list[dict] = []
        self.simulated = self.reused = 0

    def __call__(self, points: np.ndarray) -> np.ndarray:
        values, found = self.pool.lookup(points)
        missing = np.flatnonzero(~found)
        step = {"new_points": len(points), "reused": int(found.sum()), "simulated": len(missing), "store": None}
        self.reused += int(found.sum())
        if len(missing):
            step["store"] = self._solve(points[missing], len(points), int(found.sum()))
            values, found = self.pool.lookup(points)
        else:
            self.log(f"step {len(self.steps)}: {len(points)} new grid points, all already solved")
        self.steps.append(step)
        return values

    def _solve(self, points: np.ndarray, n_new: int, n_found: int) -> str:
        """Solve ``points`` into a new store (created here, not before: a step that solves nothing
        writes nothing); returns its name."""
        from persival.campaign.runner import run_campaign

        design = Design(points, np.arange(len(points)), {"kind": "adaptive", "step": len(self.steps),
                                                          "muscle": self.muscle})
        path = self.stores_dir / f"step-{design.digest()[:12]}.zarr"
        self.log(f"step {len(self.steps)}: {n_new} new grid points, {n_found} already solved, "
                 f"solving {len(points)} into {path.name}")
        summary = run_campaign(path, design, self.spec, **self.campaign_options)
        if summary["failed"] or summary["missing"]:
            raise RuntimeError(
                f"{summary['failed']} state(s) of {path} failed ({summary['failure_reasons']}); an "
                "interpolating grid needs every point: retry them with `persival campaign run "
                f"--store {path} --retry-failed`, then run this command again"
            )
        self.pool.add_store(path)
        self.simulated += summary["this_run"]["computed"]
        return path.name
