"""`persival bench nn`: the speed table (docs/theory.md, 8.4) on a run folder.

Rows (batch 1 and 64, mean of up to ``reps`` calls after a warm-up, fewer when a row would
take longer than ``budget_s``): the paper architecture 5 -> 2809 (docs/theory.md, 7.2 widths, timing only)
as three separate nets and combined in PyTorch eager, the trained paper net (our biceps)
combined, the POD net in PyTorch, the deployed ONNX tiers float32 / float16 / int8 under
onnxruntime with 1 and 2 threads, the SG (whole surface of all muscles) per state, and, when
the ``peer`` extra is installed, the paper architecture under Keras and TFLite in the same run
(:mod:`persival.evaluate.tflite_peer`, in a child process). Held-out accuracy: each trained
model against the run's held-out states.
"""

from __future__ import annotations

import numpy as np
import torch

from persival.evaluate import paper_values
from persival.evaluate.metrics import state_errors
from persival.evaluate.run_layout import LoadedRun, scope_slice
from persival.evaluate.tables import make_table
from persival.evaluate.timing import blas_threads, time_calls, torch_threads

__all__ = ["BENCH_COLUMNS", "TERMINAL_COLUMNS", "bench_table", "heldout_accuracy"]

BENCH_COLUMNS = [
    ("variant", "variant", "{}"), ("runtime", "runtime", "{}"), ("threads", "threads", "{}"), ("batch", "batch", "{:d}"),
    ("ms_per_call", "ms / call", "{:.4f}"), ("ms_per_state", "ms / state", "{:.4f}"), ("calls", "calls", "{:d}"),
    ("file_mb", "file MB", "{:.3f}"), ("parameters", "parameters", "{:,d}"), ("accuracy_on", "held-out on", "{}"),
    ("heldout_maxae_mm", "MaxAE mm", "{:.3f}"), ("heldout_mae_mm", "MAE mm", "{:.3f}"),
    ("speedup_vs_tflite", "x faster than TFLite peer", "{:.1f}"),
]
BATCHES = (1, 64)
#: The terminal's view of the table (readable at 80 columns): variant over runtime in one cell, the
#: columns a reader compares; every column is in bench_nn.md / .json.
TERMINAL_COLUMNS = [("variant / runtime", ["variant", "runtime"]), ("thr", ["threads"]), ("batch", ["batch"]),
                    ("ms/\nstate", ["ms_per_state|ms_per_call"]), ("MB", ["file_mb"]), ("MaxAE\nmm", ["heldout_maxae_mm"]),
                    ("MAE\nmm", ["heldout_mae_mm"]), ("x\nTFLite", ["speedup_vs_tflite"])]


def heldout_accuracy(predict, truth, scope_surfaces, scope: str) -> dict:
    """MaxAE (worst state) and MAE (mean) of ``predict(alpha) -> positions`` on the truth's scope."""
    if truth is None:
        return {}
    sl = scope_slice(truth.surfaces, scope)
    ref = truth.positions[:, sl]
    got = np.asarray(predict(truth.activations), dtype=np.float64)[:, scope_slice(scope_surfaces, scope)]
    e = state_errors(got, ref, ref - truth.surfaces.reference_points[sl])
    return {"accuracy_on": f"{scope}, {len(truth)} states", "heldout_maxae_mm": float(e["MaxAE_mm"].max()),
            "heldout_mae_mm": float(e["MAE_mm"].mean())}


def _row(variant, runtime, threads, batch, timing, **extra) -> dict:
    return {"variant": variant, "runtime": runtime, "threads": threads, "batch": batch,
            "ms_per_call": 1e3 * timing["mean_s"], "ms_per_state": 1e3 * timing["mean_s"] / batch,
            "median_ms_per_call": 1e3 * timing["median_s"], "calls": timing["calls"], **extra}


def _torch_rows(variant, fn, threads, reps, budget_s, **extra) -> list[dict]:
    rows = []
    with torch.no_grad(), torch_threads(threads):
        for batch in BATCHES:
            x = torch.rand(batch, 5, generator=torch.Generator().manual_seed(batch))
            rows.append(_row(variant, f"PyTorch {torch.__version__.split('+')[0]} eager", threads, batch,
                             time_calls(lambda x=x: fn(x), reps, 10, budget_s), **extra))
    return rows


def _paper_architecture_rows(activation, threads, reps, budget_s) -> list[dict]:
    from persival.surrogate.networks import PaperNet, count_parameters

    torch.manual_seed(0)
    net = PaperNet(2809, activation, 700).eval()
    combined = net.deployable(np.zeros((2809, 3))).eval()
    n = count_parameters(net)
    extra = {"parameters": n, "file_mb": 4 * n / 1e6, "accuracy_on": "timing only (untrained)"}
    rows = _torch_rows("paper arch 5->2809, three separate nets", lambda x: [m(x) for m in net.nets], threads,
                       reps, budget_s, **extra)
    return rows + _torch_rows("paper arch 5->2809, combined", combined, threads, reps, budget_s, **extra)


def _onnx_rows(run: LoadedRun, truth, reps, budget_s) -> list[dict]:
    rows = []
    for export in (run.layout.export, run.layout.export_pod):
        if (export / "metadata.json").is_file():
            rows += _export_rows(export, run, truth, reps, budget_s)
    return rows


def _export_rows(export, run: LoadedRun, truth, reps, budget_s) -> list[dict]:
    import onnxruntime as ort

    from persival.deploy.artifacts import DeployedModel

    deployed = DeployedModel(export)  # checks the folder once (contract: docs/deployment.md)
    role = "deployed" if export == run.layout.export else "exported"
    rows = []
    for tier, variant in deployed.metadata["models"]["deformation"]["variants"].items():
        path = export / variant["file"]
        accuracy = {}
        for threads in (1, 2):
            opts = ort.SessionOptions()
            opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
            opts.log_severity_level = 3  # an optional input (the load) is also an initializer: ORT warns
            sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])

            def predict(alpha, sess=sess):
                return sess.run(["positions"], {"activations": np.asarray(alpha, np.float32)})[0]
            accuracy = accuracy or heldout_accuracy(predict, truth, deployed_surfaces(run), "all")
            for batch in BATCHES:
                x = np.random.default_rng(batch).uniform(0, 1, (batch, 5)).astype(np.float32)
                rows.append(_row(f"{role} {deployed.metadata['models']['deformation'].get('architecture')} "
                                 f"ONNX {tier}", f"onnxruntime {ort.__version__}", threads, batch,
                                 time_calls(lambda x=x, p=predict: p(x), reps, 20, budget_s),
                                 file_mb=path.stat().st_size / 1e6, **accuracy))
    return rows


def deployed_surfaces(run: LoadedRun):
    """The deployed model's node layout: the POD net's (all muscles) when present, else the SG's."""
    return run.networks["pod"].surfaces if "pod" in run.networks else run.sg.surfaces


def _network_rows(run: LoadedRun, truth, reps, budget_s) -> list[dict]:
    from persival.surrogate.networks import count_parameters

    rows = []
    for label, net in run.networks.items():
        graph = net.deployable()
        scope = "biceps" if label == "paper" else "all"
        file = run.layout.network(label) / "network.pt"
        extra = {"parameters": count_parameters(graph), "file_mb": file.stat().st_size / 1e6 if file.exists() else None,
                 **heldout_accuracy(net.predict, truth, net.surfaces, scope)}
        name = f"trained paper net ({net.surfaces.n_nodes} biceps nodes), combined" if label == "paper" else \
            f"POD net ({net.surfaces.n_nodes} nodes, rank {net.net.config.get('rank')})"
        rows += _torch_rows(name, graph, 1, reps, budget_s, **extra)
    return rows


def _sg_rows(run: LoadedRun, truth, reps, budget_s) -> list[dict]:
    sg = run.sg
    accuracy = heldout_accuracy(sg.predict, truth, sg.surfaces, "all")
    size = sum(f.stat().st_size for f in run.layout.sg.glob("*.npz")) / 1e6
    rows = []
    for threads in (1, 2):
        with blas_threads(threads):
            for batch in BATCHES:
                x = np.random.default_rng(batch).uniform(0, 1, (batch, 5))
                sg.predict(x, dtype=np.float32)  # casts the coefficients once, outside the timing
                rows.append(_row(f"SG level {sg.metadata.get('level')} ({sg.grid.n_points} points, whole surface)",
                                 f"numpy {np.__version__} float32", threads, batch,
                                 time_calls(lambda x=x: sg.predict(x, dtype=np.float32), reps, 10, budget_s),
                                 file_mb=size, parameters=int(sg.grid.n_points * (3 * sg.n_nodes + 1)), **accuracy))
    return rows


def _peer_rows(activation, reps, budget_s, warn) -> tuple[list[dict], dict]:
    """The Keras/TFLite peer's rows (a child process); ``warn(text)``: why there are none."""
    from persival.evaluate.tflite_peer import INSTALL_HINT, peer_available, run_in_subprocess

    if not peer_available():
        if warn is not None:
            warn(INSTALL_HINT)
        return [], {"installed": False, "hint": INSTALL_HINT}
    import subprocess

    try:
        result = run_in_subprocess(2809, 700, activation, reps, budget_s)
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        if warn is not None:
            warn(str(exc))
        return [], {"installed": True, "hint": f"the peer is installed but failed: {exc}"}
    rows = [_row("paper arch 5->2809, combined", r["runtime"], r["threads"], r["batch"], r,
                 parameters=result["parameters"],
                 file_mb=result["tflite_bytes"] / 1e6 if r["runtime"].startswith("TFLite") else 4 * result["parameters"] / 1e6,
                 accuracy_on="timing only (untrained)") for r in result["rows"]]
    return rows, {"installed": True, **{k: v for k, v in result.items() if k != "rows"}}


def _held_out(run: LoadedRun, n_states: int = 25):
    from persival.surrogate.dataset import Dataset

    if not run.layout.held_out.exists():
        return None
    data = Dataset.from_store(run.layout.held_out).select(list(run.sg.surfaces.names))
    return data.subset(np.arange(min(n_states, len(data))))


def _targets(rows: list[dict], peer: dict) -> tuple[dict, list[str]]:
    """The speed target (docs/benchmarks.md): the deployed model >= 50x faster than the TFLite peer at batch 1, files <= 2 MB."""
    tflite = [r for r in rows if r["runtime"].startswith("TFLite") and r["batch"] == 1]
    deployed = [r for r in rows if r["variant"].startswith("deployed") and r["batch"] == 1]
    notes, check = [], {}
    if tflite:
        reference = min(r["ms_per_state"] for r in tflite)
        for r in rows:
            if r["batch"] == 1:
                r["speedup_vs_tflite"] = reference / r["ms_per_state"]
        check["tflite_ms_batch1"] = reference
    if deployed:
        best = min(deployed, key=lambda r: r["ms_per_state"])
        check["deployed_best"] = {k: best.get(k) for k in ("variant", "threads", "ms_per_state", "speedup_vs_tflite")}
        tiers = {r["variant"]: r["file_mb"] for r in deployed}
        check["deployed_files_mb"] = tiers
        if "speedup_vs_tflite" in best:
            ok = best["speedup_vs_tflite"] >= 50.0
            notes.append(f"speed target (>= 50x the TFLite peer at batch 1): {best['variant']}, {best['threads']} "
                         f"thread(s), {best['ms_per_state']:.4f} ms = {best['speedup_vs_tflite']:.0f}x: "
                         f"{'met' if ok else 'NOT met'}.")
            check["speed_target_met"] = ok
        f32 = [mb for name, mb in tiers.items() if name.endswith("float32")]
        if f32:
            check["size_target_met"] = f32[0] <= 2.0
            notes.append(f"Model file (float32, all muscles): {f32[0]:.3f} MB (target <= 2 MB): "
                         f"{'met' if f32[0] <= 2.0 else 'NOT met'}.")
    if peer.get("skipped"):
        notes.append("No Keras/TFLite rows: the peer was not asked for (--no-peer).")
    elif not peer.get("installed"):
        notes.append(f"No Keras/TFLite rows: {peer.get('hint')}.")
    return check, notes


def bench_table(run: LoadedRun, reps: int = 1000, budget_s: float = 4.0, peer: bool = True, warn=None,
                progress=None) -> dict:
    """Every row of the speed table; ``progress(step, total, what)`` after each group, ``warn(text)``
    where a row group is missing and why."""
    activation = run.networks["paper"].config.activation if "paper" in run.networks else "silu"
    truth = _held_out(run)
    groups = [("paper architecture (PyTorch)", lambda: _paper_architecture_rows(activation, 1, reps, budget_s)),
              ("trained networks (PyTorch)", lambda: _network_rows(run, truth, reps, budget_s)),
              ("deployed ONNX tiers", lambda: _onnx_rows(run, truth, reps, budget_s)),
              ("sparse grid", lambda: _sg_rows(run, truth, reps, budget_s))]
    rows, peer_info = [], {"installed": False, "skipped": True}
    if peer:
        groups.append(("Keras/TFLite peer (child process)", None))
    for k, (what, fn) in enumerate(groups):
        if fn is None:
            peer_rows, peer_info = _peer_rows(activation, reps, budget_s, warn)
            rows += peer_rows
        else:
            rows += fn()
        if progress is not None:
            progress(k + 1, len(groups), what)
    check, notes = _targets(rows, peer_info)
    if truth is not None and {"paper", "pod"} <= set(run.networks) and "biceps" in run.networks["pod"].surfaces.names:
        pod, paper = (heldout_accuracy(run.networks[k].predict, truth, run.networks[k].surfaces, "biceps")
                      for k in ("pod", "paper"))
        ok = pod["heldout_mae_mm"] <= paper["heldout_mae_mm"]
        check["accuracy_vs_paper_net"] = {"pod_biceps_mae_mm": pod["heldout_mae_mm"],
                                          "paper_biceps_mae_mm": paper["heldout_mae_mm"], "met": ok}
        notes.append(f"Accuracy on the biceps ({pod['accuracy_on']}): POD net MAE {pod['heldout_mae_mm']:.3f} mm, "
                     f"trained paper net {paper['heldout_mae_mm']:.3f} mm: equal or better {'met' if ok else 'NOT met'}.")
    label = truth.source.get("label") if truth is not None else "no held-out states"
    notes = [f"Mean of up to {reps} calls after a warm-up (fewer where a row would exceed {budget_s:g} s: see 'calls'); "
             "PyTorch rows with 1 thread; the SG's numpy BLAS with 1 and 2; 'ms / state' = ms / call / batch.",
             f"Held-out accuracy: against {label}; 'all' = every muscle of the deployed model.",
             "The paper's own times (their Intel i5, 6 cores) are below ours for reference, batch 1."] + notes
    return make_table("bench_nn", "Evaluation times",
                      f"Seconds per call of every network variant and the SG; SG of {run.source_label}.",
                      BENCH_COLUMNS, rows, paper_values.SPEED, notes, targets=check, peer=peer_info,
                      config={"reps": reps, "budget_s": budget_s, "batches": list(BATCHES)})
