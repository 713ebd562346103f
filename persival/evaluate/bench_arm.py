"""FE arm at campaign scale (docs/theory.md, section 4): response tables, seconds per state, a campaign.

Measured in one run on this machine: the response tables (built or finished now, plus the
compute time of every column from their files), the exact path (FE state from the tables) and
the table-only path per state over random activations, optionally the direct coupled solve of
the same states (the old route) with the agreement of the two, a whole sparse-grid campaign
through the campaign runner (dask, one worker per core) and the peak memory of this process and
its workers.
"""

from __future__ import annotations

import resource
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["run_arm_benchmark"]


def _peak_mb() -> dict:
    to_mb = 1.0 / 1024.0  # ru_maxrss is in KiB on Linux
    return {"this_process_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * to_mb,
            "largest_worker_MB": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * to_mb}


def run_arm_benchmark(profile: str = "quick", states: int = 10, direct: int = 0, campaign_level: int = 2,
                      seed: int = 0, progress=None) -> dict:
    """Every timing of the module docstring; ``direct`` of the ``states`` are also solved directly."""
    from persival.campaign.design import Design
    from persival.campaign.runner import run_campaign
    from persival.campaign.simulator import SimulatorSpec
    from persival.model.arm.arm_model import ArmModel
    from persival.model.fe.solver import ConvergenceError
    from persival.tables.open import ensure_tables
    from persival.tables.table_solve import OutsideTableError, TableSolver

    say = progress or (lambda text: None)
    result: dict = {"profile": profile}
    t0 = time.perf_counter()
    say("response tables")
    table = ensure_tables(None, profile)
    result["tables"] = {"this_run_s": time.perf_counter() - t0, "column_compute_s": table.build_seconds(),
                        "columns": int(table.done.size), "angles": len(table.angles_deg), "levels": len(table.levels)}
    t0 = time.perf_counter()
    arm = ArmModel(profile=profile)
    arm.base_state()  # timed here: the warm start
    solver = TableSolver(arm, table)
    result["warm_start_s"] = time.perf_counter() - t0  # meshing (cached) + hanging arm (cached) + table load
    rng = np.random.default_rng(seed)
    alphas = rng.uniform(0.0, 1.0, (states, 5))
    exact, fast, rows, outside, failed = [], [], [], [], []
    for k, alpha in enumerate(alphas):
        say(f"state {k + 1}/{states}")
        t1 = time.perf_counter()
        try:
            theta_fast, u_fast = solver.interpolate(alpha)
        except OutsideTableError:  # e.g. hyperflexion past the table's last angle: not a table state
            outside.append(alpha.tolist())
            continue
        fast.append(time.perf_counter() - t1)
        t1 = time.perf_counter()
        try:
            state = solver.solve(alpha)
        except ConvergenceError as exc:  # counted and reported, not timed (a campaign retries it directly)
            failed.append({"alpha": alpha.tolist(), "reason": str(exc), "seconds": time.perf_counter() - t1})
            continue
        exact.append(time.perf_counter() - t1)
        row = {"alpha": alpha.tolist(), "theta_exact": state.elbow_angle_deg, "theta_table_only": theta_fast,
               "table_only_node_error_max_mm": float(np.abs(u_fast - state.displacement).max()),
               "table_only_node_error_mean_mm": float(np.linalg.norm(u_fast - state.displacement, axis=1).mean()),
               "exact_s": exact[-1], "moment_residual_Nmm": state.moment_residual,
               "max_abs_J_minus_1": state.max_volume_change}
        if k < direct:
            say(f"state {k + 1}/{states}: direct coupled solve")
            t1 = time.perf_counter()
            reference = arm.solve(alpha)
            row.update(direct_s=time.perf_counter() - t1, theta_direct=reference.elbow_angle_deg,
                       exact_vs_direct_node_max_mm=float(np.abs(reference.displacement - state.displacement).max()))
        rows.append(row)
    if not rows:
        raise ValueError(f"none of the {states} random states has its equilibrium inside the tables; try another seed")
    result["states"] = rows
    result["outside_table"] = outside
    result["exact_failed"] = failed
    result["exact_s_median"], result["exact_s_max"] = float(np.median(exact)), float(np.max(exact))
    result["table_only_s_median"] = float(np.median(fast))
    if campaign_level:
        design = Design.sparse_grid(campaign_level)
        say(f"level-{campaign_level} campaign ({len(design)} states)")
        with tempfile.TemporaryDirectory() as tmp:
            t1 = time.perf_counter()
            summary = run_campaign(Path(tmp) / "bench.zarr", design, SimulatorSpec("arm", {"profile": profile}),
                                   progress=False)
            result["campaign"] = {"level": campaign_level, "states": len(design), "wall_s": time.perf_counter() - t1,
                                  "done": summary["done"], "failed": summary["failed"],
                                  "mean_state_s": summary.get("wall_time_s_mean_done")}
    result["peak_memory"] = _peak_mb()
    return result


