"""The stages of `persival run` that compute the FE arm: model -> tables -> fe -> campaign ->
anatomy (persival.pipeline.stages holds the rest and the registry). Each runner is
``fn(out, config, console) -> summary (json-able)``, reading the artifacts of the stages before it
from OUT and writing its own folder through the stages' Python API.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

__all__ = ["model", "tables", "fe", "campaign", "anatomy", "ARM_STATES"]


def _json(path: Path, data) -> None:
    path.write_text(json.dumps(data, indent=2, default=float))


def model(out: Path, config, console) -> dict:
    import meshio

    from persival.campaign.arm_simulator import muscle_surface
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.output import bone_surfaces, muscle_submesh

    folder = out / "model"
    with console.status(f"meshing the arm of {config.model or 'the built-in model'} ({config.profile} profile)"):
        arm = ArmModel(config.model, profile=config.profile)
    geometry = {"model": arm.spec.name, "model_hash": arm.model_hash, "profile": config.profile, "muscles": {}}
    for muscle in arm.spec.ordered_muscles():
        nodes, cells = muscle_submesh(arm, muscle.name)
        surface, _ = muscle_surface(arm, muscle.name)
        meshio.Mesh(arm.mesh.points[nodes], [("tetra10", cells)]).write(folder / f"mesh_{muscle.name}.vtu")
        geometry["muscles"][muscle.name] = {
            "tet10": int(len(cells)), "nodes": int(len(nodes)), "surface_nodes": int(len(surface)),
            "mesh_angle_deg": muscle.mesh_angle_deg, "fibre_prestretch": muscle.fibre_prestretch,
            "line_moment_arm_mm": {str(t): round(arm.line_moment_arm(muscle, t), 2) for t in (0, 45, 90, 120, 150)},
        }
        g = geometry["muscles"][muscle.name]
        console.print(f"  {muscle.name:16s} {g['tet10']:5d} tet10, {g['surface_nodes']:5d} surface nodes, "
                      f"line moment arm at 90 deg {g['line_moment_arm_mm']['90']:+.1f} mm")
    for name, (points, triangles) in bone_surfaces(arm, 90.0).items():
        meshio.Mesh(points, [("triangle", triangles)]).write(folder / f"bone_{name}_90deg.vtu")
    _json(folder / "geometry.json", geometry)
    return geometry


ARM_STATES = {"hanging": (0.0, 0.0, 0.0, 0.0, 0.0), "biceps_half": (0.5, 0.0, 0.0, 0.0, 0.0),
              "flexors_full": (1.0, 1.0, 1.0, 0.0, 0.0)}


def tables(out: Path, config, console) -> dict:
    """The FE arm's per-muscle response tables (docs/theory.md, section 4): built once per model and mesh in the
    state cache, reused by every later run; their moments go to OUT/tables/moments.npz."""
    if config.simulator != "arm":
        why = "the campaign runs the analytic stand-in"
        console.print(f"  [yellow]skipped[/yellow]: {why}")
        return {"skipped": why}
    from persival.tables.open import ensure_tables

    t0 = time.perf_counter()
    from persival.progress import progress_bar

    with progress_bar(console=console) as bar:
        task = bar.add_task("FE arm: meshing, rest states", total=None)
        table = ensure_tables(config.model, config.profile, None, lambda done, total: bar.update(
            task, completed=done, total=total, description="FE arm: response table columns (dask)"))
    moments = table.moment_table()
    moments.save(out / "tables" / "moments.npz")
    lo, hi = moments.finite_range_deg()
    failed = int(np.isnan(moments.tension).sum())
    console.print(f"  {table.root}: {len(table.angles_deg)} angles x {len(table.levels)} levels x 5 muscles, "
                  f"{failed} failed solves, converged over {lo:g}-{hi:g} deg; {table.build_seconds():.0f} s of "
                  f"column compute (once per model), {time.perf_counter() - t0:.0f} s this run")
    pushes = _pushes(moments, config.model, console)
    return {"root": str(table.root), "angles_deg": table.angles_deg.tolist(), "levels": table.levels.tolist(),
            "failed_solves": failed, "range_deg": [lo, hi], "column_compute_s": table.build_seconds(),
            "moments": str(out / "tables" / "moments.npz"), "pushes": pushes}


def _pushes(moments, model, console) -> dict:
    """The tables' "no muscle pushes" check (persival.tables.push_check), said in one line: over
    the whole table, and what of it lies within the joint's limits."""
    from persival.model.arm.model_file import load_model_file
    from persival.tables.push_check import push_check

    spec, _ = load_model_file(model)
    limits = tuple(spec.joint.limits_deg)
    report = push_check(moments, tuple(m.name for m in spec.muscles if m.action == "extensor"), limits)
    within = f"{limits[0]:g}-{limits[1]:g} deg"

    def said(name: str, key: str, angle: str, unit: str, inside_list: str) -> str:
        """'-16.2 N at 165 deg', and where the worst lies beyond the limits, what it is within them."""
        whole, inside = report["muscles"][name], report["muscles"][name]["in_joint_range"]
        digits = 1 if unit == "N" else 0
        text = f"{whole[key]:.{digits}f} {unit} at {whole[angle]:g} deg"
        if inside.get(angle) == whole[angle]:
            return text
        if name not in report[inside_list]:
            return f"{text} (not within {within})"
        return f"{text} ({inside[key]:.{digits}f} {unit} at {inside[angle]:g} deg within {within})"

    bad = [f"{name} pushes " + said(name, "least_tension_N", "at_deg", "N", "pushing_in_joint_range")
           for name in report["pushing"]]
    bad += [f"passive {name} flexes " + said(name, "passive_moment_max_Nmm", "passive_moment_at_deg", "N mm",
                                             "passive_extensors_flexing_in_joint_range")
            for name in report["passive_extensors_flexing"]]
    console.print("  no muscle pushes" if not bad else f"  [yellow]{'; '.join(bad)}[/yellow] (a muscle should pull, "
                  f"at least {report['limit_N']:g} N, and a passive extensor never flex: docs/arm_model.md)")
    return report


def fe(out: Path, config, console) -> dict:
    """Three FE states of the arm: from the response tables (exact path) when the run has them,
    else each continued from the hanging arm (from biceps 0.5 the jump to all flexors at 1 is a
    snap-through of the slack brachioradialis: docs/design/arm_model_record.md)."""
    from persival.evaluate.render import render_states
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.output import write_state
    from persival.model.arm.progress import ConsoleProgress

    arm = ArmModel(config.model, profile=config.profile)
    solver = None
    if config.simulator == "arm":
        from persival.tables.open import open_tables
        from persival.tables.table_solve import TableSolver

        solver = TableSolver(arm, open_tables(arm))
    rows, directories = {}, []
    with console.status("FE: the hanging arm (rest state, all activations 0)") as status, \
            ConsoleProgress(console, status, "FE: the hanging arm") as report:
        hanging = arm.base_state(progress=report)
    for name, activations in ARM_STATES.items():
        with console.status(f"FE: {name} {list(activations)} (joint equilibrium, Newton)") as status, \
                ConsoleProgress(console, status, f"FE: {name}") as report:
            if not any(activations):
                state = hanging
            elif solver is not None:
                state = solver.solve(activations, progress=report)
            else:
                state = arm.solve(activations, warm_start=hanging, progress=report)
        directories.append(write_state(arm, state, out / "fe" / name))
        rows[name] = {"activations": list(activations), "elbow_angle_deg": state.elbow_angle_deg,
                      "moment_residual_Nmm": state.moment_residual, "newton_iterations": state.statistics["iterations"],
                      "wall_time_s": state.wall_time_s, "max_abs_J_minus_1": state.max_volume_change}
        console.print(f"  {name:13s} elbow {state.elbow_angle_deg:6.2f} deg, moment residual {state.moment_residual:.1e} N mm, "
                      f"{state.statistics['iterations']} Newton iterations, {state.wall_time_s:.1f} s, "
                      f"max|J-1| {state.max_volume_change:.1e}")
    render_states(directories, out / "fe" / "arm.png")
    result = {"simulator": f"FE arm ({config.profile} profile)", "states": rows}
    _json(out / "fe" / "arm.json", result)
    return result


def campaign(out: Path, config, console) -> dict:
    """The SG design campaign and the random held-out states, or links to finished stores."""
    from persival.campaign.arm_simulator import arm_spec
    from persival.campaign.design import Design
    from persival.campaign.runner import INLINE, run_campaign
    from persival.campaign.simulator import SimulatorSpec
    from persival.campaign.store import CampaignStore

    folder = out / "campaign"
    spec = arm_spec(config.profile, "tables", config.model) if config.simulator == "arm" else SimulatorSpec(config.simulator)
    stores = {}
    for name, given, design in (("campaign", config.campaign_store, Design.sparse_grid(config.level)),
                                ("held_out", config.held_out_store, Design.random(config.held_out, seed=config.seed + 1))):
        path = folder / f"{name}.zarr"
        if given is not None:  # reuse: a symbolic link keeps the layout without copying the states
            if not path.is_symlink():  # a resumed stage has it already
                path.symlink_to(Path(given).resolve(), target_is_directory=True)
        else:
            console.print(f"  {name}: {len(design)} states of the {config.simulator} simulator"
                          + (" (resumed)" if path.exists() else ""))
            # retry_failed: a resumed stage retries what failed before (with the run's time limit,
            # perhaps a larger one); a new store has nothing failed
            run_campaign(path, design, spec, scheduler=INLINE if config.simulator == "analytic" else None,
                         timeout_s=config.state_timeout_s, retry_failed=True, progress=True)
        with CampaignStore.open(path) as store:
            stores[name] = {"path": str(path), **store.summary()}
        if name == "campaign":
            _check_complete(stores[name], path)
    if config.simulator == "arm":  # the table-only path on the same activations: a row of the evaluation
        path = folder / "held_out_table_only.zarr"
        with CampaignStore.open(folder / "held_out.zarr") as held:
            design = held.design
        run_campaign(path, design, arm_spec(config.profile, "interpolate", config.model), scheduler=INLINE,
                     progress=False)
        with CampaignStore.open(path) as store:
            stores["held_out_table_only"] = {"path": str(path), **store.summary()}
    for name, s in stores.items():
        console.print(f"  {name}: {s['done']} done, {s['failed']} failed, simulator {s['simulator']}")
    return stores


def _check_complete(summary: dict, path: Path) -> None:
    """The sparse grid needs every one of its states: stop the run, keeping the store, when some failed."""
    from persival.campaign.runner import CampaignIncomplete

    if summary["failed"] or summary["missing"]:
        reasons = "; ".join(f"{count} x {reason}" for reason, count in summary["failure_reasons"].items())
        raise CampaignIncomplete(
            f"{summary['failed']} of the sparse grid's {summary['total']} states failed ({reasons}) and "
            f"{summary['missing']} are missing; the sparse grid needs all of them. The same `persival run` "
            f"again (with a larger --state-timeout for timeouts) resumes the campaign and retries them; "
            f"so does `persival campaign run --store {path} --retry-failed`")


def anatomy(out: Path, config, console) -> dict:
    """Bodies inside each other and muscles off their beds in the FE stage's and the held-out states."""
    if config.simulator != "arm":
        why = "the campaign runs the analytic stand-in (no FE bodies)"
        console.print(f"  [yellow]skipped[/yellow]: {why}")
        return {"skipped": why}
    from persival.evaluate.anatomy_run import measure_run

    with console.status("anatomy: FE and held-out states"):
        table = measure_run(out, config.model)
    over = sorted(r["pair"] for r in table["rows"] if r.get("limit_mm") and not r["over"].startswith("0/"))
    console.print(f"  {table['notes'][0]}; {out}/anatomy/anatomy.md")
    return {"states": table["states"], "pair_states_over_limit": table["pair_states_over_limit"],
            "states_within_limits": table["states_within_limits"], "pairs_over_limit": over}
