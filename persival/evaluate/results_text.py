"""Numbers of a run's results.json as the README's result blocks print them: formats (mm, ms, MB),
markdown rows and tables, and the lookups the blocks share (a held-out row, a benchmark row, an
export's tiers, a stage's record, the machine and commit it ran on)."""

from __future__ import annotations

import re
import textwrap
from collections.abc import Callable

DEPLOYED = re.compile(r"^(?P<role>deployed|exported) (?P<arch>\S+) ONNX (?P<tier>\S+)$")
NAMES = {"structured": "structured model", "pod": "POD network", "paper": "paper network"}


def format_mm(value) -> str:
    """Lengths and angles: two decimals, three below 0.1 (0.042 mm would read 0.04)."""
    if value is None:
        return "-"
    return f"{value:.2f}" if abs(value) >= 0.1 else f"{value:.3f}"


def format_ms(value) -> str:
    """Times: about three significant digits, from 0.023 ms to 101.3 ms."""
    if value is None:
        return "-"
    return f"{value:.3f}" if value < 1 else f"{value:.2f}" if value < 10 else f"{value:.1f}"


def format_mb(value) -> str:
    if value is None:
        return "-"
    return f"{value:.2f}" if value < 10 else f"{value:.1f}"


def minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min"


def joined(values, fmt: Callable, unit: str) -> str:
    """``a / b / c unit``; an empty string where no value is known (a blank cell)."""
    if all(v is None for v in values):
        return ""
    return " / ".join(fmt(v) for v in values) + f" {unit}"


def markdown_row(cells) -> str:
    return "|" + "|".join(f" {c} " if c else " " for c in cells) + "|"


def paragraph(text: str) -> str:
    # wrapped as the hand-written prose around it, so that a regenerated block diffs line by line
    return textwrap.fill(text, width=100, break_long_words=False, break_on_hyphens=False)


def markdown_table(header, rows) -> str:
    return "\n".join([markdown_row(header), "|" + "---|" * len(header), *(markdown_row(r) for r in rows)])


def run_tables(results: dict, name: str) -> dict:
    return (results.get("tables") or {}).get(name) or {}


def held_out_row(results: dict, surrogate: str, scope: str = "all") -> dict | None:
    """A row of the error-propagation table against the held-out states (not the SG's support points)."""
    for row in run_tables(results, "error_propagation").get("rows", []):
        if row.get("surrogate") == surrogate and row.get("scope") == scope and "held-out" in str(row.get("tested_on")):
            return row
    return None


def paper_row(table: dict, word: str) -> dict | None:
    return next((r for r in table.get("paper", []) if word in str(r.get("surrogate") or r.get("network"))), None)


def deployed_model(results: dict) -> str | None:
    return (results.get("summary") or {}).get("deployed_model")


def deployed_held_out(results: dict) -> dict | None:
    return (results.get("summary") or {}).get("held_out")


def truth(results: dict) -> str:
    """What the held-out states are: FE states only when the FE arm solved them."""
    source = run_tables(results, "error_propagation").get("truth_source") or {}
    simulator = str(source.get("simulator", ""))
    return "FE" if simulator.startswith("arm") else simulator or "simulator"


def bench_rows(results: dict) -> list[dict]:
    return run_tables(results, "bench_nn").get("rows", [])


def bench_row(results: dict, match: Callable[[dict], bool], threads: int = 1, batch: int = 1) -> dict | None:
    return next((r for r in bench_rows(results) if r.get("threads") == threads and r.get("batch") == batch
                 and match(r)), None)


def exports(results: dict) -> dict[tuple[str, str], list[str]]:
    """{(role, architecture): [tiers in the bench's order]} of the ONNX rows (role: deployed or exported)."""
    found: dict[tuple[str, str], list[str]] = {}
    for row in bench_rows(results):
        m = DEPLOYED.match(str(row.get("variant")))
        if m and m["tier"] not in found.setdefault((m["role"], m["arch"]), []):
            found[(m["role"], m["arch"])].append(m["tier"])
    return found


def tier_rows(results, role, arch, tiers, threads, batch) -> list[dict | None]:
    return [bench_row(results, lambda r, t=t: r.get("variant") == f"{role} {arch} ONNX {t}", threads, batch) for t in tiers]


def stage_record(results: dict, name: str) -> dict:
    return (results.get("stages") or {}).get(name) or {}


def measured(results: dict) -> str:
    """Date, commit and machine of the run (results.json ``provenance``)."""
    provenance = results.get("provenance") or {}
    parts = [str(provenance.get("date", ""))[:10] or None]
    git = provenance.get("git") or {}
    if git.get("commit"):
        parts.append(f"commit {git['commit'][:7]}" + (" with uncommitted changes" if git.get("dirty") else ""))
    cpus = (provenance.get("machine") or {}).get("cpu_count")
    parts.append(f"{cpus} CPUs" if cpus else None)
    return ", ".join(p for p in parts if p)


def command(results: dict) -> str:
    return (results.get("provenance") or {}).get("report_command") or "persival report"


def sg_label(results: dict) -> str:
    sg = (results.get("configuration") or {}).get("sg") or {}
    if sg.get("level") is None or sg.get("grid_points") is None:
        return "sparse grid"
    return f"sparse grid, level {sg['level']} ({sg['grid_points']} {truth(results)} states)"
