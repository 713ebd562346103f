"""The evaluation stage of a run folder: every accuracy table (docs/theory.md, section 8), the figures and the speed table.

``evaluate_run(out)`` reads ``OUT/{campaign,sg,inverse,data,networks,export}`` and writes
``OUT/evaluate/``: one ``<table>.md`` + ``<table>.json`` per table, the figures (``.png``) and
``evaluation.json`` (what was made, what was skipped and why, provenance). ``persival evaluate``
and ``persival run`` both call it; ``persival report`` (:mod:`persival.evaluate.report`) turns
the folder into one HTML page.
"""

from __future__ import annotations

import datetime as _dt
import json
import platform
import sys
import time
from importlib import metadata
from pathlib import Path

__all__ = ["evaluate_run", "run_bench", "environment", "default_command", "deployed_summary"]

_PACKAGES = ("persival", "numpy", "scipy", "torch", "onnx", "onnxruntime", "zarr", "pyvista", "matplotlib",
             "tensorflow-cpu", "tensorflow")


def environment() -> dict:
    """Versions, machine and date: the provenance every number carries."""
    import os

    versions = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return {"git": source_revision(), "versions": versions,
            "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                        "cpu_count": os.cpu_count(), "node": platform.node()},
            "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")}


def deployed_summary(export: Path) -> dict | None:
    """``{"model": NAME, "held_out_fe": {...}}``: the export's own measurement of the deployed file
    against the held-out FE states (persival.deploy.held_out), or None without one."""
    metadata = Path(export) / "metadata.json"
    if not metadata.is_file():
        return None
    return json.loads(metadata.read_text()).get("provenance", {}).get("deployed")


def source_revision() -> dict:
    """The git commit of this package's source (and whether files differ from it), if it is a checkout."""
    import subprocess

    where = Path(__file__).resolve().parent

    def git(*args):
        try:
            proc = subprocess.run(["git", *args], cwd=where, capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return proc.stdout.strip() if proc.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return {"commit": None}
    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit, "branch": git("rev-parse", "--abbrev-ref", "HEAD"), "dirty": bool(status)}


def default_command(out, what: str = "evaluate") -> str:
    argv = sys.argv
    if argv and Path(argv[0]).name == "persival":
        return " ".join(["persival", *argv[1:]])
    return f"persival {what} --run {out}"


class _Steps:
    """Progress of the long steps (or silence); ``progress`` True, False/None or a progress object (persival.progress)."""

    def __init__(self, progress, console=None) -> None:
        self.own = progress is True
        if self.own:
            from persival.progress import progress_bar

            progress = progress_bar(console=console)
        self.progress = progress or None

    def __enter__(self):
        if self.own:
            self.progress.start()
        return self

    def __exit__(self, *exc):
        if self.own:
            self.progress.stop()

    def task(self, description: str, total: float):
        if self.progress is None:
            return lambda *a, **k: None
        task = self.progress.add_task(description, total=total)

        def update(completed, *_, **__):
            self.progress.update(task, completed=min(completed, total))
        update.task = task
        return update

    def finish(self, update, description: str) -> None:
        """Mark a task done (a stopping rule ends before its cap) with a closing description."""
        if self.progress is not None and hasattr(update, "task"):
            total = self.progress.tasks[[t.id for t in self.progress.tasks].index(update.task)].total
            self.progress.update(update.task, completed=total, description=description)


def _save(table: dict, folder: Path, command: str, inputs: dict, t0: float) -> dict:
    from persival.evaluate.tables import save_table

    table["provenance"] = {"command": command, "inputs": inputs, "wall_time_s": round(time.perf_counter() - t0, 2),
                           "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")}
    save_table(table, folder)
    return table


def _accuracy_tables(run, steps, command, max_draws, n_states, tables, skipped) -> dict:
    """(a) - (d); returns the raw draws of (b) for the figures."""
    from persival.evaluate.accuracy_tables import in_training_table, out_of_training_table
    from persival.evaluate.error_propagation import error_propagation_table

    folder, layout = run.layout.evaluate, run.layout
    nets = {label: str(layout.network(label)) for label in run.networks}
    t0 = time.perf_counter()
    if layout.data.exists():
        tables["in_training"] = _save(in_training_table(run), folder, command, {"data": str(layout.data), **nets}, t0)
    else:
        skipped["in_training"] = f"no training data at {layout.data}"
    draws = None
    for kind in ("random_activations", "random_angles"):
        if kind == "random_angles" and run.activation_model is None:
            skipped[kind] = f"no activation model at {layout.activation_model}"
            continue
        t0 = time.perf_counter()
        update = steps.task(f"{kind.replace('_', ' ')}: draws", max_draws)
        table, raw = out_of_training_table(run, kind, max_draws=max_draws, progress=update)
        steps.finish(update, f"{kind.replace('_', ' ')}: stopped after " + ", ".join(
            f"{r['network']}/{r['scope']} {r['draws']}" for r in table["rows"]) + " draws")
        tables[kind] = _save(table, folder, command, {"sg": str(layout.sg), **nets}, t0)
        draws = raw if kind == "random_activations" else draws
    t0 = time.perf_counter()
    if layout.held_out.exists():
        tables["error_propagation"] = _save(error_propagation_table(run, n_states), folder, command,
                                            {"held_out": str(layout.held_out), "campaign": str(layout.campaign),
                                             "sg": str(layout.sg), **nets}, t0)
    else:
        skipped["error_propagation"] = f"no held-out campaign at {layout.held_out}"
    return draws


def _prototypes_and_hotspots(run, steps, command, tables, skipped, figures, prototype_samples) -> None:
    from persival.evaluate.evaluate_figures import biceps_surface, hotspot_errors, plot_hotspots
    from persival.evaluate.prototypes import SHAPES, prototype_table
    from persival.surrogate.training_data import open_dataset

    layout, short = run.layout, None
    if layout.data.exists() and "biceps" in run.sg.surfaces.names:
        t0 = time.perf_counter()
        paper = run.networks.get("paper")
        n_mid = paper.net.config.get("n_mid") if paper is not None else None
        data = open_dataset(layout.data).select("biceps")
        table, short = prototype_table(data, n_mid, paper.config.activation if paper is not None else "silu",
                                       samples=prototype_samples, progress=steps.task("prototypes", len(SHAPES)))
        tables["prototypes"] = _save(table, layout.evaluate, command, {"data": str(layout.data)}, t0)
    else:
        skipped["prototypes"] = f"no training data of the biceps at {layout.data}"
    if "biceps" not in run.sg.surfaces.names:
        skipped["hotspots"] = "the SG has no biceps surface"
        return
    maps = {}
    if short is not None:
        graph = short.deployable(biceps_surface(run.sg.surfaces)[0]).eval()
        maps[f"paper net, short training ({tables['prototypes']['rows'][-1]['epochs']} epochs)"] = hotspot_errors(
            lambda a: _torch_predict(graph, a), data.surfaces, run.sg)
    for label, net in run.networks.items():
        if "biceps" in net.surfaces.names:
            epochs = net.metadata.get("training", {}).get("config", {})
            name = f"{label} net, full training ({epochs.get('folds', '?')} x {epochs.get('epochs', '?')} epochs)"
            maps[name] = hotspot_errors(net.predict, net.surfaces, run.sg)
    if maps:
        points, triangles = biceps_surface(run.sg.surfaces)
        figures["hotspots"] = plot_hotspots(points, triangles, maps, layout.evaluate / "hotspots_biceps.png", skipped)
        (layout.evaluate / "hotspots_biceps.json").write_text(json.dumps(
            {k: {"mean_mm": float(v.mean()), "max_mm": float(v.max())} for k, v in maps.items()}, indent=1))


def _torch_predict(graph, alpha):
    import torch

    with torch.no_grad():
        return graph(torch.as_tensor(alpha, dtype=torch.float32)).numpy()


def run_bench(out: str | Path, progress=True, reps: int = 1000, budget_s: float = 4.0, peer: bool = True,
              console=None, command: str | None = None) -> dict:
    """The speed table of a run folder: ``OUT/evaluate/bench_nn.{md,json}``; returns the table."""
    from persival.evaluate.bench_nn import bench_table
    from persival.evaluate.run_layout import load_run

    t0 = time.perf_counter()
    run = load_run(out)
    run.layout.evaluate.mkdir(parents=True, exist_ok=True)
    with _Steps(progress, console) as steps:
        warn = None if console is None else (lambda text: console.print(text, markup=False, style="yellow"))
        table = bench_table(run, reps, budget_s, peer, warn, steps.task("speed table", 5 if peer else 4))
    return _save(table, run.layout.evaluate, command or default_command(out, "bench nn"),
                 {"export": str(run.layout.export), "sg": str(run.layout.sg)}, t0)


def evaluate_run(out: str | Path, progress=True, bench: bool = True, peer: bool = True, max_draws: int = 20000,
                 n_states: int = 25, prototype_samples: int = 64, console=None, command: str | None = None) -> dict:
    """Every table and figure of the evaluation stage into ``OUT/evaluate``; returns
    ``{"tables": {name: table}, "figures": {name: path}, "skipped": {name: why}, "wall_time_s": s}``."""
    from persival.evaluate.evaluate_figures import collect_stage_figures
    from persival.evaluate.run_layout import load_run
    from persival.evaluate.timing import blas_threads, torch_threads

    t0 = time.perf_counter()
    command = command or default_command(out)
    run = load_run(out)
    folder = run.layout.evaluate
    folder.mkdir(parents=True, exist_ok=True)
    tables, skipped, figures = {}, {}, {}
    with _Steps(progress, console) as steps:
        # one thread: on a shared 2-core machine more threads only wait for the busy core
        with torch_threads(1), blas_threads(1):
            _accuracy_tables(run, steps, command, max_draws, n_states, tables, skipped)
            _prototypes_and_hotspots(run, steps, command, tables, skipped, figures, prototype_samples)
        figures.update(collect_stage_figures(run, folder))
    if bench:
        tables["bench_nn"] = run_bench(out, progress, peer=peer, console=console,
                                       command=command)
    summary = {"run": str(Path(out)), "source": run.source_label, "tables": sorted(tables),
               "figures": {k: str(v) for k, v in figures.items()}, "skipped": skipped,
               "wall_time_s": time.perf_counter() - t0, "provenance": {"command": command, **environment()},
               "deployed": deployed_summary(run.layout.export)}
    (folder / "evaluation.json").write_text(json.dumps(summary, indent=1))
    return {"tables": tables, "figures": figures, "skipped": skipped, "wall_time_s": summary["wall_time_s"]}

