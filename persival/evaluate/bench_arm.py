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

__all__ = ["run_arm_benchmark", "print_arm_benchmark"]


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


def print_arm_benchmark(result: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"FE arm from response tables ({result['profile']} profile; targets: docs/benchmarks.md)")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    tab = result["tables"]
    t.add_row("response tables: columns (angles x levels)", f"{tab['columns']} ({tab['angles']} x {tab['levels']})")
    t.add_row("response tables: column compute, all columns \\[s]", f"{tab['column_compute_s']:.0f}")
    t.add_row("response tables: this run \\[s] (0 when cached)", f"{tab['this_run_s']:.1f}")
    t.add_row("warm start: mesh + hanging arm + tables \\[s]", f"{result['warm_start_s']:.1f}")
    t.add_row("exact path per state, median / max \\[s]", f"{result['exact_s_median']:.2f} / {result['exact_s_max']:.2f}")
    t.add_row("table-only path per state, median \\[ms]", f"{1e3 * result['table_only_s_median']:.1f}")
    t.add_row("random states with their equilibrium outside the tables (skipped)", f"{len(result['outside_table'])}")
    for failure in result.get("exact_failed", []):
        t.add_row("random state whose exact path failed (not timed)",
                  f"alpha {np.round(failure['alpha'], 3).tolist()}: {failure['reason']} ({failure['seconds']:.1f} s)")
    rows = result["states"]
    t.add_row("table-only vs exact: angle, max \\[deg]",
              f"{max(abs(r['theta_exact'] - r['theta_table_only']) for r in rows):.3f}")
    t.add_row("table-only vs exact: node error max / mean \\[mm]",
              f"{max(r['table_only_node_error_max_mm'] for r in rows):.3f} / "
              f"{np.mean([r['table_only_node_error_mean_mm'] for r in rows]):.3f}")
    with_direct = [r for r in rows if "direct_s" in r]
    if with_direct:
        t.add_row(f"direct coupled solve per state, median of {len(with_direct)} \\[s]",
                  f"{np.median([r['direct_s'] for r in with_direct]):.1f}")
        t.add_row("exact vs direct: angle / node, max",
                  f"{max(abs(r['theta_exact'] - r['theta_direct']) for r in with_direct):.2e} deg / "
                  f"{max(r['exact_vs_direct_node_max_mm'] for r in with_direct):.2e} mm")
    t.add_row("largest |moment residual| \\[N mm] / max |J-1|",
              f"{max(abs(r['moment_residual_Nmm']) for r in rows):.1e} / {max(r['max_abs_J_minus_1'] for r in rows):.2%}")
    if "campaign" in result:
        c = result["campaign"]
        t.add_row(f"level-{c['level']} campaign: {c['states']} states, wall \\[min]",
                  f"{c['wall_s'] / 60:.1f} ({c['done']} done, {c['failed']} failed)")
        t.add_row("  + tables (column compute / 2 workers) \\[min]", f"{(c['wall_s'] + tab['column_compute_s'] / 2) / 60:.1f}")
    mem = result["peak_memory"]
    t.add_row("peak memory: this process / largest worker \\[MB]",
              f"{mem['this_process_MB']:.0f} / {mem['largest_worker_MB']:.0f}")
    Console().print(t)
