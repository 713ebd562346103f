"""The upper-limb model file (SPEC 3.3): the default loads, bad files get clear errors."""

import numpy as np
import pytest

from persival.model.arm import ArmModel, muscle_profile
from persival.model.arm_file import ModelFileError, load_model_file
from persival.model.defaults import default_model_path
from persival.model.geometry import swept_solid_mesh
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
        ("mesh_angle_deg = 90.0", "mesh_angle_deg = 170.0", "outside the joint limits"),
        ("limits_deg = [0.0, 160.0]", "limits_deg = [160.0, 0.0]", "lower < upper"),
        ("[joint]", "[joint]\nstiffness = 3", "stiffness"),  # unknown keys are refused
        ("name = \"persival-upper-limb\"", "name = [", "not valid TOML"),
    ],
)
def test_bad_model_files_are_refused(tmp_path, old, new, message):
    with pytest.raises(ModelFileError, match=message):
        load_model_file(edited(tmp_path, old, new))


def test_missing_file_and_unknown_profile(tmp_path):
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model_file(tmp_path / "nope.toml")
    model, _ = load_model_file()
    with pytest.raises(ModelFileError, match="unknown profile 'huge'"):
        model.profile("huge")


def test_moment_arms_at_90_degrees_are_anatomical():
    """Straight-line moment arms of the default geometry within SPEC 3.3's ranges."""
    arm = ArmModel.__new__(ArmModel)  # geometry only: no meshing
    arm.spec, _ = load_model_file()
    arm.axis, arm.centre = np.array([1.0, 0.0, 0.0]), np.zeros(3)
    expected = {"biceps": (35, 45), "brachialis": (20, 25), "brachioradialis": (50, 70), "triceps": (-22, -18),
                "anconeus": (-12, -8)}
    for muscle in arm.spec.ordered_muscles():
        r = arm.line_moment_arm(muscle, 90.0)
        lo, hi = expected[muscle.name]
        assert lo <= r <= hi, (muscle.name, r)
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
    assert result.exit_code != 0 and "need 5 activations" in result.output
    result = runner.invoke(app, ["simulate", "-a", "1.5,0,0,0,0", "--out", str(out)])
    assert result.exit_code == 2 and "[0, 1]" in result.output
    bad = tmp_path / "bad.toml"
    bad.write_text("name = [")
    result = runner.invoke(app, ["simulate", "-a", "0.5,0,0,0,0", "--model", str(bad), "--out", str(out)])
    assert result.exit_code == 2 and "not valid TOML" in result.output
    assert not out.exists()  # nothing written
