"""The result blocks of README.md and docs/benchmarks.md, rendered from a run's results.json.

One source for each number: `persival report` writes every table of a run to
``RUN/report/results.json`` (:mod:`persival.evaluate.report`); the committed copy is
``docs/results.json``. A block is the text between ``<!-- results:NAME -->`` and
``<!-- /results:NAME -->``; :func:`persival.evaluate.readme_blocks.rewrite` replaces each block's text by its renderer's and
leaves every character outside the markers as it was. A renderer answers None when the results
lack its numbers (an analytic run has no FE states): that block stays as written.

Numbers come from results.json only: the run's tables (``error_propagation``, ``bench_nn``,
``random_activations``, ``random_angles``, their ``paper`` rows: persival.evaluate.paper_values),
``summary`` (the deployed file's own held-out measurement), ``stages`` (each stage's record) and
``provenance`` (date, commit, machine). Figures of separate commands (`persival bench deployed`,
...) are not in results.json and stay hand-written outside the markers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from persival.evaluate import results_text as rt

__all__ = ["BLOCKS"]



# ---- what results.json holds -------------------------------------------------------------------


# ---- the blocks --------------------------------------------------------------------------------


class _Accuracy(NamedTuple):
    """One surrogate against the held-out states: worst MaxAE, mean MAE (mm), worst angle error (deg)."""

    label: str
    max_ae: float | None
    mae: float | None
    angle: float | None
    source: str  # where in results.json, for the benchmarks page
    deployed: bool = False
    short: str = ""  # the label in the benchmarks page's row of the SG beside the networks


def _deployed_accuracy(results: dict) -> _Accuracy | None:
    held, name = rt.deployed_held_out(results), rt.deployed_model(results)
    if not held:
        return None
    # the export's own measurement is of its float32 file; without one the summary took the network's table row
    exported = held.get("from") == "export/metadata.json"
    return _Accuracy(f"{rt.NAMES.get(name, name)} (deployed, {'ONNX float32' if exported else 'before export'})",
                     held.get("max_ae_mm"), held.get("mae_mm"), held.get("max_angle_error_deg"),
                     "export stage (`summary.held_out`)" if exported else "evaluate stage (`error_propagation`)",
                     deployed=True)


def _accuracy_rows(results: dict) -> list[_Accuracy]:
    """The deployed file, then the table-only path, the SG and the networks of the error-propagation table."""
    deployed = _deployed_accuracy(results)
    rows = [deployed] if deployed else []
    for surrogate, scope, label, short in (
            ("FE response tables (table-only)", "all", "response tables without FE solve (table-only)", ""),
            ("SG", "all", rt.sg_label(results), rt.sg_label(results).split(" (")[0]),
            ("pod NN", "all", "POD network on sparse-grid data", "POD network"),
            ("paper NN", "biceps", "paper network, biceps only", "paper network (biceps)")):
        row = rt.held_out_row(results, surrogate, scope)
        # the deployed network's own row is the deployed row already
        if row is None or (deployed and surrogate == f"{rt.deployed_model(results)} NN"):
            continue
        rows.append(_Accuracy(label, row.get("max MaxAE_mm"), row.get("mean MAE_mm"), row.get("max angle_error_deg"),
                              "evaluate stage (`error_propagation`)", short=short))
    return rows


def _cells(rows: list[_Accuracy], bold: bool = False) -> list[str]:
    """worst MaxAE, mean MAE, worst angle: one value per cell, or ``a / b / c`` for several rows."""
    cells = [rt.joined([getattr(r, key) for r in rows], rt.format_mm, unit)
             for key, unit in (("max_ae", "mm"), ("mae", "mm"), ("angle", "deg"))]
    return [f"**{c}**" if bold and c else c for c in cells]


def _states_words(results: dict) -> str:
    held = rt.deployed_held_out(results) or rt.held_out_row(results, "SG") or {}
    count = f"{held['states']} " if held.get("states") else ""
    return f"{count}random held-out {rt.truth(results)} states"


def _paper_accuracy(results: dict) -> tuple[dict, dict] | None:
    """The paper's SG and network rows of the error-propagation table (persival.evaluate.paper_values)."""
    paper = rt.run_tables(results, "error_propagation")
    sg, nn = rt.paper_row(paper, "SG"), rt.paper_row(paper, "NN")
    return (sg, nn) if sg and nn else None


def render_accuracy(results: dict) -> str | None:
    """README: every surrogate of the run against the held-out states, and the paper's figures."""
    rows = _accuracy_rows(results)
    if not rows:
        return None
    body = [[f"**{r.label}**" if r.deployed else r.label, *_cells([r], bold=r.deployed)] for r in rows]
    paper = _paper_accuracy(results)
    if paper:
        sg, nn = paper
        body.append([f"the paper (its arm, {sg.get('scope')}): sparse grid / network",
                     rt.joined([sg.get("max MaxAE_mm"), nn.get("max MaxAE_mm")], rt.format_mm, "mm"),
                     rt.joined([sg.get("mean MAE_mm"), nn.get("mean MAE_mm")], rt.format_mm, "mm"), ""])
    header = [f"{_states_words(results)} (all muscles unless said)", "worst MaxAE", "mean MAE", "worst elbow-angle error"]
    return rt.markdown_table(header, body)


def _export_label(role: str, arch: str, tiers: list[str]) -> str:
    return f"{rt.NAMES.get(arch, arch)} ({'deployed' if role == 'deployed' else '`export_pod/`'}), ONNX {' / '.join(tiers)}"


def _tier_values(results, role, arch, tiers, key: str, threads: int = 1, batch: int = 1) -> list:
    """``key`` of each tier's bench row (None where the bench has no such row)."""
    return [r and r.get(key) for r in rt.tier_rows(results, role, arch, tiers, threads, batch)]


def _speed_row(results, role, arch, tiers) -> list[str]:
    """Batch 1 on one thread (and per state at batch 64), the files, for one export's tiers."""
    time = rt.joined(_tier_values(results, role, arch, tiers, "ms_per_state"), rt.format_ms, "ms")
    batch = rt.joined(_tier_values(results, role, arch, tiers, "ms_per_state", batch=64), rt.format_ms, "ms")
    time += f" ({batch} per state at batch 64)" if batch else ""
    return [_export_label(role, arch, tiers), time, rt.joined(_tier_values(results, role, arch, tiers, "file_mb"),
                            rt.format_mb, "MB")]


def _paper_speed_row(results: dict) -> list[str] | None:
    torch_ = rt.bench_row(results, lambda r: r.get("variant") == "paper arch 5->2809, combined"
                    and str(r.get("runtime")).startswith("PyTorch"))
    figure = next((r for r in rt.run_tables(results, "bench_nn").get("paper", []) if r.get("runtime") == "TFLite (paper)"), None)
    if torch_ is None:
        return None
    label, times = "the paper's network rebuilt (PyTorch)", [torch_.get("ms_per_state")]
    if figure:
        label, times = label + " / the paper's TFLite figure", times + [figure.get("ms_per_call")]
    return [label, " / ".join(f"{rt.format_ms(t)} ms" for t in times), rt.joined([torch_.get("file_mb")], rt.format_mb, "MB")]


def render_speed(results: dict) -> str | None:
    """README: time per state and file size of every exported model, the SG and the paper's network."""
    exports = rt.exports(results)
    if not exports:
        return None
    rows = [_speed_row(results, role, arch, tiers)
            for (role, arch), tiers in sorted(exports.items(), key=lambda item: item[0][0] != "deployed")]
    sg = rt.bench_row(results, lambda r: str(r.get("variant")).startswith("SG level"))
    if sg:
        rows.append([f"sparse grid, whole surface ({sg.get('runtime', 'numpy').split()[0]})",
                     rt.joined([sg.get("ms_per_state")], rt.format_ms, "ms"), rt.joined([sg.get("file_mb")], rt.format_mb, "MB")])
    paper = _paper_speed_row(results)
    rows += [paper] if paper else []
    return rt.markdown_table(["speed and size (onnxruntime, 1 thread, batch 1)", "time per state", "file"], rows)


def _model_words(results: dict) -> str | None:
    """"quick profile: 6529 tet10, 5 muscles with 8030 surface nodes, biceps 2478" from the model stage."""
    summary = rt.stage_record(results, "model").get("summary") or {}
    muscles = summary.get("muscles") or {}
    if not muscles:
        return None
    tet10 = sum(m.get("tet10", 0) for m in muscles.values())
    nodes = sum(m.get("surface_nodes", 0) for m in muscles.values())
    biceps = f", biceps {muscles['biceps']['surface_nodes']}" if "biceps" in muscles else ""
    return f"{summary.get('profile')} profile: {tet10} tet10, {len(muscles)} muscles with {nodes} surface nodes{biceps}"


def _stage_words(results: dict) -> str | None:
    """Minutes of the stages: all of them, the response tables, the campaign, training."""
    times = {name: record["wall_time_s"] for name, record in (results.get("stages") or {}).items()
             if name != "run" and isinstance(record, dict) and "wall_time_s" in record}
    if not times:
        return None
    words = [f"{rt.minutes(sum(times.values()))} in its stages"]
    tables = rt.stage_record(results, "tables").get("summary") or {}
    if "tables" in times and not tables.get("skipped"):
        muscles = len((rt.stage_record(results, "model").get("summary") or {}).get("muscles") or {})
        shape = (f" ({len(tables['levels']) * muscles} columns of {len(tables['angles_deg'])} angles, once per model)"
                 if muscles and tables.get("levels") and tables.get("angles_deg") else "")
        words.append(f"{rt.minutes(times['tables'])} of it the response tables{shape}")
    words += [f"{what} {rt.minutes(times[name])}" for name, what in (("campaign", "the campaign"), ("train", "training"))
              if name in times]
    return ", ".join(words)


def _fe_words(results: dict) -> str | None:
    states = (rt.stage_record(results, "fe").get("summary") or {}).get("states") or {}
    names = (("hanging", "Hanging arm"), ("biceps_half", "biceps 0.5"), ("flexors_full", "flexors 1"))
    words = [f"{what} {states[name]['elbow_angle_deg']:.2f} deg" for name, what in names if name in states]
    return ", ".join(words) + "." if words else None


def render_run(results: dict) -> str | None:
    """README: the run the tables come from, in one paragraph (command, mesh, date, machine, minutes, FE angles)."""
    stages = _stage_words(results)
    if stages is None:
        return None
    fe_arm = rt.truth(results) == "FE"
    # the model stage meshes the arm in every run, but only an FE run's numbers are of that mesh
    model = _model_words(results) if fe_arm else None
    arm = "our FE arm" if fe_arm else f"the {rt.truth(results)} stand-in (no FE states)"
    text = (f"The paper's tables on {arm}, from `{rt.command(results)}`" + (f" ({model})" if model else "")
            + f", {rt.measured(results)}: {stages}.")
    fe = _fe_words(results)
    return rt.paragraph(text + (" " + fe if fe else ""))


def _out_of_training(results: dict, kind: str) -> tuple[dict, dict] | None:
    table = rt.run_tables(results, kind)
    ours = next((r for r in table.get("rows", []) if r.get("network") == "pod" and r.get("scope") == "all"), None)
    paper = (table.get("paper") or [None])[0]
    return (ours, paper) if ours and paper else None


def render_out_of_training(results: dict) -> str | None:
    """README: the POD network against the SG it was trained on (the paper's out-of-training tests)."""
    found = [_out_of_training(results, k) for k in ("random_activations", "random_angles")]
    if not all(found):
        return None
    (act, paper_act), (ang, paper_ang) = found

    def pair(row):
        return f"{rt.format_mm(row['max MaxAE_mm'])} / {rt.format_mm(row['mean MAE_mm'])}"
    return rt.paragraph("Networks against the sparse grid they were trained on (the paper's out-of-training tests): POD "
                      f"network {pair(act)} mm at random activations and {pair(ang)} mm at alpha_opt(Theta) (the paper: "
                      f"{pair(paper_act)} and {pair(paper_ang)} mm).")


def render_bench_accuracy(results: dict) -> str | None:
    """docs/benchmarks.md: the deployed file, the table-only path, and the SG beside the networks."""
    rows = _accuracy_rows(results)
    if not rows:
        return None
    alone = [r for r in rows if not r.short]
    body = [[r.label, *_cells([r]), r.source] for r in alone]
    compared = [r for r in rows if r.short]
    if compared:  # the SG and the networks in one row, as the paper's table compares them
        body.append([" / ".join(r.short for r in compared), *_cells(compared), compared[0].source])
    header = ["surrogate", "worst MaxAE", "mean MAE", "worst elbow-angle error", "where in results.json"]
    paper = _paper_accuracy(results)
    figures = ""
    if paper:
        sg, nn = paper
        figures = (f"The paper's figures (its arm, {sg.get('scope')}): sparse grid {rt.format_mm(sg.get('max MaxAE_mm'))} / "
                   f"{rt.format_mm(sg.get('mean MAE_mm'))} mm, network {rt.format_mm(nn.get('max MaxAE_mm'))} / "
                   f"{rt.format_mm(nn.get('mean MAE_mm'))} mm. ")
    where = f"{_states_words(results)}; from the results.json of `{rt.command(results)}`: {rt.measured(results)}."
    return rt.markdown_table(header, body) + "\n\n" + rt.paragraph(figures + where)


def _bench_speed_row(results, role, arch, tiers) -> list[str]:
    """Batch 1 and 64 (per state), each on one thread and in brackets on two, and the files."""
    cells = [_export_label(role, arch, tiers)]
    for batch in (1, 64):
        one = rt.joined(_tier_values(results, role, arch, tiers, "ms_per_state", 1, batch), rt.format_ms, "ms")
        two = rt.joined(_tier_values(results, role, arch, tiers, "ms_per_state", 2, batch), rt.format_ms, "ms")
        one = f"**{one}**" if role == "deployed" and batch == 1 and one else one
        cells.append(one + (f" (2 threads {two})" if two else ""))
    return cells + [rt.joined(_tier_values(results, role, arch, tiers, "file_mb"),
                            rt.format_mb, "MB")]


def render_bench_speed(results: dict) -> str | None:
    """docs/benchmarks.md: every exported model at batch 1 and 64, one and two threads, and its files."""
    exports = rt.exports(results)
    if not exports:
        return None
    rows = [_bench_speed_row(results, role, arch, tiers)
            for (role, arch), tiers in sorted(exports.items(), key=lambda item: item[0][0] != "deployed")]
    table = rt.markdown_table(["model", "batch 1, 1 thread", "batch 64, per state", "file"], rows)
    source = f"From the results.json (`bench_nn`) of `{rt.command(results)}`: {rt.measured(results)}."
    return f"{table}\n\n" + rt.paragraph(source)


#: block name -> renderer(results) -> markdown, or None where results.json lacks the numbers
BLOCKS: dict[str, Callable[[dict], str | None]] = {
    "run": render_run, "accuracy": render_accuracy, "speed": render_speed, "out-of-training": render_out_of_training,
    "bench-accuracy": render_bench_accuracy, "bench-speed": render_bench_speed,
}
