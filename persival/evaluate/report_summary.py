"""The report's headline: how far the deployed model is from the simulator, how fast, how small.

Read, never recomputed, from the run folder: the deployed model's held-out accuracy from
``export/metadata.json`` (``provenance.deployed.held_out_fe``, when the export states it) or else
from the error-propagation table's row of the deployed network; its batch-1 time and file size
from the speed table and the export; the paper's figures beside them. The deployed model is named
as the export names it (``provenance.deployed.model`` or the deformation model's architecture),
so any model ``persival export`` writes is summarised the same way.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

from persival.evaluate import paper_values

__all__ = ["headline", "headline_html", "stage_records", "provenance_rows"]

VIEWER_SHOTS = ("report/viewer.png", "evaluate/viewer.png", "export/viewer.png")


def _metadata(out: Path) -> dict:
    path = out / "export" / "metadata.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def _held_out(meta: dict, name: str, tables: dict) -> dict | None:
    stated = (meta.get("provenance", {}).get("deployed") or {}).get("held_out_fe")
    table = tables.get("error_propagation")
    truth = (table or {}).get("truth_source", {}).get("label")
    if stated:
        return {**stated, "truth": truth or "held-out FE states", "from": "export/metadata.json"}
    if table:
        for row in table["rows"]:
            if row.get("surrogate") in (f"{name} NN", name) and row.get("scope") == "all" \
                    and "held-out" in str(row.get("tested_on")):
                return {"states": row.get("states"), "max_ae_mm": row.get("max MaxAE_mm"), "mae_mm": row.get("mean MAE_mm"),
                        "max_angle_error_deg": row.get("max angle_error_deg"), "truth": truth,
                        "from": "error_propagation table"}
    return None


def _speed(tables: dict) -> dict | None:
    bench = tables.get("bench_nn")
    best = (bench or {}).get("targets", {}).get("deployed_best")
    if not best:
        return None
    paper_tflite = next(r["ms_per_call"] for r in paper_values.SPEED if r["runtime"] == "TFLite (paper)")
    ours = bench["targets"].get("tflite_ms_batch1")
    return {"variant": best["variant"], "threads": best["threads"], "batch1_ms": best["ms_per_state"],
            "paper_tflite_ms": paper_tflite, "tflite_peer_here_ms": ours,
            "speedup_vs_peer_here": ours / best["ms_per_state"] if ours else None}


def _size(meta: dict, tables: dict) -> dict | None:
    variants = meta.get("models", {}).get("deformation", {}).get("variants", {})
    if "float32" not in variants:
        return None
    rows = (tables.get("bench_nn") or {}).get("rows", [])
    tflite = [r for r in rows if str(r.get("runtime", "")).startswith("TFLite") and r.get("file_mb")]
    torch_ = [r for r in rows if str(r.get("variant", "")).startswith("paper arch") and r.get("file_mb")]
    paper = (tflite or torch_ or [{}])[0]
    return {"float32_mb": variants["float32"]["bytes"] / 1e6, "target_mb": 2.0,
            "paper_architecture_mb": paper.get("file_mb"), "paper_architecture_parameters": paper.get("parameters"),
            "paper_architecture_as": "TFLite flatbuffer" if tflite else "float32 weights (4 bytes per parameter)"}


def headline(out: str | Path, tables: dict) -> dict:
    """The summary's numbers (results.json ``summary``)."""
    out = Path(out)
    meta = _metadata(out)
    deformation = meta.get("models", {}).get("deformation", {})
    name = (meta.get("provenance", {}).get("deployed") or {}).get("model") or deformation.get("architecture") \
        or "deployed model"
    viewer = next((s for s in VIEWER_SHOTS if (out / s).is_file()), None)
    paper_nn = next(r for r in paper_values.ERROR_PROPAGATION if "NN" in r["surrogate"])
    contract = (meta.get("provenance", {}).get("deployed") or {}).get("angle_contract")
    return {"deployed_model": name, "nodes": meta.get("n_nodes"), "held_out": _held_out(meta, name, tables),
            "angle_contract": contract,
            "paper_held_out": {"max_ae_mm": paper_nn["max MaxAE_mm"], "mae_mm": paper_nn["mean MAE_mm"],
                               "states": paper_nn["states"], "scope": "biceps, the paper's arm"},
            "speed": _speed(tables), "size": _size(meta, tables),
            "pictures": {"arm": "fe/arm.png" if (out / "fe" / "arm.png").is_file() else None, "viewer": viewer}}


def _f(value, fmt: str, unit: str = "") -> str:
    return "-" if value is None else f"{fmt.format(value)}{unit}"


def headline_html(summary: dict, image) -> str:
    """The summary section; ``image(relative_path) -> data URI`` embeds a picture of the run."""
    esc = html.escape
    held, paper, speed, size = summary["held_out"], summary["paper_held_out"], summary["speed"], summary["size"]
    rows = []
    if held:
        rows.append(("accuracy against " + esc(str(held.get("truth") or "held-out states")),
                     f"worst state MaxAE {_f(held.get('max_ae_mm'), '{:.2f}', ' mm')}, mean MAE "
                     f"{_f(held.get('mae_mm'), '{:.2f}', ' mm')}, worst elbow-angle error "
                     f"{_f(held.get('max_angle_error_deg'), '{:.2f}', ' deg')} (all muscles)",
                     f"{paper['max_ae_mm']:.2f} mm / {paper['mae_mm']:.2f} mm ({paper['scope']}, {paper['states']} FE states)"))
    contract = summary.get("angle_contract")
    if contract:
        rows.append(("the angle asked for (with a load in the hand) against the angle shown",
                     f"within {contract['max_angle_error_deg']:.2f} deg (mean {contract['mean_angle_error_deg']:.3f}) "
                     f"on {contract['requests']} random requests, {contract['angle_range_deg'][0]:.0f}-"
                     f"{contract['angle_range_deg'][1]:.0f} deg, loads up to {contract['max_load_kg']:.2f} kg",
                     "not reported"))
    if speed:
        here = (f"; the paper's architecture as TFLite here: {speed['tflite_peer_here_ms']:.2f} ms, "
                f"{speed['speedup_vs_peer_here']:.0f}x slower") if speed.get("tflite_peer_here_ms") else ""
        rows.append(("one state, batch 1 (CPU)", f"{speed['batch1_ms']:.3f} ms ({esc(speed['variant'])}, "
                     f"{speed['threads']} thread){here}", f"{speed['paper_tflite_ms']:.2f} ms (TFLite, their i5)"))
    if size:
        rows.append(("model file (float32)", f"{size['float32_mb']:.2f} MB (target: at most {size['target_mb']:g} MB)",
                     f"{_f(size['paper_architecture_mb'], '{:.1f}', ' MB')} (their architecture, "
                     f"{esc(size['paper_architecture_as'])})"))
    nodes = f", {summary['nodes']} surface nodes" if summary.get("nodes") else ""
    source = f" (accuracy from the {esc(held['from'])})" if held else ""
    parts = ['<section id="summary"><h2>Summary</h2>',
             f"<p>The deployed model: <strong>{esc(str(summary['deployed_model']))}</strong>{nodes}{source}.</p>",
             '<table class="summary"><thead><tr><th>what</th><th>PerSival</th><th>the paper</th></tr></thead><tbody>']
    parts += [f"<tr><td>{a}</td><td>{b}</td><td>{c}</td></tr>" for a, b, c in rows]
    parts.append("</tbody></table>")
    pictures = [(p, cap) for p, cap in ((summary["pictures"]["arm"], "the FE arm"),
                                        (summary["pictures"]["viewer"], "the web viewer (default view)")) if p]
    if pictures:
        parts.append('<div class="pictures">' + "".join(
            f'<figure><img alt="{esc(cap)}" src="{image(p)}"><figcaption>{esc(cap)}: {esc(p)}</figcaption></figure>'
            for p, cap in pictures) + "</div>")
    parts.append("</section>")
    return "\n".join(parts)


def stage_records(out: str | Path) -> dict | None:
    """Every stage's record (OUT/<stage>/stage.json: digest, inputs, wall time, summary), by stage,
    plus the run's own record (run.json) when the run has finished."""
    out = Path(out)
    records = {}
    for path in sorted(out.glob("*/stage.json")):
        try:
            record = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            continue
        records[record.get("stage", path.parent.name)] = record
    run = out / "run.json"
    if run.is_file():
        records["run"] = json.loads(run.read_text())
    return records or None


def provenance_rows(environment: dict) -> list[tuple[str, str]]:
    """(what, value) rows: the source revision, the versions, the machine, the date."""
    git = environment.get("git", {})
    rows = [("git commit", git.get("commit") or "not a git checkout"), ("git branch", git.get("branch") or "-"),
            ("uncommitted changes", {True: "yes", False: "no"}.get(git.get("dirty"), "-"))]
    rows += [(name, str(version)) for name, version in environment.get("versions", {}).items()]
    machine = environment.get("machine", {})
    rows += [("platform", str(machine.get("platform"))), ("processor", str(machine.get("processor"))),
             ("CPUs", str(machine.get("cpu_count"))), ("date", str(environment.get("date")))]
    return rows
