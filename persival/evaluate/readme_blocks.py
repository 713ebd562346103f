"""The result blocks in README.md and docs/benchmarks.md: found between their markers and rewritten
from a run's results.json (the renderers: persival.evaluate.readme_tables), every character
outside the markers left as it was."""

from __future__ import annotations

import json
import re
from pathlib import Path

from persival.evaluate.readme_tables import BLOCKS

__all__ = ["BLOCKS", "DEFAULT_FILES", "load_results", "render", "rewrite", "rewrite_file"]

DEFAULT_FILES = ("README.md", "docs/benchmarks.md")
_MARKER = re.compile(r"<!-- results:(?P<name>[a-z0-9-]+) -->\n(?P<body>.*?)<!-- /results:(?P=name) -->", re.DOTALL)
_OPENING = re.compile(r"<!-- results:([a-z0-9-]+) -->")


def load_results(path: str | Path) -> dict:
    """A results.json of `persival report`; a ValueError for anything else."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--results {path}: no such results file (persival report writes RUN/report/results.json)")
    try:
        results = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"--results {path}: not JSON ({exc})") from None
    if not isinstance(results, dict) or results.get("format") != "persival-results":
        raise ValueError(f"--results {path}: not a results.json of `persival report` (no format 'persival-results')")
    return results


def render(name: str, results: dict) -> str | None:
    if name not in BLOCKS:
        raise ValueError(f"unknown result block {name!r}: known are {', '.join(BLOCKS)}")
    return BLOCKS[name](results)


def rewrite(text: str, results: dict) -> tuple[str, dict[str, str]]:
    """``text`` with every marked block rendered anew, and {block: "changed" | "unchanged" | "no numbers"}."""
    opened = _OPENING.findall(text)
    closed = [m["name"] for m in _MARKER.finditer(text)]
    if opened != closed:
        unclosed = sorted(set(opened) - set(closed)) or opened
        raise ValueError(f"result block without its closing marker: {', '.join(unclosed)}")
    status: dict[str, str] = {}

    def replace(match: re.Match) -> str:
        name, body = match["name"], match["body"]
        rendered = render(name, results)
        if rendered is None:  # keep what is written: a run without these numbers must not erase them
            status[name] = "no numbers"
            return match[0]
        new = rendered.rstrip("\n") + "\n"
        status[name] = "unchanged" if new == body else "changed"
        return f"<!-- results:{name} -->\n{new}<!-- /results:{name} -->"
    return _MARKER.sub(replace, text), status


def rewrite_file(path: str | Path, results: dict, check: bool = False) -> dict[str, str]:
    """Rewrite the blocks of ``path`` in place (not with ``check``); returns each block's status."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--file {path}: no such file")
    text = path.read_text()
    try:
        new, status = rewrite(text, results)
    except ValueError as exc:
        raise ValueError(f"--file {path}: {exc}") from None
    if not status:
        raise ValueError(f"--file {path}: no result block (<!-- results:NAME --> ... <!-- /results:NAME -->)")
    if new != text and not check:
        path.write_text(new)
    return status
