"""Command-line options of a campaign turned into its inputs: a Design and a SimulatorSpec.

Not in commands.py because other stages' commands build specs too (``surrogate adapt``) and no
commands.py imports another's.
"""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["build_design", "build_spec"]


def _parse_value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def build_design(design: str | None, level: int, n_random: int, seed: int):
    from persival.campaign.design import Design

    if design in (None, "sparse-grid"):
        return Design.sparse_grid(level)
    if design == "random":
        return Design.random(n_random, seed)
    return Design.from_file(design)


def build_spec(simulator: str, options: list[str], options_file: Path | None, command: str | None,
               reference: Path | None, surfaces: list[str], result_file: str | None):
    from persival.campaign.importers import parse_selector
    from persival.campaign.simulator import SimulatorSpec

    opts: dict = {}
    if options_file is not None:
        try:
            opts.update(json.loads(Path(options_file).read_text()))
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"--options {options_file}: {exc}") from None
    for item in options:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--option expects KEY=VALUE, got {item!r}")
        opts[key] = _parse_value(value)
    external = {"command": command, "reference": str(reference.resolve()) if reference else None,
                "result": result_file}
    if simulator != "external" and (any(external.values()) or surfaces):
        raise ValueError("--command, --reference, --surface and --result-file belong to "
                         "--simulator external")
    if simulator == "external":
        opts.update({k: v for k, v in external.items() if v})
        if surfaces:
            sel = {}
            for item in surfaces:
                name, sep, selector = item.partition("=")
                if not sep:
                    raise ValueError(f"--surface expects NAME=SELECTOR, got {item!r}")
                sel[name] = parse_selector(selector)
            opts["surfaces"] = sel
        missing = [k for k in ("command", "reference", "surfaces") if not opts.get(k)]
        if missing:
            raise ValueError(f"--simulator external needs {', '.join(missing)} "
                             "(--command, --reference, --surface NAME=SELECTOR, or --options FILE)")
    return SimulatorSpec(simulator, opts)
