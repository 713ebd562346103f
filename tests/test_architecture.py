"""Imports flow one way (SPEC 2): model -> tables -> campaign -> surrogate -> deploy -> evaluate,
and inside the model the FE core, the anatomy and the arm: fe -> anatomy -> arm.

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
STAGES = ("model.fe", "model.anatomy", "model.arm", "tables", "campaign", "surrogate", "deploy", "evaluate")
TOP = {"persival.pipeline", "persival.pipeline.stages", "persival.pipeline.arm_stages"}  # and the command line, persival.cli.*
BOTTOM, ABOVE_ALL = -1, len(STAGES)
# a lazily imported factory, e.g. "persival.campaign.analytic:AnalyticSimulator"
LAZY_TARGET = re.compile(r"^(persival(?:\.\w+)+):\w+$")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def rank(module: str) -> int:
    """Position in the pipeline: BOTTOM for top-level helpers, ABOVE_ALL for the sequencers."""
    if module in TOP or module == "persival.cli" or module.startswith("persival.cli."):
        return ABOVE_ALL
    parts = module.split(".")
    for depth in (3, 2):  # a model layer (persival.model.fe) before a stage (persival.tables)
        if len(parts) >= depth and ".".join(parts[1:depth]) in STAGES:
            return STAGES.index(".".join(parts[1:depth]))
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
            # `from persival.model.fe import tet10` imports the module persival.model.fe.tet10
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
    return problems, n_imports


def test_imports_only_look_upstream():
    problems, n_imports = violations()
    print(f"\n{len(modules())} modules, {n_imports} imports of persival modules checked")
    assert not problems, "backward imports:\n" + "\n".join(problems)


def test_the_checker_sees_a_backward_import(tmp_path):
    # The checker itself: a later-stage import, a relative one, a lazy name and a command-line import.
    source = ("from persival.surrogate.sparse_grid import SparseGrid\n"
              "def f():\n    from ..evaluate import metrics\n"
              "LAZY = {'x': 'persival.deploy.server:app'}\n"
              "from persival.cli import model\n")
    path = tmp_path / "fake.py"
    path.write_text(source)
    found = {name for _, name in imported_modules(path, "persival.campaign.runner")}
    assert {"persival.surrogate.sparse_grid", "persival.evaluate.metrics", "persival.deploy.server",
            "persival.cli.model"} <= found
    assert rank("persival.vocabulary") < rank("persival.model.fe.solver") < rank("persival.model.anatomy.walls")
    assert rank("persival.model.anatomy.walls") < rank("persival.model.arm.body") < rank("persival.tables.open")
    assert rank("persival.tables.open") < rank("persival.evaluate.render") < rank("persival.cli")


def _runtime_imports(path: Path, module: str) -> set[str]:
    """The persival modules ``path`` imports by statement (not a registry's lazy name, not under
    ``if TYPE_CHECKING:``, not its own parent package, which Python imports first anyway)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                   and getattr(node.test, "id", None) == "TYPE_CHECKING" for n in ast.walk(node)}
    names = {m for _, m in imported_modules(path, module)}
    typed = {m for node in ast.walk(tree) if id(node) in typing_only and isinstance(node, ast.ImportFrom)
             for m in [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]}
    lazy = {match.group(1) for node in ast.walk(tree) if isinstance(node, ast.Constant) and isinstance(node.value, str)
            for match in [LAZY_TARGET.match(node.value)] if match}
    return {m for m in names - typed - lazy if not module.startswith(m + ".")}


def test_no_import_circles():
    """No module reaches itself through its imports (a type-only import aside): each idea can be
    read, tested and replaced on its own."""
    known = dict(modules())
    graph = {m: {t for t in _runtime_imports(p, m) if t in known.values() and t != m} for p, m in known.items()}
    circles = []
    for start in graph:  # depth-first search for a path back to start
        stack, seen = [(start, [start])], set()
        while stack:
            node, path = stack.pop()
            for nxt in graph.get(node, ()):
                if nxt == start:
                    circles.append(" -> ".join(path + [start]))
                elif nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, path + [nxt]))
    assert not circles, "import circles:\n" + "\n".join(sorted(set(circles)))


def test_only_the_command_line_imports_typer_and_rich():
    """The library is used from Python as well: typer (the command line's parser) and rich (its
    terminal output) stay in persival.cli; the library reports through persival.progress."""
    offenders = [f"{path.relative_to(PACKAGE.parent)}" for path, module in modules()
                 if not (module == "persival.cli" or module.startswith("persival.cli."))
                 and re.search(r"^\s*(import (typer|rich)|from (typer|rich)[ .])", path.read_text(), re.M)]
    assert not offenders, "typer or rich imported outside persival.cli: " + ", ".join(offenders)


# Modules over 300 lines and functions over 60: each a numerical kernel (its docstring says why) or
# a command's option list. A new one fails here: look for the second idea inside it.
LONG_MODULES = {"persival.surrogate.sparse_grid", "persival.model.fe.solver", "persival.model.arm.muscle_unit",
                "persival.model.anatomy.bone_shapes", "persival.model.fe.material"}
LONG_FUNCTIONS = {"persival.model.fe.material._law_point", "persival.model.fe.geometry.swept_solid_mesh",
                  "persival.model.fe.assembly._element_kernel", "persival.model.fe.solver.solve",
                  "persival.evaluate.bench_arm.run_arm_benchmark",
                  "persival.cli.run.register", "persival.cli.run.run", "persival.cli.campaign.run"}


def test_modules_and_functions_stay_small():
    long_modules, long_functions = set(), set()
    for path, module in modules():
        text = path.read_text()
        if len(text.splitlines()) > 300:
            long_modules.add(module)
            assert "One module on purpose" in (ast.get_docstring(ast.parse(text)) or ""), f"{module}: say why in its docstring"
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno - node.lineno + 1 > 60:
                long_functions.add(f"{module}.{node.name}")
    assert long_modules <= LONG_MODULES, f"modules over 300 lines: {sorted(long_modules - LONG_MODULES)}"
    assert long_functions <= LONG_FUNCTIONS, f"functions over 60 lines: {sorted(long_functions - LONG_FUNCTIONS)}"
