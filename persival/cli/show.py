"""What the command line prints: the library's results (benchmarks, the paper's tables, the
anatomy checks) as rich tables on the terminal. The library computes and returns them; only the
command line imports rich's tables."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from persival.evaluate.anatomy import limit_text, over_limit, worst_cases
from persival.evaluate.bench_fe import FEBenchmark
from persival.evaluate.bench_sparse_grid import BenchResult
from persival.evaluate.tables import cell, grid
from persival.model.arm.kinematics import ArmKinematics


def print_fe_benchmark(result: FEBenchmark) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"FE Newton iteration vs factorization ({result.backend})")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    rows = [
        ("tet10 cells", f"{result.cells}"),
        ("DOFs (free)", f"{result.dofs} ({result.free_dofs})"),
        ("surface nodes", f"{result.surface_nodes}"),
        ("assembly K + f \\[s]", f"{result.assembly_s:.4f}"),
        ("internal force f only \\[s]", f"{result.internal_force_s:.4f}"),
        ("symbolic analysis (once per pattern) \\[s]", f"{result.analysis_s:.4f}"),
        ("numerical factorization \\[s]", f"{result.factorization_s:.4f}"),
        ("triangular solves \\[s]", f"{result.solve_s:.4f}"),
        ("one Newton iteration \\[s]", f"{result.newton_iteration_s:.4f}"),
        ("Newton iteration / factorization", f"{result.ratio:.2f}  (target <= 1.5)"),
        ("full solve: load steps / Newton iterations", f"{result.load_steps} / {result.newton_iterations}"),
        ("full solve wall time \\[s]", f"{result.solve_wall_s:.2f}"),
        ("max |J - 1|", f"{result.max_volume_change:.2e}"),
    ]
    for name, value in rows:
        table.add_row(name, value)
    Console().print(table)


def print_sg_benchmark(result: BenchResult) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(
        title=f"Sparse grid: {result.n_points} points, {result.n_out} outputs per state",
    )
    table.add_column("operation")
    table.add_column("dtype")
    table.add_column("batch", justify="right")
    table.add_column("mean s/state", justify="right")
    table.add_column("median s/state", justify="right")
    table.add_column("reps", justify="right")
    for r in result.rows:
        table.add_row(r.what, r.dtype, str(r.batch), f"{r.seconds_per_state:.3e}",
                      f"{r.median_seconds_per_state:.3e}", str(r.repetitions))
    for what, sec in (("fit: LU factorize", result.fit_factorize_s),
                      (f"fit: solve {result.n_out} out", result.fit_solve_s)):
        table.add_row(what, "float64", "-", f"{sec:.3e}", "-", "1")
    Console().print(table)


def print_deployed_benchmark(result: dict) -> str:
    """Print the table; returns it as markdown (for docs/benchmarks.md)."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{result['states']} exact FE states at random activations (seed {result['seed']}, "
                  f"{result['profile']} profile; solved in {result['solve_seconds']:.0f} s)")
    for column in ("model", "worst MaxAE mm", "p95 MaxAE mm", "mean MAE mm", "worst angle error deg"):
        table.add_column(column, justify="left" if column == "model" else "right")
    lines = ["| model | worst MaxAE mm | p95 MaxAE mm | mean MAE mm | worst angle error deg |", "|---|---|---|---|---|"]
    for name, r in result["rows"].items():
        cells = [f"{r['max_ae_mm']:.2f}", f"{r['p95_max_ae_mm']:.2f}" if "p95_max_ae_mm" in r else "-", f"{r['mae_mm']:.3f}",
                 f"{r['max_angle_error_deg']:.3f}" if "max_angle_error_deg" in r else "-"]
        table.add_row(name, *cells)
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    Console().print(table)
    return "\n".join(lines) + "\n"


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


def to_rich(table: dict, columns: list[tuple[str, list[str]]] | None = None):
    """A rich Table. ``columns``: None for every column, or a narrow view for a terminal:
    (label, keys) pairs whose cell stacks the keys' values one per line (e.g. variant over
    runtime; "a|b": a, or b where a row has no a), paper rows marked "paper:" in their first
    cell. Cells are plain text, never markup (a "[peer]" in a cell is printed as written)."""
    from rich.table import Table
    from rich.text import Text

    if columns is None:
        header, body = grid(table)
        t = Table(title=table["title"], caption=table["description"] if len(table["description"]) < 200 else None)
        for k, h in enumerate(header):
            t.add_column(h or "", justify="left" if k < 3 else "right")
        for kind, cells in body:
            t.add_row(*(Text(c) for c in cells), style="dim" if kind == "paper" else None)
        return t
    from rich import box

    formats = {c["key"]: c["format"] for c in table["columns"]}
    body = []
    for kind, rows in (("ours", table["rows"]), ("paper", table["paper"])):
        for r in rows:
            cells = ["\n".join(_first(r, key, formats) for key in keys) for _, keys in columns]
            if kind == "paper":
                cells[0] = f"paper: {cells[0]}"
            body.append((kind, cells))
    t = Table(title=table["title"], box=box.SIMPLE_HEAD, padding=(0, 1), pad_edge=False)
    for k, (label, _) in enumerate(columns):
        if k == 0:  # takes what the numbers leave, wrapping at words
            t.add_column(label, justify="left")
        else:  # as wide as its widest entry, never wrapped
            width = max(len(line) for text in [label] + [c[k] for _, c in body] for line in text.splitlines())
            t.add_column(label, justify="right", no_wrap=True, width=width)
    for kind, cells in body:
        t.add_row(*(Text(c) for c in cells), style="dim" if kind == "paper" else None)
    return t


def _first(row: dict, keys: str, formats: dict) -> str:
    for key in keys.split("|"):
        if row.get(key) is not None:
            return cell(row[key], formats.get(key, "{}"))
    return "-"


def _cell(over: bool, text: str) -> str:
    return f"[red]{text}[/red]" if over else text


def print_anatomy_tables(console, results: list[dict], per_state_columns: int = 5) -> None:
    """The overlap and bed-gap tables: one column per state when there are few, else the worst state."""
    from rich.table import Table

    worst = worst_cases(results)
    few = len(results) <= per_state_columns
    table = Table(title=f"surface nodes of a body inside another ({len(results)} states; nodes within the attachment "
                        "distance of a muscle's ends left out; red: beyond the limit)")
    for column in ("body", "inside", "limit (mm)"):
        table.add_column(column)
    if few:
        for state in results:
            table.add_column(f"{state['state']}\n{state['elbow_angle_deg']:.0f} deg\nnodes, deepest", justify="right")
    else:
        for column in ("states", "most nodes", "deepest (mm)", "in state"):
            table.add_column(column, justify="right")
    for entry in worst["overlaps"]:
        a, b = entry["body"], entry["inside"]
        row = [a, b, limit_text(a, b)]
        if few:
            for state in results:
                hit = next((r for r in state["overlaps"] if (r["body"], r["inside"]) == (a, b)), None)
                row.append("" if hit is None else
                           _cell(over_limit(a, b, state["elbow_angle_deg"], hit["deepest_mm"]),
                                 f"{hit['nodes']}/{hit['of']}, {hit['deepest_mm']:.1f}"))
        else:
            row += [str(entry["states"]), f"{entry['most_nodes']}/{entry['of']}",
                    _cell(entry["over_states"] > 0, f"{entry['deepest_mm']:.1f}"),
                    f"{entry['deepest_state']} ({entry['deepest_angle_deg']:.0f} deg)"]
        table.add_row(*row)
    console.print(table)
    gaps = Table(title="largest gap between a muscle's belly and its bed (mm; at: position between origin 0 and "
                       "insertion 1)")
    gaps.add_column("muscle")
    gaps.add_column("bed")
    if few:
        for state in results:
            gaps.add_column(f"{state['state']}\n{state['elbow_angle_deg']:.0f} deg", justify="right")
    else:
        gaps.add_column("largest gap", justify="right")
        gaps.add_column("in state", justify="right")
    for entry in worst["bed_gaps"]:
        row = [entry["muscle"], ", ".join(entry["bed"])]
        if few:
            for state in results:
                hit = next(r for r in state["bed_gaps"] if r["muscle"] == entry["muscle"])
                gap = hit["largest_gap_mm"]
                row.append(f"{gap:.1f} at {hit['at_fraction']:.2f}" if gap > 0 else "0 (on its bed)")
        else:
            row += [f"{entry['largest_gap_mm']:.1f}", f"{entry['state']} ({entry['elbow_angle_deg']:.0f} deg)"]
        gaps.add_row(*row)
    console.print(gaps)


def check_outlines_table(console, model_file=None, out: Path | None = None) -> list[dict]:
    """The model file's muscle outlines across the humerus (persival.model.arm.cross_sections): a table
    of the overlaps per level, and the JSON file."""
    from rich.table import Table

    from persival.model.arm.cross_sections import LEVELS, outline_overlaps, where

    kinematics = ArmKinematics(model_file, check_outlines=False)  # here they are reported, not refused
    rows = outline_overlaps(kinematics)
    table = Table(title=f"{kinematics.spec.name}: outlines across the humerus overlapping each other or the bone, "
                        f"or outside the skin ({len(rows)} at {len(LEVELS)} levels; muscles in their mesh poses)")
    for column in ("level", "z (mm)", "outline", "where", "vertices", "deepest (mm)"):
        table.add_column(column, justify="right" if column in ("z (mm)", "vertices", "deepest (mm)") else "left")
    for r in rows:
        table.add_row(f"{100 * r['level']:.0f} %", f"{r['z_mm']:g}", r["outline"], where(r), f"{r['vertices']}/{r['of']}",
                      f"{r['deepest_mm']:.1f}")
    console.print(table if rows else "no outlines overlap or leave the skin at any level")
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"model": kinematics.spec.name, "levels": list(LEVELS), "overlaps": rows}, indent=1))
        console.print(f"wrote {out}")
    return rows
