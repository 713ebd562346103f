"""`persival report`: one self-contained HTML page of a run, and ``results.json`` with every table.

``write_report(out)`` reads ``OUT/evaluate/`` (the tables of :func:`persival.evaluate.evaluation.evaluate_run`
and its figures) plus every other figure of the run, and writes ``OUT/report/index.html`` (figures
embedded as base64 PNG, no script, no external file) and ``OUT/report/results.json``. Each number
carries its provenance: the command and inputs of its table, the training and SG configuration,
the package versions, the machine and the date.
"""

from __future__ import annotations

import base64
import datetime as _dt
import hashlib
import html
import json
from pathlib import Path

from persival.evaluate.report_summary import headline, headline_html, provenance_rows, stage_records
from persival.evaluate.tables import load_table, to_html

__all__ = ["write_report", "TABLE_ORDER"]

TABLE_ORDER = ("in_training", "random_activations", "random_angles", "error_propagation", "prototypes", "bench_nn",
               "anatomy")

_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1240px; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.8em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.4em; text-align: right; }
th { min-width: 3.5em; vertical-align: bottom; }
td:first-child { min-width: 7em; }
th { background: #f0f0f0; } td:nth-child(-n+3) { text-align: left; }
tr.paper td { background: #fff8e6; color: #555; font-style: italic; }
.scroll { overflow-x: auto; } figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
code, pre { font-size: 0.8em; } pre { background: #f6f6f6; padding: 0.5em; overflow-x: auto; }
.provenance { color: #666; font-size: 0.75em; word-break: break-all; }
#summary { background: #f4f8fc; border: 1px solid #cfe0f0; padding: 0.3em 1em 1em; border-radius: 6px; }
table.summary td, table.summary th { white-space: normal; text-align: left; vertical-align: top; }
table.summary td:first-child { font-weight: 600; }
.pictures { display: flex; gap: 1em; flex-wrap: wrap; } .pictures figure { flex: 1 1 420px; margin: 0.5em 0; }
table.kv td { text-align: left; white-space: normal; }
"""


CAPTIONS = {
    "hotspots_biceps.png": "Error hot spots: each biceps node's mean error |x_net - x_SG| over 500 random activations "
                           "(paper net after a short and after its full training, POD net), at the reference pose.",
    "activation_model.png": "alpha_opt(Theta): the least-effort activations over the reachable range (SG).",
    "history_paper.png": "Training history of the paper net: validation MAE per coordinate net and the losses per epoch.",
    "history_pod.png": "Training history of the POD net: validation MAE per coordinate and the losses per epoch.",
}


def _caption(relative: str) -> str:
    name = Path(relative).name
    return f"{CAPTIONS[name]} ({relative})" if name in CAPTIONS else relative


def _figures(out: Path) -> list[tuple[str, Path]]:
    """(caption, path): the evaluation figures first, then every other PNG of the run, each picture once."""
    seen, found = set(), []
    candidates = sorted((out / "evaluate").glob("*.png")) + sorted(
        p for p in out.rglob("*.png") if "report" not in p.relative_to(out).parts[:1]
        and p.relative_to(out).parts[0] != "evaluate")
    for path in candidates:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        if digest in seen:
            continue
        seen.add(digest)
        found.append((_caption(str(path.relative_to(out))), path))
    return found


def _configs(out: Path) -> dict:
    """The configuration behind the numbers: SG, activation model, networks, export."""
    configs = {}
    sg = out / "sg" / "surrogate.json"
    if sg.is_file():
        meta = json.loads(sg.read_text())
        configs["sg"] = {k: meta.get(k) for k in ("label", "simulator", "profile", "level", "degree", "grid_points",
                                                 "muscles", "model_hash")}
    model = out / "inverse" / "activation_model.json"
    if model.is_file():
        meta = json.loads(model.read_text())
        configs["activation_model"] = {"range_deg": [meta["knots_deg"][0], meta["knots_deg"][-1]], **meta.get("metadata", {})}
    for label in ("paper", "pod"):
        path = out / "networks" / label / "surrogate.json"
        if path.is_file():
            meta = json.loads(path.read_text())
            training = meta.get("training", {})
            configs[f"network_{label}"] = {"net": meta.get("net"), "parameters": meta.get("parameters"),
                                           "config": training.get("config"), "best": training.get("best"),
                                           "wall_time_s": training.get("wall_time_s"),
                                           "dataset_sha256": training.get("dataset_sha256"),
                                           "source": meta.get("source", {}).get("label")}
    export = out / "export" / "metadata.json"
    if export.is_file():
        meta = json.loads(export.read_text())
        configs["export"] = {"provenance": {k: v for k, v in meta.get("provenance", {}).items() if k != "training"},
                             "variants": {t: {k: v.get(k) for k in ("file", "bytes")}
                                          for t, v in meta.get("models", {}).get("deformation", {}).get("variants", {}).items()}}
    return configs


def _load_tables(folder: Path) -> dict[str, dict]:
    tables = {}
    for path in sorted(folder.glob("*.json")):
        try:
            table = load_table(path)
        except (ValueError, json.JSONDecodeError):
            continue  # evaluation.json, hot-spot summaries: not tables
        tables[table["name"]] = table
    order = [n for n in TABLE_ORDER if n in tables] + sorted(n for n in tables if n not in TABLE_ORDER)
    return {n: tables[n] for n in order}


def _data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _kv_table(rows) -> str:
    esc = html.escape
    return '<table class="kv">' + "".join(f"<tr><td>{esc(str(k))}</td><td>{esc(str(v))}</td></tr>" for k, v in rows) + "</table>"


def _page(out: Path, tables: dict, figures: list, provenance: dict, configs: dict, source: str, summary: dict,
          stages: dict | None) -> str:
    esc = html.escape
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">', '<link rel="icon" href="data:,">',
             f"<title>PerSival report: {esc(out.name)}</title><style>{_CSS}</style></head><body>",
             "<h1>PerSival: the paper's tables on our arm</h1>",
             f"<p>Run folder <code>{esc(str(out))}</code>; data: <strong>{esc(source)}</strong>. "
             "Rows marked <em>paper</em> are the paper's figures for its own arm model, beside ours.</p>",
             headline_html(summary, lambda rel: _data_uri(out / rel)),
             "<h2>Contents</h2><ul>" + "".join(f'<li><a href="#table-{esc(n)}">{esc(t["title"])}</a></li>'
                                               for n, t in tables.items())
             + '<li><a href="#figures">Figures</a></li><li><a href="#provenance">Provenance</a></li></ul>',
             "<h2>Tables</h2>"]
    parts += [f'<div class="scroll">{to_html(t)}</div>' for t in tables.values()]
    parts.append('<h2 id="figures">Figures</h2>')
    for caption, path in figures:
        parts.append(f'<figure><img alt="{esc(caption)}" src="{_data_uri(path)}">'
                     f"<figcaption>{esc(caption)}</figcaption></figure>")
    parts.append('<h2 id="provenance">Provenance</h2>')
    parts.append(_kv_table([("report command", provenance.get("report_command")), *provenance_rows(provenance)]))
    if stages:
        parts.append("<h3>Stages of the run</h3>")
        parts.append(_kv_table([(name, f"{r['wall_time_s']:.1f} s, inputs digest {r.get('digest')}")
                                for name, r in stages.items() if name != "run" and "wall_time_s" in r]))
    parts.append("<details><summary>Every table's inputs and the full record (JSON)</summary>")
    parts.append(f"<pre>{esc(json.dumps(provenance, indent=1, default=str))}</pre></details>")
    parts.append("<h3>Configuration</h3>")
    parts.append(f"<pre>{esc(json.dumps(configs, indent=1, default=str))}</pre>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(out: str | Path, command: str | None = None) -> Path:
    """``OUT/report/index.html`` and ``OUT/report/results.json``; returns the HTML's path."""
    from persival.evaluate.evaluation import default_command, deployed_summary, environment

    out = Path(out)
    folder = out / "evaluate"
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no evaluation in this run folder (run `persival evaluate --run {out}` first)")
    tables = _load_tables(folder)
    if not tables:
        raise FileNotFoundError(f"{folder}: no table (run `persival evaluate --run {out}` first)")
    tables |= _load_tables(out / "anatomy")  # the run's anatomy (persival.evaluate.anatomy_run), when measured
    evaluation = json.loads((folder / "evaluation.json").read_text()) if (folder / "evaluation.json").is_file() else {}
    provenance = {"report_command": command or default_command(out, "report"), **environment(),
                  "evaluation": evaluation.get("provenance"), "skipped": evaluation.get("skipped", {}),
                  "tables": {n: t.get("provenance") for n, t in tables.items()}}
    configs = _configs(out)
    figures = _figures(out)
    source = evaluation.get("source") or configs.get("sg", {}).get("label") or "unknown source"
    summary, stages = headline(out, tables), stage_records(out)
    report = out / "report"
    report.mkdir(parents=True, exist_ok=True)
    index = report / "index.html"
    index.write_text(_page(out, tables, figures, provenance, configs, source, summary, stages))
    results = {"format": "persival-results", "run": str(out), "source": source,
               "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"), "summary": summary,
               "provenance": provenance, "configuration": configs, "tables": tables,
               "figures": [c for c, _ in figures], "stages": stages,
               # the export's own record, read now: an export redone after the evaluation (its
               # activation models, their angle contract) is what the report describes
               "deployed": deployed_summary(out / "export") or evaluation.get("deployed")}
    (report / "results.json").write_text(json.dumps(results, indent=1, default=float))
    return index
