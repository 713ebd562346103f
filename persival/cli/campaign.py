"""CLI of the campaign stage: ``persival campaign run | status | export``."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from persival.campaign.options import build_design, build_spec
from persival.cli.errors import check_output_dir, user_errors
from persival.cli.help import FullHelpGroup

_SIMULATOR_HELP = ("Simulator kind: arm (the built-in FE model), analytic (closed-form test model) "
                   "or external.")


def register(app: typer.Typer) -> None:
    """Attach this stage's commands to the main app."""
    campaign_app = typer.Typer(
        cls=FullHelpGroup, help="Simulation campaigns: run a simulator over a design into a store.", no_args_is_help=True)
    app.add_typer(campaign_app, name="campaign")
    campaign_app.command("run")(run)
    campaign_app.command("status")(status)
    campaign_app.command("export")(export)


def run(
    store: Path = typer.Option(
        ..., "--store", help="Campaign store (zarr directory); created if new, resumed if it exists."),
    design: str = typer.Option(
        None, "--design", help="sparse-grid, random or a .csv/.npy FILE (new store default: "
        "sparse-grid; existing store: its own design)."),
    level: int = typer.Option(2, "--level", help="Sparse-grid level (5-D: 1 -> 243 points, 2 -> 1053)."),
    n_random: int = typer.Option(100, "--n-random", help="Number of random points."),
    seed: int = typer.Option(0, "--seed", help="Seed of the random design."),
    simulator: str = typer.Option(
        None, "--simulator", help=_SIMULATOR_HELP + " New store default: arm; existing store: its own."),
    option: list[str] = typer.Option(
        [], "--option", help="Simulator option KEY=VALUE (value parsed as JSON if it can be), repeatable."),
    options_file: Path = typer.Option(None, "--options", help="JSON file with simulator options."),
    command: str = typer.Option(
        None, "--command", help="External: command template, e.g. "
        "'python fe.py --alpha {alpha} --out {out}/result.vtu'."),
    reference: Path = typer.Option(
        None, "--reference", help="External: result file with the reference (undeformed) geometry."),
    surface: list[str] = typer.Option(
        [], "--surface", help="External: NAME=SELECTOR (cell_data:NAME=V, cell_set:NAME, part:ID), "
        "repeatable."),
    result_file: str = typer.Option(
        None, "--result-file", help="External: mesh file the command writes in {out} (default result.vtu)."),
    scheduler: str = typer.Option(
        None, "--scheduler", help="Dask scheduler address (tcp://host:8786), or 'inline' for "
        "in-process; default: a LocalCluster."),
    workers: int = typer.Option(
        None, "--workers", help="LocalCluster worker processes (default: one per core)."),
    timeout: float = typer.Option(
        None, "--timeout", help="Seconds per attempt before a state is recorded as failed ('timeout')."),
    max_attempts: int = typer.Option(
        3, "--max-attempts", help="Attempts per state (retries use smaller load steps)."),
    retry_failed: bool = typer.Option(
        False, "--retry-failed", help="Also recompute states recorded as failed."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Run (or resume) a campaign: solve every missing state of the design into the store."""
    from persival.campaign.design import DesignError
    from persival.campaign.runner import run_campaign
    from persival.campaign.simulator import UnknownSimulatorError
    from persival.campaign.store import CampaignStore, StoreError

    # No out=: a failure half-way keeps the states solved so far (the store resumes); the
    # runner checks every input before it creates a new store.
    with user_errors(DesignError, StoreError, UnknownSimulatorError, TypeError):
        if store.exists():
            existing = CampaignStore.open(store)
            d = existing.design if design is None else build_design(design, level, n_random, seed)
            if simulator is None and not (option or options_file or command or reference or surface):
                spec = existing.spec
            else:
                spec = build_spec(simulator or existing.spec.kind, option, options_file,
                                  command, reference, surface, result_file)
            existing.close()
        else:
            d = build_design(design, level, n_random, seed)
            spec = build_spec(simulator or "arm", option, options_file, command, reference,
                              surface, result_file)
        _prepare(spec, scheduler, workers)
        summary = run_campaign(store, d, spec, scheduler=scheduler, n_workers=workers,
                               timeout_s=timeout, max_attempts=max_attempts,
                               retry_failed=retry_failed, progress=progress)
    _print_summary(summary)


def status(
    store: Path = typer.Option(..., "--store", help="Campaign store."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """Done / failed / missing counts, failure reasons and provenance of a store."""
    from persival.campaign.store import CampaignStore, StoreError

    with user_errors(StoreError):
        s = CampaignStore.open(store)
        summary = s.summary()
        summary["provenance"] = s.provenance
        summary["simulator_spec"] = json.loads(s.spec.to_json())
    if as_json:
        typer.echo(json.dumps(summary, indent=1))
    else:
        _print_summary(summary)


def export(
    store: Path = typer.Option(..., "--store", help="Campaign store."),
    out: Path = typer.Option(..., "--out", help="Output directory for the VTU series."),
    progress: bool = typer.Option(True, "--progress/--no-progress"),
) -> None:
    """Export done states as VTU files plus campaign.pvd (open it in ParaView)."""
    from persival.campaign.export import export_vtu
    from persival.campaign.store import StoreError

    with user_errors(StoreError, out=out):
        check_output_dir(out)
        res = export_vtu(store, out, progress=progress)
    typer.echo(f"wrote {res['states']} states to {res['out']} (open campaign.pvd in ParaView)")



def _prepare(spec, scheduler, workers) -> None:
    """The FE arm's response tables before its campaign (built once per model and mesh)."""
    from rich.console import Console

    from persival.campaign.arm_simulator import prepare_spec

    if spec.kind != "arm":
        return
    with Console().status("FE arm: meshing, hanging arm, response tables (built once per model)") as status:
        prepare_spec(spec, lambda done, total: status.update(f"FE arm: response table columns {done}/{total}"),
                     scheduler, workers)


def _print_summary(summary: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"campaign {summary['path']}", show_header=False)
    table.add_row("simulator", str(summary["simulator"]))
    table.add_row("states", f"{summary['total']} total: [green]{summary['done']} done[/], "
                            f"[red]{summary['failed']} failed[/], {summary['missing']} missing")
    run = summary.get("this_run")
    if run:
        rate = run["states_per_hour"]
        table.add_row("this run", f"{run['computed']} computed in {run['elapsed_s']:.1f} s"
                      + (f" ({rate:,.0f} states/h)" if rate else "")
                      + (f", {run['lost']} lost (still missing)" if run["lost"] else ""))
    if summary.get("wall_time_s_mean_done") is not None:
        table.add_row("wall time / done state", f"{summary['wall_time_s_mean_done']:.3g} s")
    table.add_row("store size", f"{summary['store_bytes'] / 1e6:.1f} MB")
    for reason, count in summary["failure_reasons"].items():
        table.add_row(f"failed x{count}", reason)
    Console().print(table)
