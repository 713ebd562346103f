"""One table format for every result of the evaluation stage: a dict, Markdown, HTML, rich.

A table is a plain dict (so ``results.json`` is just the tables):

    {"name": "random_activations", "title": "...", "description": "...",
     "columns": [{"key": "max MaxAE_mm", "label": "MaxAE mm (worst state)", "format": "{:.3f}"}, ...],
     "rows": [{"network": "paper", "scope": "biceps", "max MaxAE_mm": 1.23, ...}, ...],
     "paper": [{"network": "paper's NN", ...}],    # the paper's figures, same keys (may be [])
     "notes": ["..."], "provenance": {"command": ..., "inputs": ..., "config": ...}, ...}

Rows and paper rows share the column keys; a missing key prints as a dash.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

__all__ = ["make_table", "cell", "grid", "to_markdown", "to_html", "save_table", "load_table"]


def make_table(name: str, title: str, description: str, columns: list[tuple[str, str, str]], rows: list[dict],
               paper: list[dict] | None = None, notes: list[str] | None = None, **extra) -> dict:
    """``columns``: (key, label, format) triples; ``extra``: anything else to keep (draws, config...)."""
    return {"name": name, "title": title, "description": description,
            "columns": [{"key": k, "label": label, "format": fmt} for k, label, fmt in columns],
            "rows": rows, "paper": list(paper or []), "notes": list(notes or []), **extra}


def cell(value, fmt: str = "{}") -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, str):
        return value
    try:
        return fmt.format(value)
    except (ValueError, TypeError):
        return str(value)


def grid(table: dict) -> tuple[list[str], list[tuple[str, list[str]]]]:
    """Header labels and (kind, cells) rows: ours first, then the paper's (a first column says
    whose, when the table has the paper's rows)."""
    cols = table["columns"]
    whose = [""] if table["paper"] else []
    header = [*whose, *(c["label"] for c in cols)]
    body = [("ours", [*(["PerSival"] if whose else []), *(cell(r.get(c["key"]), c["format"]) for c in cols)])
            for r in table["rows"]]
    body += [("paper", ["paper", *(cell(r.get(c["key"]), c["format"]) for c in cols)]) for r in table["paper"]]
    return header, body


def to_markdown(table: dict) -> str:
    header, body = grid(table)
    lines = [f"### {table['title']}", "", table["description"], ""]
    lines.append("| " + " | ".join(header) + " |")
    lines.append("|" + "|".join("---" for _ in header) + "|")
    lines += ["| " + " | ".join(c.replace("|", "/") for c in cells) + " |" for _, cells in body]
    if table["notes"]:
        lines.append("")
        lines += [f"- {n}" for n in table["notes"]]
    prov = table.get("provenance")
    if prov:
        lines += ["", f"Provenance: `{prov.get('command', '')}`; " + json.dumps(
            {k: v for k, v in prov.items() if k != "command"}, default=str)]
    return "\n".join(lines) + "\n"


def to_html(table: dict) -> str:
    header, body = grid(table)
    esc = html.escape
    out = [f'<section class="table" id="table-{esc(table["name"])}">', f"<h3>{esc(table['title'])}</h3>",
           f"<p>{esc(table['description'])}</p>", "<table>",
           "<thead><tr>" + "".join(f"<th>{esc(h)}</th>" for h in header) + "</tr></thead><tbody>"]
    for kind, cells in body:
        out.append(f'<tr class="{kind}">' + "".join(f"<td>{esc(c)}</td>" for c in cells) + "</tr>")
    out.append("</tbody></table>")
    if table["notes"]:
        out.append("<ul>" + "".join(f"<li>{esc(n)}</li>" for n in table["notes"]) + "</ul>")
    prov = table.get("provenance")
    if prov:
        out.append(f'<p class="provenance">provenance: <code>{esc(json.dumps(prov, default=str))}</code></p>')
    out.append("</section>")
    return "\n".join(out)


def save_table(table: dict, folder: str | Path) -> tuple[Path, Path]:
    """``folder/<name>.md`` and ``folder/<name>.json``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    md, js = folder / f"{table['name']}.md", folder / f"{table['name']}.json"
    md.write_text(to_markdown(table))
    js.write_text(json.dumps(table, indent=1, default=float))
    return md, js


def load_table(path: str | Path) -> dict:
    table = json.loads(Path(path).read_text())
    if not isinstance(table, dict) or not {"name", "columns", "rows"} <= set(table):
        raise ValueError(f"{path} is not an evaluation table")
    table.setdefault("paper", [])
    table.setdefault("notes", [])
    return table
