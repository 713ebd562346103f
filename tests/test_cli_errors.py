"""Every subcommand, given bad input, answers as a newcomer should meet it (issue 16).

Exit code 2; stderr a single line starting with ``error:`` (or typer's usage-error box for a
malformed option); no traceback; and the working folder exactly as it was. Every input here
fails validation before any FE work, so the walk takes seconds.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from persival.cli import app

BOX = "usage error"  # expected answer: a malformed or out-of-range option, one line naming the command

# (command, arguments, what is wrong, expected: BOX or a fragment of the one-line error)
CASES = [
    ("run", ["--profile", "nosuch", "--out", "new"], "unknown profile", "unknown profile 'nosuch'"),
    ("run", ["--out", "afile"], "file where a folder is expected", "is a file, not a folder"),
    ("simulate", ["-a", "1.5,0,0,0,0", "--out", "new"], "out of range", "biceps = 1.5"),
    ("simulate", ["-a", "0,nan,0,0,0", "--out", "new"], "not finite", "not finite"),
    ("simulate", ["-a", "0.5,x", "--out", "new"], "malformed", "--activations must be comma-separated numbers"),
    ("simulate", ["-a", "0.5,0,0", "--out", "new"], "too few values", "--activations needs 5 numbers"),
    ("simulate", ["-a", "0,0,0,0,0", "--model", "nosuch.toml", "--out", "new"], "missing file", "no such file"),
    ("simulate", ["-a", "0,0,0,0,0", "--model", "folder", "--out", "new"], "folder where a file is expected",
     "is a directory"),
    ("simulate", ["-a", "0,0,0,0,0", "--model", "foreign.toml", "--out", "new"], "foreign model file", "invalid model file"),
    ("simulate", ["-a", "0,0,0,0,0", "--out", "afile"], "file where a folder is expected", "is a file, not a folder"),
    ("render", ["nosuch", "--out", "new.png"], "missing state folder", "not a state directory"),
    ("render", ["afile", "--out", "new.png"], "file where a state folder is expected", "not a state directory"),
    ("render", ["folder", "--out", "folder"], "folder where a file is expected", "is a folder, not a file"),
    ("render", ["folder", "--muscles", "deltoid", "--out", "new.png"], "unknown muscle", "muscles to draw must be"),
    ("sections", ["nosuch", "--out", "new.png"], "missing state folder", "not a state directory"),
    ("sections", ["folder", "--heights", "a,b", "--out", "new.png"], "malformed heights", "comma-separated numbers"),
    ("simulate", ["-a", "0,0,0,0,0", "--angle", "170", "--out", "new"], "held angle beyond the joint", "joint limits"),
    ("simulate", ["-a", "0,0,0,0,0", "--load", "-1", "--out", "new"], "negative load in the hand", "--load must be"),
    ("anatomy", ["nosuch"], "missing state folder", "not a state directory"),
    ("anatomy", ["folder", "--store", "random.zarr"], "state folders and a store", "one of the four"),
    ("anatomy", ["--run", "folder"], "a run folder with no FE states", "no FE states"),
    ("anatomy", ["--outlines", "--model", "foreign.toml"], "foreign model file", "invalid model file"),
    ("anatomy", ["--store", "random.zarr", "--out", "new.json"], "a store of the analytic stand-in",
     "anatomy needs FE arm states"),
    ("anatomy", ["--store", "nosuch.zarr"], "missing store", "does not exist"),
    ("anatomy", ["--store", "random.zarr", "--out", "folder"], "folder where a file is expected", "is a folder, not a file"),
    ("curves", ["--profile", "nosuch", "--out", "new"], "unknown profile", "unknown profile 'nosuch'"),
    ("curves", ["--model", "afile", "--out", "new"], "malformed model file", "not valid TOML"),
    ("curves", ["--out", "afile"], "file where a folder is expected", "is a file, not a folder"),
    ("accuracy", ["--test", "random.zarr", "--surrogate", "x=nosuch", "--out", "new"], "missing surrogate",
     "not a fitted surrogate"),
    ("accuracy", ["--test", "random.zarr", "--surrogate", "x=random.zarr", "--out", "new"], "a store given as surrogate",
     "not a fitted surrogate"),
    ("accuracy", ["--test", "random.zarr", "--surrogate", "nosuch", "--out", "new"], "malformed LABEL=DIR", "expects LABEL=DIR"),
    ("accuracy", ["--test", "random.zarr", "--surrogate", "x=folder", "--out", "afile"], "file where a folder is expected",
     "is a file, not a folder"),
    ("bench fe", ["--activation", "2"], "out of range", BOX),
    ("bench fe", ["--activation", "nan"], "not finite", BOX),
    ("bench fe", ["--backend", "nosuch"], "unknown backend", "unknown sparse solver backend"),
    ("bench deployed", ["--run", "folder"], "a folder that is no run", "no sparse-grid surrogate"),
    ("bench fe", ["--mesh-size", "0"], "out of range", BOX),
    ("bench sg", ["--degree", "2"], "even degree", "positive odd integer"),
    ("bench sg", ["--level", "0"], "out of range", BOX),
    ("campaign run", ["--store", "new.zarr", "--simulator", "analytic", "--level", "0"], "out of range", "level must be"),
    ("campaign run", ["--store", "new.zarr", "--simulator", "nosuch"], "unknown simulator", "unknown simulator kind"),
    ("campaign run", ["--store", "new.zarr", "--simulator", "analytic", "--design", "nosuch.csv"], "missing design file",
     "does not exist"),
    ("campaign run", ["--store", "new.zarr", "--simulator", "analytic", "--design", "bad.csv"], "design out of range",
     "anconeus = 1.5"),
    ("campaign run", ["--store", "new.zarr", "--simulator", "analytic", "--design", "nan.csv"], "design not finite",
     "not finite"),
    ("campaign run", ["--store", "new.zarr", "--simulator", "analytic", "--option", "oops"], "malformed option", "KEY=VALUE"),
    ("campaign run", ["--store", "new.zarr", "--simulator", "analytic", "--timeout", "nan"], "not finite",
     "timeout_s must be"),
    ("campaign run", ["--store", "afile", "--simulator", "analytic"], "file where a store is expected", "not a campaign store"),
    ("campaign run", ["--store", "afile/new.zarr", "--simulator", "analytic"], "file in the way of the folder",
     "a file is in the way"),
    ("campaign run", ["--store", "random.zarr", "--design", "sparse-grid", "--level", "1"], "foreign design for the store",
     "design: store has 3 points"),
    ("campaign status", ["--store", "nosuch.zarr"], "missing store", "does not exist"),
    ("campaign status", ["--store", "folder"], "folder that is not a store", "not a campaign store"),
    ("campaign export", ["--store", "nosuch.zarr", "--out", "new"], "missing store", "does not exist"),
    ("campaign export", ["--store", "random.zarr", "--out", "afile"], "file where a folder is expected",
     "is a file, not a folder"),
    ("surrogate fit-sg", ["--store", "nosuch.zarr", "--out", "new"], "missing store", "does not exist"),
    ("surrogate fit-structured", ["--store", "random.zarr", "--out", "new"], "a store of the analytic stand-in",
     "the 'analytic' simulator"),
    ("surrogate fit-structured", ["--store", "random.zarr", "--out", "new", "--tolerance", "0"], "zero tolerance",
     BOX),
    ("surrogate fit-structured", ["--store", "random.zarr", "--out", "new", "--frame", "muscle"], "unknown frame",
     "--frame must be 'world' or 'own'"),
    ("surrogate fit-sg", ["--store", "random.zarr", "--out", "new"], "foreign store (random design)", "sparse-grid"),
    ("surrogate fit-sg", ["--store", "random.zarr", "--out", "afile"], "file where a folder is expected",
     "is a file, not a folder"),
    ("surrogate adapt", ["--out", "new", "--max-points", "40", "--simulator", "analytic", "--seed-store", "nosuch.zarr"],
     "missing seed store", "does not exist"),
    ("surrogate adapt", ["--out", "new", "--max-points", "40", "--seed-store", "random.zarr"],
     "foreign seed store (analytic, not arm)", "computed with"),
    ("surrogate adapt", ["--out", "new", "--max-points", "0", "--simulator", "analytic"], "out of range", BOX),
    ("surrogate adapt", ["--out", "new", "--max-points", "40", "--simulator", "analytic", "--norm", "l7"], "unknown norm",
     "norm must be"),
    ("surrogate adapt", ["--out", "new", "--max-points", "40", "--simulator", "nosuch"], "unknown simulator", "arm or analytic"),
    ("surrogate adapt", ["--out", "afile", "--max-points", "40", "--simulator", "analytic"], "file where a folder is expected",
     "is a file, not a folder"),
    ("inverse", ["--surrogate", "nosuch"], "missing surrogate", "not a surrogate folder"),
    ("inverse", ["--surrogate", "random.zarr"], "a store given as surrogate", "not a surrogate folder"),
    ("inverse", ["--surrogate", "folder", "--angles", "20,x"], "malformed angles", "--angles must be"),
    ("inverse", ["--surrogate", "folder", "--out", "afile"], "file where a folder is expected", "is a file, not a folder"),
    ("data", ["--surrogate", "nosuch", "--activation-model", "nosuch.json", "--out", "new"], "missing surrogate",
     "not a surrogate folder"),
    ("data", ["--surrogate", "folder", "--activation-model", "afile", "--out", "new", "--angle-fraction", "2"],
     "out of range", BOX),
    ("train", ["--data", "nosuch", "--out", "new"], "missing training data", "not a dataset folder"),
    ("train", ["--data", "folder", "--out", "new", "--arch", "nosuch"], "unknown architecture", "arch must be"),
    ("train", ["--data", "folder", "--out", "new", "--device", "tpu"], "unknown device", "device must be auto, cpu or cuda"),
    ("train", ["--data", "folder", "--out", "new", "--epochs", "0"], "out of range", BOX),
    ("evaluate", ["--run", "nosuch"], "missing run folder", "no such run folder"),
    ("evaluate", ["--run", "folder"], "run folder without an SG", "no sparse-grid surrogate"),
    ("report", ["--run", "folder"], "run folder without an evaluation", "no evaluation"),
    ("report readme", ["--results", "nosuch.json"], "missing results file", "no such results file"),
    ("report readme", ["--results", "afile"], "a results file that is not JSON", "not JSON"),
    ("bench nn", ["--run", "afile"], "a file where a run folder is expected", "no such run folder"),
    ("export", ["--network", "nosuch", "--out", "new"], "missing network", "not a surrogate folder"),
    ("export", ["--network", "folder", "--out", "afile"], "file where a folder is expected", "is a file, not a folder"),
    ("serve", ["--artifacts", "nosuch"], "missing export folder", "no such artifact folder"),
    ("serve", ["--artifacts", "folder", "--port", "70000"], "out of range", BOX),
    ("bench serve", ["--artifacts", "nosuch", "--duration", "1"], "missing export folder", "no such artifact folder"),
    ("tables", ["--profile", "nosuch"], "unknown profile", "unknown profile 'nosuch'"),
    ("tables", ["--levels", "0.2,1"], "levels not from 0 to 1", "must run from 0 to 1"),
    ("tables", ["--angles", "0:160:-5"], "negative angle step", "--angles must be"),
    ("tables", ["--moments-out", "new.txt"], "moments file not .npz", "must name a .npz file"),
    ("tables", ["--out", "afile"], "foreign file in the way of the table", "not a response table"),
    ("simulate", ["-a", "0,0,0,0,0", "--method", "guess", "--out", "new"], "unknown method", "--method must be"),
    ("bench arm", ["--profile", "nosuch"], "unknown profile", "unknown profile 'nosuch'"),
    ("bench arm", ["--states", "0"], "out of range", BOX),
    ("bench arm", ["--out", "folder"], "folder where a file is expected", "is a folder, not a file"),
    ("moments", ["--profile", "nosuch", "--out", "new.npz"], "unknown profile", "unknown profile 'nosuch'"),
    ("moments", ["--out", "new.npz", "--levels", "0,x"], "malformed levels", "--levels must be"),
    ("moments", ["--out", "new.npz", "--levels", "0.2,1"], "levels not from 0 to 1", "must run from 0 to 1"),
    ("moments", ["--out", "afile"], "foreign file in the way of the table", "not a moment table"),
    ("moments", ["--out", "folder"], "folder where a file is expected", "is a folder, not a file"),
    ("model init", ["--out", "afile"], "existing file (never overwritten)", "exists; pick a new name"),
    ("model init", ["--from", "atlas_wall", "--out", "new.toml"], "misspelt packaged model", "not a packaged model"),
    ("model list", ["extra"], "an argument it does not take", BOX),
    ("simulate", ["-a", "0,0,0,0,0", "--model", "atlas_wall", "--out", "new"], "misspelt packaged model",
     "packaged models: default"),
    ("model init", ["--out", "folder"], "folder where a file is expected", "is a folder, not a file"),
    ("mesh", ["--model", "hole.toml", "--out", "new"], "surface with a large hole", "open surface with a hole"),
    ("mesh", ["--model", "overlap.toml", "--out", "new"], "outlines that overlap", "brachialis in biceps at 30 %"),
    ("simulate", ["-a", "0,0,0,0,0", "--model", "overlap.toml", "--out", "new"], "outlines that overlap",
     "brachialis in biceps at 30 %"),
    ("mesh", ["--model", "two.toml", "--out", "new"], "surface of two bodies", "2 disconnected bodies"),
    ("mesh", ["--model", "notmesh.toml", "--out", "new"], "surface file that is not a mesh", "not a triangle surface"),
    ("mesh", ["--model", "far.toml", "--out", "new"], "origin_point far from the surface", "from the surface"),
    ("mesh", ["--model", "metres.toml", "--out", "new"], "surface in metres read as mm", "likely in m "),
    ("mesh", ["--model", "hole.toml", "--muscles", "deltoid", "--out", "new"], "unknown muscle", "--muscles must be"),
    ("simulate", ["-a", "0,0,0,0,0", "--model", "metres.toml", "--out", "new"], "surface in metres read as mm",
     "likely in m "),
    ("tables", ["--model", "two.toml"], "surface of two bodies", "2 disconnected bodies"),
    ("run", ["--model", "hole.toml", "--out", "new"], "surface with a large hole", "open surface with a hole"),
    ("run", ["--model", "good.toml", "--simulator", "analytic", "--out", "new"], "model file with the analytic stand-in",
     "--model needs --simulator arm"),
    ("motion", ["--table", "nosuch.npz", "--out", "new"], "missing table", "no such moment table"),
    ("motion", ["--table", "afile", "--out", "new"], "foreign table", "not a moment table"),
    ("motion", ["--table", "afile", "--out", "new", "--loads", "1,-2"], "negative load", "--loads must be >= 0"),
    ("motion", ["--table", "afile", "--out", "new", "--loads", "nan"], "non-finite load", "not finite"),
    ("motion", ["--table", "afile", "--out", "new", "--angles", "inf"], "non-finite angle", "not finite"),
    ("motion", [], "neither a table nor a subcommand", "needs --table and --out"),
    ("motion play", ["--input", "noangle.csv", "--out", "new", "--artifacts", "export"], "no angle column",
     "which column is the elbow angle"),
    ("motion play", ["--input", "backwards.csv", "--out", "new", "--artifacts", "export"], "time going backwards",
     "time does not increase at frame 3"),
    ("motion play", ["--input", "nan.mot", "--out", "new", "--artifacts", "export"], "NaN in a motion file",
     "not a finite number"),
    ("motion play", ["--input", "far.csv", "--out", "new", "--artifacts", "export"], "no frame in the reachable range",
     "no frame lies inside the model's reachable range"),
    ("motion play", ["--input", "nosuch.csv", "--out", "new", "--artifacts", "export"], "missing recording",
     "no such file"),
    ("motion play", ["--input", "far.csv", "--out", "new", "--artifacts", "folder"], "not an export folder",
     "metadata.json: missing"),
    ("motion play", ["--input", "far.csv", "--out", "afile", "--artifacts", "export"], "file where a folder is expected",
     "is a file, not a folder"),
    ("motion play", ["--input", "far.csv", "--out", "new", "--artifacts", "export", "--load", "-1"], "negative load", BOX),
    ("bench viewer", ["--artifacts", "folder"], "not an export folder", "metadata.json: missing"),
    ("bench viewer", ["--artifacts", "export", "--json", "folder"], "folder where a file is expected",
     "is a folder, not a file"),
]


def leaf_commands(group=None, prefix: str = "") -> set[str]:
    """Every runnable subcommand of the app, e.g. "campaign run"."""
    group = group or typer.main.get_command(app)
    names = set()
    for name, command in group.commands.items():
        full = f"{prefix} {name}".strip()
        names |= leaf_commands(command, full) if hasattr(command, "commands") else {full}
    return names


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A folder with the inputs the cases name: a file, a folder, model and design files, a store."""
    from persival.campaign.design import Design
    from persival.campaign.runner import INLINE, run_campaign
    from persival.campaign.simulator import SimulatorSpec

    root = tmp_path_factory.mktemp("walk")
    (root / "afile").write_text("not a folder\n")
    (root / "folder").mkdir()
    (root / "foreign.toml").write_text('name = "a table that is no arm"\n[bones]\nradius = 3\n')
    from persival.model.arm.defaults import builtin_model_path

    atlas = (builtin_model_path().parent / "variants" / "atlas_arm.toml").read_text()
    (root / "overlap.toml").write_text(atlas.replace("{ z = 81.7, centre = [-2.0, 21.0]", "{ z = 81.7, centre = [-2.0, 32.0]"))
    (root / "bad.csv").write_text("0.1,0.2,0.3,0.4,1.5\n")
    (root / "nan.csv").write_text("0.1,0.2,nan,0.4,0.5\n")
    run_campaign(root / "random.zarr", Design.random(3, seed=0), SimulatorSpec("analytic", {}), scheduler=INLINE, progress=False)
    _bad_surfaces(root)
    # recordings for `motion play`, and an export whose reachable range ends below 150 deg
    from deploy.test_server import build_contract_export

    build_contract_export(root / "export")
    (root / "noangle.csv").write_text("time_s,shoulder_deg\n0,10\n1,20\n")
    (root / "backwards.csv").write_text("time_s,elbow_angle_deg\n0,40\n1,50\n0.5,60\n")
    (root / "nan.mot").write_text("Coordinates\ninDegrees=yes\nendheader\ntime\tr_elbow_flex\n0\t40\n0.1\tNaN\n")
    (root / "far.csv").write_text("time_s,elbow_angle_deg\n0,170\n1,175\n")
    return root


def _bad_surfaces(root: Path) -> None:
    """Model files whose biceps comes from a surface that must be refused (docs/own_anatomy.md)."""
    import numpy as np
    from surface_files import SPINDLE_LENGTH, model_with_surface, spindle, write_obj

    vertices, faces = spindle()
    cut = [row * 32 + column for row in range(12, 18) for column in range(8)]  # a 6 x 4 patch of the belly
    write_obj(root / "hole.obj", vertices, np.delete(faces, cut, axis=0))
    write_obj(root / "two.obj", np.vstack([vertices, vertices + [60.0, 0.0, 0.0]]), np.vstack([faces, faces + len(vertices)]))
    write_obj(root / "spindle.obj", vertices, faces)
    write_obj(root / "metres.obj", vertices / 1000.0, faces)
    (root / "notmesh.stl").write_text("a scanner's log file, no triangles\n")
    model_with_surface(root / "hole.toml", "hole.obj")
    model_with_surface(root / "two.toml", "two.obj")
    model_with_surface(root / "notmesh.toml", "notmesh.stl")
    model_with_surface(root / "far.toml", "spindle.obj", origin_point=(100.0, 0.0, 0.0))
    model_with_surface(root / "good.toml", "spindle.obj")
    model_with_surface(root / "metres.toml", "metres.obj", insertion_point=(0.0, 0.0, SPINDLE_LENGTH / 1000.0))


def test_every_subcommand_has_a_bad_input():
    missing = leaf_commands() - {command for command, *_ in CASES}
    assert not missing, f"add a bad-input case to tests/test_cli_errors.py for: {sorted(missing)}"


@pytest.mark.slow
def test_bad_inputs_are_one_line_errors_and_leave_nothing(workdir, monkeypatch, capsys):
    monkeypatch.chdir(workdir)
    runner = CliRunner()
    rows = []
    for command, args, what, expected in CASES:
        before = snapshot(workdir)
        result = runner.invoke(app, [*command.split(), *args], prog_name="persival")
        stderr = result.stderr.strip()
        label = f"persival {command} {' '.join(args)}"
        assert result.exception is None or isinstance(result.exception, SystemExit), f"{label}: {result.exc_info}"
        assert result.exit_code == 2, f"{label}: exit {result.exit_code}\n{result.output}"
        assert "Traceback" not in result.output, label
        if expected is BOX:  # click's usage error, as one line: "error: persival CMD: ... (`persival CMD --help` ...)"
            assert len(stderr.splitlines()) == 1 and stderr.startswith(f"error: persival {command}: "), f"{label}\n{stderr}"
            assert any(word in stderr for word in ("Invalid value", "Missing", "unexpected extra argument")), stderr
            message = stderr
        else:
            assert len(stderr.splitlines()) == 1 and stderr.startswith("error: "), f"{label}: not one line\n{stderr}"
            assert expected in stderr, f"{label}: {stderr!r} lacks {expected!r}"
            message = stderr
        assert snapshot(workdir) == before, f"{label} changed the working folder"
        rows.append((f"{command} {' '.join(args)}", what, message))
    with capsys.disabled():  # the count shows in every run; the table with -s
        print(f"\n{len(rows)} bad inputs tried over {len(leaf_commands())} subcommands: exit 2, one short message, nothing left")
    for command, what, message in rows:
        print(f"  persival {command:<90.90} | {what:<38} | {message}")


def test_internal_errors_are_one_line_unless_debug():
    from persival.cli.errors import ErrorReportingGroup

    demo = typer.Typer(cls=ErrorReportingGroup)

    @demo.callback()
    def main(debug: bool = typer.Option(False, "--debug")) -> None:
        """Like persival's main app."""

    @demo.command()
    def boom() -> None:
        raise RuntimeError("a bug")

    result = CliRunner().invoke(demo, ["boom"])
    assert result.exit_code == 1 and result.stderr.startswith("internal error: RuntimeError: a bug")
    assert len(result.stderr.splitlines()) == 1 and "--debug" in result.stderr
    result = CliRunner().invoke(demo, ["--debug", "boom"])
    assert isinstance(result.exception, RuntimeError)  # re-raised: typer prints its traceback


def test_a_hanging_arm_that_does_not_converge_is_a_clean_error(tmp_path, monkeypatch):
    """A model whose hanging arm has no FE equilibrium within the retries (e.g. a variant meant for
    flexed poses) ends `persival simulate` with one error line and exit 3, nothing written."""
    import persival.model.arm.arm_model as arm_module
    from persival.model.fe.solver import ConvergenceError

    class StallingArm:
        def __init__(self, *args, **kwargs):
            pass

        def base_state(self, progress=None):
            raise ConvergenceError("muscle 'biceps' from 120.0 deg, activation 0.00 to 20.0 deg, 0.00: stalled")

    monkeypatch.setattr(arm_module, "ArmModel", StallingArm)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["simulate", "-a", "0,0,0,0,0", "--out", "new"])
    stderr = result.stderr.strip()
    assert result.exit_code == 3, result.output
    assert len(stderr.splitlines()) == 1 and stderr.startswith("error: the hanging arm"), stderr
    assert "stalled" in stderr and "Traceback" not in result.output
    assert not list(tmp_path.iterdir())
