"""CLI of the model stage: ``persival model list`` (the packaged model files), ``persival model
init`` (one of them, to edit) and ``persival mesh`` (a model's muscles meshed, with fibres and a
repair report, for inspection)."""

from __future__ import annotations

from pathlib import Path

import typer

from persival.cli.errors import check_output_dir, check_output_file, user_errors
from persival.cli.help import FullHelpGroup
from persival.model.arm.defaults import MODEL_HELP, profiles_help


def register(app: typer.Typer) -> None:
    """Attach ``model init`` and ``mesh`` to the main app."""
    model_app = typer.Typer(cls=FullHelpGroup, help="The model file: list the packaged ones, write one for editing.",
                            no_args_is_help=True)
    app.add_typer(model_app, name="model")
    model_app.command("list")(list_models)
    model_app.command("init")(init)
    app.command("mesh")(mesh)


def list_models() -> None:
    """The model files packaged with PerSival: pass a name as --model to any command."""
    from rich.console import Console
    from rich.table import Table

    from persival.model.arm.defaults import packaged_models

    models = packaged_models()
    folder = models["default"].parent
    # a file's path relative to the package's model folder, which is printed once in full: at 80
    # columns a full path per row was cut to "/work/main/persival/model…"
    table = Table(title="packaged models (--model NAME)", caption=f"files in {folder}", caption_justify="left")
    table.add_column("name", no_wrap=True)
    table.add_column("description")
    table.add_column("file", overflow="fold")
    for name, path in models.items():
        table.add_row(name, _first_comment(path.read_text()), str(path.relative_to(folder)))
    Console().print(table)


def _first_comment(text: str) -> str:
    """What a model file is: its opening comment's first sentence, after what it is a variant of,
    without parentheses."""
    import re

    lines = []
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("# ").strip())
    sentence = " ".join(lines).split(". ")[0]
    sentence = sentence.split("): ", 1)[-1]
    sentence = re.sub(r"\s*\([^()]*\)", "", sentence)
    return sentence.rstrip(".:")


def init(
    out: Path = typer.Option(Path("my_arm.toml"), "--out", help="Model file to write (TOML); an existing file is "
                             "never overwritten."),
    source: str = typer.Option("default", "--from", help="Packaged model to copy (`persival model list`)."),
) -> None:
    """Write a packaged model file (bones, joint, five muscles, mesh profiles) for editing."""
    from rich.console import Console

    from persival.model.arm.defaults import packaged_models

    with user_errors():
        models = packaged_models()
        if source not in models:
            raise ValueError(f"--from {source!r}: not a packaged model; choose one of {', '.join(models)}")
        check_output_file(out)
        if out.exists():
            raise FileExistsError(f"--out {out} exists; pick a new name (it is never overwritten)")
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(models[source].read_text())
    Console().print(f"wrote {out}: the packaged model {source!r}. Use it with --model {out} (persival simulate, tables, "
                    "mesh); a muscle can take its shape from a surface file (docs/own_anatomy.md).")


def mesh(
    model: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    muscles: str | None = typer.Option(None, "--muscles", help="Comma-separated muscles (default: those with their own "
                                       "surface, or all five when none has one)."),
    profile: str = typer.Option("quick", "--profile", help=profiles_help()),
    out: Path = typer.Option(Path("results/mesh"), "--out", help="Output folder: <muscle>.vtu, <muscle>_surface.vtp, "
                             "<muscle>.png, mesh_report.json."),
) -> None:
    """Mesh a model's muscles (own surfaces repaired, meshed, given Laplace fibres) and report each step."""
    from rich.console import Console

    from persival.model.arm.body import ArmBody
    from persival.model.arm.muscle_meshes import mesh_muscles
    from persival.model.fe.mesh import MeshError
    from persival.vocabulary import check_muscle_names

    console = Console()
    with user_errors():  # the model and its surfaces are checked before anything is written
        chosen = check_muscle_names(muscles, "--muscles") if muscles is not None else None
        body = ArmBody.frame(model, profile)
        chosen = chosen or tuple(body.surfaces) or check_muscle_names(None)
        check_output_dir(out)
    with user_errors(MeshError, out=out), console.status("meshing") as status:
        report = mesh_muscles(body, chosen, out, progress=lambda name: status.update(f"meshing the {name}"))
    _print_mesh_report(console, report, out)


def _print_mesh_report(console, report: dict, out: Path) -> None:
    from rich.table import Table

    table = Table(title=f"{report['model']}, {report['profile']} profile")
    for column in ("muscle", "verts in", "nodes", "kept", "tet10", "mm^3", "min q", "scale", "s", "arm mm"):
        table.add_column(column, justify="left" if column == "muscle" else "right")
    for name, e in report["muscles"].items():
        table.add_row(name, str(e.get("vertices_in", "-")), str(e["nodes_out"]), str(e.get("vertices_kept_as_nodes", "-")),
                      str(e["tetrahedra"]), f"{e['volume_mm3']:.0f}", f"{e['min_quality']:.3f}" if "min_quality" in e else "-",
                      f"{e.get('scale', 1.0):.3f}", f"{e['meshing_s']:.1f}",
                      " / ".join(f"{v:.1f}" for v in e["moment_arm_mm"].values()))
    console.print(table)
    console.print("kept: surface vertices that are mesh nodes; mm^3: volume; min q: minimum quality (gamma); arm: moment "
                  "arm of the line of action at the mesh pose / 90 deg")
    for name, e in report["muscles"].items():
        if e["surface"]:
            done = ", ".join(f"{k} {v}" for k, v in e["repairs"].items() if v) or "nothing to repair"
            console.print(f"{name} repairs: {done}")
        if e.get("fibre_fallback_cells"):
            console.print(f"{name} fibres: {e['fibre_fallback_cells']} cells with no Laplace gradient (past an attachment "
                          "face, or in a lobe neither face reaches) run along the centre line")
    console.print(f"wrote {out}: <muscle>.vtu, <muscle>_surface.vtp, <muscle>.png, mesh_report.json")
