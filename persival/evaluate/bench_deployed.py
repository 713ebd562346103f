"""`persival bench deployed`: every surrogate of a run against many more exact FE states.

The run's own held-out test has 25 states; this benchmark solves N more (random activations,
the response tables' exact path: converged FE equilibria, not interpolations) into a resumable
campaign store under ``RUN/bench/`` and measures, on the same states, the deployed ONNX file, the
structured surrogate (and its shape error alone, at each FE state's own angle), the sparse grid,
the POD network and the tables' table-only path (docs/theory.md 8.3).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

__all__ = ["run_deployed_benchmark"]


def _summary(positions, angles, truth) -> dict:
    errors = np.linalg.norm(positions - truth.positions, axis=2)
    row = {"max_ae_mm": float(errors.max()), "mae_mm": float(errors.mean(axis=1).mean()),
           "p95_max_ae_mm": float(np.percentile(errors.max(axis=1), 95))}
    if angles is not None:
        row["max_angle_error_deg"] = float(np.abs(np.asarray(angles) - truth.elbow_angles).max())
    return row


def run_deployed_benchmark(run: str | Path, states: int = 200, seed: int = 11, progress: bool = True) -> dict:
    from persival.campaign.arm_simulator import arm_spec
    from persival.campaign.design import Design
    from persival.campaign.runner import run_campaign
    from persival.deploy.held_out import held_out_accuracy
    from persival.evaluate.run_layout import load_run
    from persival.surrogate.dataset import Dataset

    loaded = load_run(run)
    if loaded.structured is None:
        raise FileNotFoundError(f"{loaded.layout.structured}: this run has no structured surrogate (an FE-arm run makes one)")
    profile = loaded.structured.profile
    store = loaded.layout.root / "bench" / f"exact_{states}_seed{seed}.zarr"
    model_file = loaded.structured.model_file  # None: the built-in arm
    t0 = time.perf_counter()
    run_campaign(store, Design.random(states, seed=seed), arm_spec(profile, "tables", model_file), progress=progress)
    solve_s = time.perf_counter() - t0
    truth = Dataset.from_store(store).select(list(loaded.structured.surfaces.names))
    rows = {}
    export = loaded.layout.export / "deformation.onnx"
    if export.is_file():
        rows["deployed ONNX float32"] = held_out_accuracy(export, truth)
        rows["deployed ONNX float32"].pop("states")
    positions, angles = loaded.structured.predict_with_angle(truth.activations)
    rows["structured (numpy, float64)"] = _summary(positions, angles, truth)
    rows["structured, shape only (at the FE angle)"] = _summary(
        loaded.structured.surfaces_at(truth.elbow_angles, truth.activations), None, truth)
    rows["sparse grid"] = _summary(*_sg_all(loaded.sg, truth), truth)
    if "pod" in loaded.networks:
        rows["POD network"] = _summary(*loaded.networks["pod"].predict_with_angle(truth.activations), truth)
    table_only = loaded.layout.root / "bench" / f"exact_{states}_seed{seed}_table_only.zarr"
    run_campaign(table_only, Design.random(states, seed=seed),
                 arm_spec(profile, "interpolate", model_file), scheduler="inline", progress=False)
    interpolated = Dataset.from_store(table_only).select(list(truth.surfaces.names))
    rows["FE tables, table-only"] = _summary(interpolated.positions, interpolated.elbow_angles, truth)
    return {"run": str(run), "states": len(truth), "seed": seed, "profile": profile, "store": str(store),
            "solve_seconds": solve_s, "rows": rows}


def _sg_all(sg, truth):
    positions, angles = sg.predict_with_angle(truth.activations)
    ids = np.concatenate([np.arange(s, s + c) for name, s, c in zip(sg.surfaces.names, sg.surfaces.node_starts,
                                                                    sg.surfaces.node_counts) if name in truth.surfaces.names])
    return positions[:, ids], angles


