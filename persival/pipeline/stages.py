"""The stages of `persival run` (persival.pipeline sequences them): each reads the artifacts of
the stages before it from OUT and writes its own folder, through the stages' Python API. The FE
arm's stages (model, tables, fe, campaign, anatomy) are in persival.pipeline.arm_stages; here the
surrogates', deployment's and evaluation's, and the registry.

Each runner is ``fn(out, config, console) -> summary (json-able)``; ``SETTINGS[name]`` lists the
RunConfig fields that change its result (part of its digest, so a changed setting reruns it).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from persival.pipeline.arm_stages import anatomy, campaign, fe, model, tables

__all__ = ["RUNNERS", "SETTINGS", "print_results"]


def structured(out: Path, config, console) -> dict:
    """The deployed model: per-muscle shape and moment models fitted to the response tables."""
    if config.simulator != "arm":
        why = "the structured surrogate is fitted to the FE arm's response tables (the campaign ran the analytic stand-in)"
        console.print(f"  [yellow]skipped[/yellow]: {why}")
        return {"skipped": why}
    from persival.surrogate.build import fit_structured
    from persival.surrogate.dataset import Dataset

    surrogate = fit_structured(out / "campaign" / "held_out.zarr", out / "structured", config.profile,
                                config.model)
    meta = surrogate.metadata
    held = Dataset.from_store(out / "campaign" / "held_out.zarr")
    positions, angles = surrogate.predict_with_angle(held.activations)
    errors = np.linalg.norm(positions - held.positions, axis=2)
    check = {"states": len(held), "max_ae_mm": float(errors.max()), "mae_mm": float(errors.mean()),
             "max_angle_error_deg": float(np.abs(angles - held.elbow_angles).max())}
    console.print(f"  fitted from the tables in {meta['fit_seconds']:.1f} s; POD modes "
                  + ", ".join(f"{k} {v}" for k, v in meta["modes"].items())
                  + f"; against {check['states']} held-out FE states: worst MaxAE {check['max_ae_mm']:.2f} mm, "
                  f"mean MAE {check['mae_mm']:.3f} mm, worst angle error {check['max_angle_error_deg']:.2f} deg")
    return {"modes": meta["modes"], "parameters": meta["parameters"], "fit_seconds": meta["fit_seconds"],
            "grid": meta["grid"], "held_out_fe": check}


def sg(out: Path, config, console) -> dict:
    from persival.surrogate.build import fit_sparse_grid

    surrogate = fit_sparse_grid(out / "campaign" / "campaign.zarr", out / "sg", muscles=None)
    console.print(f"  level {surrogate.metadata['level']}: {surrogate.grid.n_points} points, {surrogate.n_nodes} surface "
                  f"nodes of {len(surrogate.surfaces.names)} muscles + elbow angle; data: {surrogate.metadata['label']}")
    return {k: surrogate.metadata[k] for k in ("label", "level", "grid_points", "muscles")}


def inverse(out: Path, config, console) -> dict:
    from persival.surrogate.build import build_activation_model, solve_inverse

    t0 = time.perf_counter()
    model = build_activation_model(out / "sg", out / "inverse" / "activation_model.json")
    build_s = time.perf_counter() - t0
    lo, hi = model.range_deg
    solution, problem = solve_inverse(out / "sg", [lo + 0.1 * (hi - lo), 0.5 * (lo + hi), hi - 0.1 * (hi - lo)])
    for r in solution.rows():
        console.print(f"  Theta {r['target_deg']:6.2f} deg -> alpha {[round(a, 3) for a in r['activations']]}, "
                      f"achieved {r['achieved_deg']:.3f} deg")
    console.print(f"  activation model: {len(model.knots)} knots over {lo:.2f}-{hi:.2f} deg "
                  f"(reachable {problem.reachable_range()[0]:.2f}-{problem.reachable_range()[1]:.2f}), "
                  f"{len(model.branch_notes)} branch notes, built in {build_s:.1f} s")
    unconverged = model.metadata.get("unconverged_intervals", [])
    if unconverged:
        console.print(f"  [yellow]{len(unconverged)} interval(s) still off the solver by more than the tolerance[/yellow] "
                      "(max_knots reached): activation_model.json's metadata lists them")
    return {"range_deg": [lo, hi], "reachable_deg": list(problem.reachable_range()), "knots": len(model.knots),
            "branch_notes": model.branch_notes, "unconverged_intervals": unconverged, "examples": solution.rows()}


def motion(out: Path, config, console) -> dict:
    """The motion model solves least effort on the deployed model's own moment balance (the
    structured model's, fitted to the tables); a run without it (the analytic stand-in) needs a
    moment table of an arm (--moment-table)."""
    from persival.surrogate.motion_model import MotionActivationModel
    from persival.surrogate.motion_plot import plot_motion_model

    if (out / "structured" / "surrogate.json").is_file():
        from persival.surrogate.open import load_surrogate

        deployed = load_surrogate(out / "structured")
        provenance = {"model_hash": deployed.metadata.get("model_hash"), "profile": deployed.profile}
        model = MotionActivationModel.build(deployed.moments, provenance=provenance)
        source = str(out / "structured")
    elif config.moment_table is not None:
        from persival.model.arm.model_file import load_model_file
        from persival.tables.moment_table import MomentTable

        spec, model_hash = load_model_file(config.model)
        profile = config.profile if config.simulator == "arm" else None  # the analytic stand-in has no mesh
        table = MomentTable.load(config.moment_table, model_hash=model_hash, profile=profile, complete=True)
        model = MotionActivationModel.from_table(table, spec)
        source = config.moment_table
    else:
        why = "the analytic stand-in has no muscle moments"
        console.print(f"  [yellow]skipped[/yellow]: {why}; the export has no activation_motion model")
        return {"skipped": why}
    model.save(out / "motion")
    plot_motion_model(model, out / "motion" / "motion_model.png")
    holdable = model.holdable_load_kg(np.array([30.0, 60.0, 90.0, 120.0]))
    reach = model.static_range_deg()
    console.print(f"  range {model.range_deg[0]:.0f}-{model.range_deg[1]:.0f} deg, held with no load {reach[0]:.1f}-"
                  f"{reach[1]:.1f} deg; holdable load at 30/60/90/120 deg: " + " / ".join(f"{h:.2f}" for h in holdable) + " kg")
    return {"range_deg": list(model.range_deg), "static_range_deg": list(reach),
            "holdable_load_kg_30_60_90_120": holdable.tolist(), "balance": source}


def data(out: Path, config, console) -> dict:
    from persival.surrogate.build import make_training_data

    make_training_data(out / "sg", out / "inverse" / "activation_model.json", out / "data", config.samples,
                       config.angle_fraction, config.seed)
    console.print(f"  {config.samples} SG states, {config.angle_fraction:.0%} at alpha_opt(Theta), the rest uniform in [0,1]^5")
    return {"samples": config.samples, "angle_fraction": config.angle_fraction}


def _train_progress(console, label: str):
    state = {"last": 0.0}

    def report(done, total, val_loss, mae, where):
        if time.perf_counter() - state["last"] > 5.0 or done == total:  # a line at least every 5 s
            state["last"] = time.perf_counter()
            console.print(f"  {label}: {where}, val. loss {val_loss:.4g}, "
                          f"MAE x/y/z {mae[0]:.2f}/{mae[1]:.2f}/{mae[2]:.2f} mm")
    return report


def train(out: Path, config, console) -> dict:
    from persival.surrogate.build import train_network
    from persival.surrogate.training import TrainingConfig

    summary = {}
    runs = (("pod", TrainingConfig(arch="pod", folds=config.pod_folds, epochs=config.pod_epochs, seed=config.seed), None),
            ("paper", TrainingConfig(arch="paper", folds=config.paper_folds, epochs=config.paper_epochs, activation="relu",
                                     seed=config.seed), ["biceps"]))
    for name, cfg, muscles in runs:
        surrogate = train_network(out / "data", out / "networks" / name, cfg, muscles,
                                  _train_progress(console, f"{name} net"))
        best = surrogate.metadata["training"]["best"]
        summary[name] = {"parameters": surrogate.metadata["parameters"], "best": best,
                         "wall_time_s": surrogate.metadata["training"]["wall_time_s"],
                         "muscles": surrogate.metadata["muscles"], "rank": surrogate.metadata["training"].get("rank")}
        console.print(f"  {name} net: {summary[name]['parameters']} parameters, best validation loss {best['val_loss']:.4g} "
                      f"(fold {best['fold']}, epoch {best['epoch']}), {summary[name]['wall_time_s']:.0f} s")
    return summary


def export(out: Path, config, console) -> dict:
    """The deployed model with the activation models of its own balance (the motion model and it
    at rest: the angle a user asks for is the angle it draws); the POD network with the paper's
    sparse-grid angle model."""
    from persival.deploy.export import export_model
    from persival.surrogate.activation_model import AngleActivationModel
    from persival.surrogate.dataset import Dataset
    from persival.surrogate.open import load_surrogate

    network = load_surrogate(out / "networks" / "pod")
    sg_angle = AngleActivationModel.load(out / "inverse" / "activation_model.json")
    motion_model = None
    if (out / "motion" / "motion_model.json").exists():
        from persival.surrogate.motion_model import MotionActivationModel

        motion_model = MotionActivationModel.load(out / "motion")
    held = out / "campaign" / "held_out.zarr"
    held = Dataset.from_store(held).select(list(network.surfaces.names)) if held.exists() else None
    # the deployed model (export/): the structured surrogate where the run has one, else the POD net
    exports = {"export": (network, sg_angle, motion_model)}
    if (out / "structured" / "surrogate.json").is_file():
        deployed = load_surrogate(out / "structured")
        angle_model = motion_model.at_rest() if motion_model is not None else sg_angle
        exports = {"export": (deployed, angle_model, motion_model), "export_pod": (network, sg_angle, None)}
    summary = {}
    for folder, (surrogate, angle_model, motion) in exports.items():
        meta = export_model(surrogate, out / folder, activation_model=angle_model, motion_model=motion, held_out=held)
        deployed = meta["provenance"].get("deployed", {})
        console.print(f"  {folder}/: {surrogate.metadata.get('arch')}{' (deployed)' if folder == 'export' else ''}" + "".join(
            f"; {tier} {v['bytes'] / 1e6:.3f} MB, |ONNX - torch| <= {v['max_abs_diff_vs_torch']['positions']:.1e} mm"
            for tier, v in meta["models"]["deformation"]["variants"].items()))
        if deployed:
            h = deployed["held_out_fe"]
            console.print(f"    vs {h['states']} held-out FE states: worst MaxAE {h['max_ae_mm']:.2f} mm, mean MAE "
                          f"{h['mae_mm']:.3f} mm, worst angle error {h.get('max_angle_error_deg', float('nan')):.2f} deg")
        summary[folder] = {"model": surrogate.metadata.get("arch"), "variants": meta["models"]["deformation"]["variants"],
                           "n_nodes": meta["n_nodes"], "deployed": deployed or None,
                           "angle_model": meta["models"].get("activation_angle", {}).get("source")}
    if "export_pod" in exports:
        summary["contract"] = _contract_check(out / "export", console)
    return summary


def _contract_check(folder: Path, console) -> dict:
    """(angle, load) -> activations -> the deployed model's angle, on random requests (SPEC 5, 9);
    kept in metadata.json's provenance.deployed (the report's results.json repeats it)."""
    import json

    from persival.deploy.artifacts import DeployedModel
    from persival.deploy.contract import angle_requests, check_angle_contract

    model = DeployedModel(folder)
    result = check_angle_contract(model, angle_requests(model, 200, seed=0))
    meta = json.loads((folder / "metadata.json").read_text())
    meta["provenance"].setdefault("deployed", {})["angle_contract"] = result
    (folder / "metadata.json").write_text(json.dumps(meta, default=float))
    console.print(f"  contract: {result['requests']} random (angle, load up to {result['max_load_kg']:.2f} kg) requests -> "
                  f"the deployed model's angle within {result['max_angle_error_deg']:.3f} deg "
                  f"(mean {result['mean_angle_error_deg']:.3f})")
    return result


def evaluate(out: Path, config, console) -> dict:
    from persival.evaluate.evaluation import evaluate_run

    result = evaluate_run(out, progress=True, console=console, n_states=config.held_out, bench=config.bench)
    if config.bench:
        result.setdefault("skipped", {}).update(_viewer_screenshot(out, console))
    for name, why in result.get("skipped", {}).items():
        console.print(f"  [yellow]skipped[/yellow] {name}: {why}")
    return {"tables": sorted(result["tables"]), "figures": sorted(result["figures"]), "skipped": result.get("skipped", {})}


def _viewer_screenshot(out: Path, console) -> dict:
    """The viewer's default view for the report (evaluate/viewer.png), with its frame rate: a
    short `persival bench viewer`. Where there is no Chromium, a note says how to get one."""
    from persival.deploy.bench_viewer import ViewerBenchError, run_viewer_bench

    shot = out / "evaluate" / "viewer.png"
    try:
        result = run_viewer_bench(out / "export", seconds=2.0, trace=False, warmup=1.0, screenshot=shot)
    except ViewerBenchError as exc:
        return {"viewer screenshot": f"{exc}"}
    shipped = result["phases"][0]
    console.print(f"  viewer: {shot} ({shipped['fps']:.0f} fps in headless Chromium, software GL)")
    return {}


def report(out: Path, config, console) -> dict:
    from persival.evaluate.report import write_report

    path = write_report(out)
    console.print(f"  {path}")
    return {"html": str(path)}


SETTINGS = {
    "model": ["profile", "model_hash"], "tables": ["profile", "simulator", "model_hash"],
    "fe": ["profile", "simulator", "model_hash"],
    "campaign": ["profile", "simulator", "level", "held_out", "campaign_store", "held_out_store", "seed", "model_hash"],
    "anatomy": [], "structured": ["profile", "model_hash"],
    "sg": [], "inverse": [], "motion": ["moment_table", "profile", "model_hash"], "data": ["samples", "angle_fraction", "seed"],
    "train": ["pod_folds", "pod_epochs", "paper_folds", "paper_epochs", "seed"], "export": [],
    "evaluate": ["seed", "bench"], "report": [],
}
RUNNERS = {"model": model, "tables": tables,
           "fe": fe, "campaign": campaign, "anatomy": anatomy, "structured": structured, "sg": sg, "inverse": inverse,
           "motion": motion, "data": data,
           "train": train, "export": export, "evaluate": evaluate, "report": report}


def print_results(out: Path, console, total_s: float, stages_s: float) -> None:
    console.rule(f"results: this run {total_s / 60:.1f} min, all stages {stages_s / 60:.1f} min")
    console.print(f"  report:   {out}/report/index.html")
    console.print(f"  export:   {out}/export/ (ONNX + metadata.json)")
    console.print(f"  viewer:   persival serve --artifacts {out}/export   then open http://127.0.0.1:8000/")
    console.print(f"  stages:   {out}/<stage>/stage.json (inputs digest, time, summary)")
