"""`persival run`: the end-to-end job over the stages that exist, each reading the last one's artifact.

1. model     - validate and mesh the built-in arm (quick profile): reference VTU + geometry.json
2. FE        - three equilibria of the arm (hanging, biceps 0.5, flexors 1; each from the hanging arm): arm.json, arm/<state>/, arm.png
3. campaign  - a level-1 sparse-grid campaign (243 states) and 50 random held-out states into zarr
               stores, with the fast analytic simulator (an arm campaign takes ~30 min: README)
4. surrogate - B-spline sparse grid fitted to the store (biceps surface + elbow angle): sg_biceps/;
               an adaptive grid of the same FE budget grown from the store: sg_adaptive/
5. evaluate  - both against the held-out states, SPEC 7 metrics: accuracy/accuracy.json + .png
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, default=float))


def model_stage(out: Path, profile: str = "quick") -> dict:
    import meshio

    from persival.campaign.arm_simulator import muscle_surface
    from persival.model.arm import ArmModel
    from persival.model.output import bone_surfaces, muscle_submesh

    t0 = time.perf_counter()
    arm = ArmModel(profile=profile)
    geometry = {"model": arm.spec.name, "model_hash": arm.model_hash, "profile": profile, "muscles": {}}
    for muscle in arm.spec.ordered_muscles():
        nodes, cells = muscle_submesh(arm, muscle.name)
        surface, _ = muscle_surface(arm, muscle.name)
        meshio.Mesh(arm.mesh.points[nodes], [("tetra10", cells)]).write(out / f"mesh_{muscle.name}.vtu")
        geometry["muscles"][muscle.name] = {
            "tet10": int(len(cells)),
            "nodes": int(len(nodes)),
            "surface_nodes": int(len(surface)),
            "mesh_angle_deg": muscle.mesh_angle_deg,
            "fibre_prestretch": muscle.fibre_prestretch,
            "line_moment_arm_mm": {str(t): round(arm.line_moment_arm(muscle, t), 2) for t in (0, 45, 90, 120, 150)},
        }
    for name, (points, triangles) in bone_surfaces(arm, 90.0).items():
        meshio.Mesh(points, [("triangle", triangles)]).write(out / f"bone_{name}_90deg.vtu")
    geometry["wall_time_s"] = time.perf_counter() - t0
    _write_json(out / "geometry.json", geometry)
    return geometry


ARM_STATES = {
    "hanging": (0.0, 0.0, 0.0, 0.0, 0.0),
    "biceps_half": (0.5, 0.0, 0.0, 0.0, 0.0),
    "flexors_full": (1.0, 1.0, 1.0, 0.0, 0.0),
}


def arm_stage(out: Path, profile: str = "quick", console=None) -> dict:
    """Three FE states of the arm, each continued from the hanging arm: state.json + VTU per
    state, and a picture of the three (``arm.png``).

    Not from each other: from biceps 0.5 (92 deg) the jump to every flexor at 1 activates the
    slack, bowed brachioradialis at fixed length, a snap-through on which load stepping stalls
    (docs/arm_model.md); from the hanging arm the same state converges."""
    from persival.evaluate.render import render_states
    from persival.model.arm import ArmModel
    from persival.model.output import write_state

    arm = ArmModel(profile=profile)
    rows, directories = {}, []
    hanging = arm.base_state()
    for name, activations in ARM_STATES.items():
        state = hanging if not any(activations) else arm.solve(activations, warm_start=hanging)
        directories.append(write_state(arm, state, out / "arm" / name))
        rows[name] = {
            "activations": list(activations),
            "elbow_angle_deg": state.elbow_angle_deg,
            "moment_residual_Nmm": state.moment_residual,
            "newton_iterations": state.statistics["iterations"],
            "wall_time_s": state.wall_time_s,
            "max_abs_J_minus_1": state.max_volume_change,
        }
        if console is not None:
            console.print(f"  {name:13s} elbow {state.elbow_angle_deg:6.2f} deg, moment residual {state.moment_residual:.1e} N mm, "
                          f"{state.statistics['iterations']} Newton iterations, {state.wall_time_s:.1f} s, max|J-1| {state.max_volume_change:.1e}")
    render_states(directories, out / "arm.png")
    result = {"profile": profile, "states": rows}
    _write_json(out / "arm.json", result)
    return result


def campaign_stage(out: Path, level: int = 1, n_test: int = 50) -> tuple[Path, Path]:
    """The sparse-grid training campaign and a random held-out campaign of the same simulator."""
    from persival.campaign.design import Design
    from persival.campaign.runner import INLINE, run_campaign
    from persival.campaign.simulator import SimulatorSpec

    spec = SimulatorSpec("analytic", {})
    store, test = out / "campaign.zarr", out / "held_out.zarr"
    run_campaign(store, Design.sparse_grid(level), spec, scheduler=INLINE, progress=True)
    run_campaign(test, Design.random(n_test, seed=1), spec, scheduler=INLINE, progress=True)
    return store, test


def surrogate_stage(out: Path, store_path: Path) -> dict:
    """The regular SG on the campaign, and an adaptive SG grown to the same FE budget (reusing its states)."""
    from persival.campaign.store import CampaignStore
    from persival.surrogate.adaptive_campaign import run_adaptive_campaign
    from persival.surrogate.surface_surrogate import SurfaceSurrogate

    surrogate = SurfaceSurrogate("biceps").fit(store_path)
    surrogate.save(out / "sg_biceps")
    with CampaignStore.open(store_path) as store:
        spec = store.spec
    adaptive = run_adaptive_campaign(out / "sg_adaptive", spec, max_points=surrogate.grid.n_points,
                                     seed_stores=[store_path], progress=False)
    test = np.random.default_rng(0).uniform(0.0, 1.0, (1, 5))
    surrogate.predict(test, dtype=np.float32)
    t0 = time.perf_counter()
    for _ in range(100):
        surrogate.predict(test, dtype=np.float32)
    return {
        **surrogate.metadata,
        "surface_nodes": surrogate.n_nodes,
        "adaptive_grid_points": adaptive.surrogate.grid.n_points,
        "adaptive_states_solved": adaptive.simulated,
        "predict_ms_per_state_batch1_float32": (time.perf_counter() - t0) / 100 * 1e3,
    }


def evaluate_stage(out: Path, test_store: Path) -> dict:
    """Both surrogates against the held-out states (SPEC 7 metrics): accuracy.json + accuracy.png."""
    from persival.evaluate.surrogate_accuracy import accuracy_report, plot_accuracy

    report = accuracy_report({"regular": out / "sg_biceps", "adaptive": out / "sg_adaptive" / "surrogate"}, test_store)
    (out / "accuracy").mkdir(exist_ok=True)
    _write_json(out / "accuracy" / "accuracy.json", report)
    plot_accuracy(report, out / "accuracy" / "accuracy.png")
    return report


def run(out: Path, profile: str = "quick") -> dict:
    from rich.console import Console

    console = Console()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    console.rule("1/4 model: the built-in arm")
    geometry = model_stage(out, profile)
    for name, g in geometry["muscles"].items():
        console.print(f"  {name:16s} {g['tet10']:5d} tet10, {g['surface_nodes']:5d} surface nodes, moment arm at 90 deg {g['line_moment_arm_mm']['90']:+.1f} mm")
    console.rule("2/4 FE: the arm hanging, biceps at 0.5, all flexors at 1 (joint equilibrium)")
    fe = arm_stage(out, profile, console)
    console.rule("3/5 campaign: level-1 sparse grid + 50 random held-out states (analytic simulator)")
    store, test_store = campaign_stage(out)
    console.rule("4/5 surrogate: B-spline sparse grid on the store, and an adaptive one of the same FE budget")
    report = surrogate_stage(out, store)
    console.print(f"  regular: {report['grid_points']} points, {report['predict_ms_per_state_batch1_float32']:.3f} ms per state; "
                  f"adaptive: {report['adaptive_grid_points']} points ({report['adaptive_states_solved']} new states solved)")
    console.rule("5/5 evaluate: surrogates vs held-out states (SPEC 7)")
    accuracy = evaluate_stage(out, test_store)
    for label, row in accuracy["surrogates"].items():
        console.print(f"  {label:8s} {row['fe_states']:4d} FE states: MaxAE {row['max MaxAE_mm']:.3f} mm, MAE {row['mean MAE_mm']:.3f} mm, "
                      f"MaxRE {row['max MaxRE_pct']:.2f} %, max angle error {row['max angle_error_deg']:.3f} deg")
    console.rule("results")
    console.print(f"  {out}/geometry.json, mesh_*.vtu, bone_*.vtu   (open the VTU files in ParaView)")
    console.print(f"  {out}/arm.json, {out}/arm/<state>/state.json + VTU, picture {out}/arm.png")
    console.print(f"  {out}/campaign.zarr   (persival campaign status --store {out}/campaign.zarr)")
    console.print(f"  {out}/held_out.zarr   (50 random states the surrogates never saw)")
    console.print(f"  {out}/sg_biceps/, {out}/sg_adaptive/surrogate/ (persival.surrogate.surface_surrogate.SurfaceSurrogate.load)")
    console.print(f"  {out}/accuracy/accuracy.json, picture {out}/accuracy/accuracy.png")
    console.print("  viewer: not built yet (see README status)")
    summary = {"geometry": geometry, "fe": fe, "surrogate": report, "accuracy": accuracy["surrogates"]}
    _write_json(out / "summary.json", summary)
    return summary
