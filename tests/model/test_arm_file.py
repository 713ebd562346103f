"""The upper-limb model file (SPEC 3.3): the default loads, bad files get clear errors."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from persival.cli import app
from persival.model.anatomy.schema_base import ModelFileError
from persival.model.arm.arm_model import ArmModel, muscle_profile
from persival.model.arm.defaults import builtin_model_path, default_model_path, packaged_models, resolve_model_path
from persival.model.arm.model_file import load_model_file
from persival.model.fe.geometry import swept_solid_mesh
from persival.vocabulary import MUSCLES


def edited(tmp_path, old, new):
    text = default_model_path().read_text()
    assert old in text, old
    path = tmp_path / "arm.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_default_model_loads_with_five_muscles():
    model, digest = load_model_file()
    assert [m.name for m in model.ordered_muscles()] == list(MUSCLES)
    assert len(digest) == 64
    assert set(model.profiles) >= {"quick", "paper"}


@pytest.mark.parametrize(
    "old, new, message",
    [
        ('name = "anconeus"', 'name = "biceps"', "missing: \\['anconeus'\\]"),
        ("belly_radius = 20.0", "belly_radius = -20.0", "belly_radius"),
        ("origin = [0.0, 16.0, 330.0]", "origin = [0.0, 2.0, 150.0]", "inside bone 'humerus'"),
        ("tendon_radius = [4.0, 5.0]", "tendon_radius = [4.0, -5.0]", "tendon_radius must be positive"),
        ("mesh_angle_deg = 140.0", "mesh_angle_deg = 170.0", "outside the joint limits"),
        ("limits_deg = [0.0, 160.0]", "limits_deg = [160.0, 0.0]", "lower < upper"),
        ("[joint]", "[joint]\nstiffness = 3", "stiffness"),  # unknown keys are refused
        ("name = \"persival-upper-limb\"", "name = [", "not valid TOML"),
        ("insertion = [0.0, -18.0, 16.0]", "insertion = [0.0, -10.0, 10.0]", "inside its wrap cylinder"),
        ('insertion = [2.0, -2.0, -45.0]\nwrap_radius = 7.0', 'insertion = [2.0, -2.0, -45.0]\nwrap_cable = 10.0',
         "wrap_cable needs a wrap_radius"),
        ('insertion = [2.0, -2.0, -45.0]\nwrap_radius = 7.0', 'insertion = [2.0, -2.0, -45.0]\nwrap_radius = 7.0\n'
         'insertion_tie = "forearm"', "forearm-tied insertion face"),
        ('insertion = [2.0, -2.0, -45.0]\nwrap_radius = 7.0', 'insertion = [2.0, -2.0, -45.0]\ninsertion_tie = "bone"',
         "insertion_tie"),
        # a list entry is named by its name: one line that says which muscle
        ('insertion = [2.0, -2.0, -45.0]\nwrap_radius = 7.0', 'insertion = [2.0, -2.0, -45.0]\nwrap_radius = 7.0\n'
         'matrix_prestretch = 1.9', "muscles\\[biceps\\]\\.matrix_prestretch: Input should be less than or equal to 1.4"),
    ],
)
def test_bad_model_files_are_refused(tmp_path, old, new, message):
    with pytest.raises(ModelFileError, match=message):
        load_model_file(edited(tmp_path, old, new))


def test_missing_file_and_unknown_profile(tmp_path):
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model_file(tmp_path / "nope.toml")
    with pytest.raises(ModelFileError, match="packaged models: default, atlas_arm"):
        load_model_file("atlas_wall")  # a misspelt name lists the names
    model, _ = load_model_file()
    with pytest.raises(ModelFileError, match="unknown profile 'huge'"):
        model.profile("huge")


def test_path_moment_arms_are_in_the_spec_bands():
    """Moment arms of the default paths (straight or wrapped) in SPEC 3.3's bands (Murray et al. 1995)."""
    arm = ArmModel.__new__(ArmModel)  # geometry only: no meshing
    arm.spec, _ = load_model_file()
    arm.axis, arm.centre = np.array([1.0, 0.0, 0.0]), np.zeros(3)
    bands = {  # muscle: (angles, lowest, highest)
        "biceps": [((90.0,), 35, 45), ((140.0,), 25, None)],
        "brachialis": [((90.0,), 18, 30), ((140.0,), 18, None)],
        "brachioradialis": [((90.0, 105.0, 120.0), 45, 70)],
        "triceps": [(np.arange(0.0, 161.0, 5.0), -25, -15)],  # wrapped over the trochlea beyond 40 deg
        "anconeus": [(np.arange(0.0, 161.0, 5.0), -12, -5)],
    }
    for muscle in arm.spec.ordered_muscles():
        for angles, lo, hi in bands[muscle.name]:
            for theta in angles:
                r = arm.line_moment_arm(muscle, theta)
                assert lo <= r and (hi is None or r <= hi), (muscle.name, theta, r)
    # no muscle changes sides over the joint's range (a lever of at least 4 mm): a flexor behind
    # the hinge near 0 deg made some activations bistable (a second stable root near -8 deg)
    for muscle in arm.spec.ordered_muscles():
        sign = 1.0 if muscle.action == "flexor" else -1.0
        arms = np.array([arm.line_moment_arm(muscle, t) for t in np.arange(0.0, 161.0, 5.0)])
        assert (sign * arms > 4.0).all(), (muscle.name, arms.min(), arms.max())
    # the biceps' origin-insertion length shrinks by about a quarter from 0 to 150 deg
    biceps = arm.spec.muscle("biceps")
    length = [np.linalg.norm(np.array(biceps.origin) - arm.forearm_point(biceps.insertion, t)) for t in (0.0, 150.0)]
    assert 0.18 < 1 - length[1] / length[0] < 0.3


def test_paper_profile_biceps_surface_has_about_2809_nodes():
    arm = ArmModel.__new__(ArmModel)
    arm.spec, _ = load_model_file()
    arm.axis, arm.centre = np.array([1.0, 0.0, 0.0]), np.zeros(3)
    biceps = arm.spec.muscle("biceps")
    line = arm.centre_line(biceps)
    length = float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
    radius, _ = muscle_profile(biceps, np.linspace(0, 1, len(line)), length)
    mesh = swept_solid_mesh(line, radius, arm.spec.mesh_size("paper", "biceps"))
    n = len(mesh.surface_nodes())
    print(f"paper-profile biceps: {mesh.n_cells} tet10, {n} surface nodes")
    assert abs(n - 2809) <= 0.1 * 2809


def test_simulate_command_refuses_bad_input_before_meshing(tmp_path):
    from typer.testing import CliRunner

    from persival.cli import app

    runner = CliRunner()
    out = tmp_path / "out"
    result = runner.invoke(app, ["simulate", "-a", "0.5,0,0", "--out", str(out)])
    assert result.exit_code == 2 and "--activations needs 5 numbers" in result.output
    result = runner.invoke(app, ["simulate", "-a", "1.5,0,0,0,0", "--out", str(out)])
    assert result.exit_code == 2 and "[0, 1]" in result.output
    bad = tmp_path / "bad.toml"
    bad.write_text("name = [")
    result = runner.invoke(app, ["simulate", "-a", "0.5,0,0,0,0", "--model", str(bad), "--out", str(out)])
    assert result.exit_code == 2 and "not valid TOML" in result.output
    assert not out.exists()  # nothing written


def test_packaged_models_load_by_name(tmp_path, monkeypatch):
    """--model takes a packaged model's name; a file of that name in the working folder wins."""
    spindle = builtin_model_path().parent / "variants" / "spindle_arm.toml"
    assert packaged_models()["spindle_arm"] == spindle and packaged_models()["default"] == builtin_model_path()
    assert load_model_file("spindle_arm")[1] == load_model_file(spindle)[1]
    assert load_model_file("default")[1] == load_model_file(builtin_model_path())[1]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "spindle_arm").write_text(builtin_model_path().read_text())
    assert resolve_model_path("spindle_arm") == Path("spindle_arm")
    assert load_model_file("spindle_arm")[1] == load_model_file("default")[1]


def test_the_model_variable_picks_the_model_of_commands_without_model(tmp_path, monkeypatch):
    """$PERSIVAL_MODEL (a packaged name or a file) is what no --model means; unset, the built-in arm;
    naming nothing is refused in one line that names the variable."""
    monkeypatch.delenv("PERSIVAL_MODEL", raising=False)
    assert default_model_path() == builtin_model_path()
    assert [w.name for w in load_model_file(None)[0].walls] == ["anterior_septum", "posterior_fascia"]  # anatomical
    monkeypatch.setenv("PERSIVAL_MODEL", "spindle_arm")
    assert load_model_file(None)[1] == load_model_file("spindle_arm")[1]
    own = tmp_path / "own.toml"
    own.write_text(builtin_model_path().read_text())
    monkeypatch.setenv("PERSIVAL_MODEL", str(own))
    assert default_model_path() == own
    monkeypatch.setenv("PERSIVAL_MODEL", "nosuch_arm")
    with pytest.raises(ModelFileError, match="PERSIVAL_MODEL=nosuch_arm: no such model file"):
        load_model_file(None)
    result = CliRunner().invoke(app, ["simulate", "-a", "0,0,0,0,0", "--out", str(tmp_path / "o")])
    assert result.exit_code != 0 and "PERSIVAL_MODEL=nosuch_arm" in result.output
    assert not (tmp_path / "o").exists()


def test_model_list_and_init_from_a_variant(tmp_path):
    runner = CliRunner()
    listing = runner.invoke(app, ["model", "list"], env={"COLUMNS": "200"})
    assert listing.exit_code == 0, listing.output
    for name in packaged_models():
        assert name in listing.output
    assert "five muscles lofted through atlas outlines" in listing.output  # the file's own comment says what it is
    assert "spindle muscles along straight or bowed lines" in listing.output
    out = tmp_path / "spindle.toml"
    result = runner.invoke(app, ["model", "init", "--from", "spindle_arm", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_text() == packaged_models()["spindle_arm"].read_text()
    refused = runner.invoke(app, ["model", "init", "--from", "nosuch", "--out", str(tmp_path / "x.toml")])
    assert refused.exit_code != 0 and "not a packaged model" in refused.output
    assert not (tmp_path / "x.toml").exists()


def test_biceps_on_humerus_variant_loads():
    """The shipped variant: the default but for the biceps (humerus contact, forearm tie, meshed at 120 deg)."""
    variant = builtin_model_path().parent / "variants" / "biceps_on_humerus.toml"
    spec, _ = load_model_file(variant)
    default, _ = load_model_file("spindle_arm")
    biceps = {m.name: m for m in spec.ordered_muscles()}["biceps"]
    assert biceps.wraps == ["humerus"] and biceps.insertion_tie == "forearm" and biceps.mesh_angle_deg == 120.0
    assert [m for m in spec.ordered_muscles() if m.name != "biceps"] == [m for m in default.ordered_muscles()
                                                                         if m.name != "biceps"]
