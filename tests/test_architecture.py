"""Imports flow one way (SPEC 2): model -> tables -> campaign -> surrogate -> deploy -> evaluate.

Reads every module's imports with ast (function-level imports included, and "module:attr"
strings that a registry imports by name) and fails on one that reaches a later stage. The
top-level helpers (vocabulary, grid_points, cli_errors, ...) sit below every stage; pipeline,
cli and run_command sit above them all and may import anything.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "persival"
STAGES = ("model", "tables", "campaign", "surrogate", "deploy", "evaluate")
TOP = {"persival.pipeline", "persival.stages", "persival.stages_arm", "persival.cli", "persival.run_command"}
BOTTOM, ABOVE_ALL = -1, len(STAGES)
# a lazily imported factory, e.g. "persival.campaign.analytic:AnalyticSimulator"
LAZY_TARGET = re.compile(r"^(persival(?:\.\w+)+):\w+$")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def rank(module: str) -> int:
    """Position in the pipeline: BOTTOM for top-level helpers, ABOVE_ALL for the sequencers."""
    if module in TOP:
        return ABOVE_ALL
    parts = module.split(".")
    if len(parts) >= 2 and parts[1] in STAGES:
        return STAGES.index(parts[1])
    return BOTTOM


def imported_modules(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, module) of every persival module imported by ``path``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = module.split(".")[: len(module.split(".")) - node.level + is_package]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # `from persival.model import arm` imports the module persival.model.arm
            found += [(node.lineno, target)] + [(node.lineno, f"{target}.{a.name}") for a in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            match = LAZY_TARGET.match(node.value)
            if match:
                found.append((node.lineno, match.group(1)))
    return [(line, name) for line, name in found if name == "persival" or name.startswith("persival.")]


def modules():
    return sorted((p, module_name(p)) for p in PACKAGE.rglob("*.py") if "node_modules" not in p.parts)


def violations() -> tuple[list[str], int]:
    problems, n_imports = [], 0
    for path, module in modules():
        for line, target in imported_modules(path, module):
            n_imports += 1
            where = f"{path.relative_to(PACKAGE.parent)}:{line}"
            if rank(target) > rank(module):
                problems.append(f"{where}: {module} (stage {rank(module)}) imports later {target} (stage {rank(target)})")
            if module.endswith(".commands") and target.endswith(".commands") and target.split(".")[1] != module.split(".")[1]:
                problems.append(f"{where}: {module} imports another stage's commands, {target}")
    return problems, n_imports


def test_imports_only_look_upstream():
    problems, n_imports = violations()
    print(f"\n{len(modules())} modules, {n_imports} imports of persival modules checked")
    assert not problems, "backward imports:\n" + "\n".join(problems)


def test_the_checker_sees_a_backward_import(tmp_path):
    # The checker itself: a later-stage import, a relative one, a lazy name and a commands import.
    source = ("from persival.surrogate.sparse_grid import SparseGrid\n"
              "def f():\n    from ..evaluate import metrics\n"
              "LAZY = {'x': 'persival.deploy.server:app'}\n"
              "from persival.model import commands\n")
    path = tmp_path / "fake.py"
    path.write_text(source)
    found = {name for _, name in imported_modules(path, "persival.campaign.commands")}
    assert {"persival.surrogate.sparse_grid", "persival.evaluate.metrics", "persival.deploy.server",
            "persival.model.commands"} <= found
    assert rank("persival.vocabulary") < rank("persival.model.arm") < rank("persival.evaluate.render") < rank("persival.cli")
