"""Fascial walls (persival.model.anatomy.walls): a septum's window and a sleeve give the exact contact
force and tangent (central differences of the energy and of the force), a septum acts only in its
band and keeps each muscle to the side it is meshed on, and a model file's walls reach the
muscles that name them."""

from __future__ import annotations

import numpy as np
import pytest
from contact_differences import differences

from persival.model.anatomy.obstacles import Capsule
from persival.model.anatomy.walls import Septum, Sleeve, septum_sides, wall_obstacles
from persival.model.fe.contact import ObstacleContact
from persival.model.fe.geometry import box_mesh


def test_septum_and_sleeve_tangents_match_finite_differences():
    """A block's nodes across a septum's ramp (the window's slope and curvature count) and
    outside a sleeve (shaft and the end beyond it)."""
    mesh = box_mesh((2, 2, 2), (10.0, 10.0, 10.0))
    x0 = mesh.points + 0.3 * np.random.default_rng(1).standard_normal(mesh.points.shape)
    septum = Septum([0.0, 4.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], (3.0, 40.0), 6.0, "septum")
    sleeve = Sleeve(Capsule([5.0, 5.0, -20.0], [5.0, 5.0, 8.0], 6.5, "sleeve"))
    contact = ObstacleContact.at_nodes(mesh, [septum, sleeve], 3.0)
    g_septum, g_sleeve = septum.project(x0)[0], sleeve.project(x0)[0]
    z = x0[:, 2]
    assert np.any((g_septum > 0) & (z > 3.0) & (z < 9.0)) and np.any((g_septum > 0) & (z > 9.0))  # ramp and full
    assert np.any(g_sleeve > 0) and np.any((g_sleeve > 0) & (z > 8.0))  # shaft and beyond the end
    asymmetry, tangent, force = differences(contact, x0)
    assert asymmetry < 1e-12 and tangent < 1e-7 and force < 1e-7


def test_septum_acts_only_in_its_band_and_keeps_each_side():
    septum = Septum([0.0, 30.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], (40.0, 160.0), 20.0, "septum")
    x = np.array([[0.0, 25.0, 20.0], [0.0, 25.0, 50.0], [0.0, 25.0, 100.0], [0.0, 25.0, 170.0], [0.0, 35.0, 100.0]])
    g = septum.project(x)[0]
    assert g[0] == 0.0 and g[3] == 0.0  # below and above the band
    assert 0.0 < g[1] < 5.0 and g[2] == pytest.approx(5.0) and g[4] < 0.0  # ramping in, fully on, free side

    class Wall:  # a model-file entry (persival.model.arm.model_file.Wall)
        name, kind, segment = "septum", "septum", "upper_arm"
        point, normal, along, band, ramp = (0.0, 30.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (40.0, 160.0), 20.0
        turns, fades_deg, gives_mm = 0.0, None, 0.0

    deep = np.array([[0.0, 20.0, 100.0], [3.0, 22.0, 120.0]])
    superficial = deep + [0.0, 25.0, 0.0]
    origin, axis = np.zeros(3), np.array([1.0, 0.0, 0.0])
    assert septum_sides([Wall], origin, axis, 60.0, deep) == {"septum": -1.0}
    assert septum_sides([Wall], origin, axis, 60.0, superficial) == {"septum": 1.0}
    kept_deep = wall_obstacles([Wall], origin, axis, 60.0, {"septum": -1.0})[0]
    assert kept_deep.project(deep)[0].max() <= 0.0 and kept_deep.project(superficial)[0].min() > 0.0


def test_the_built_in_arm_keeps_biceps_and_brachialis_on_either_side_of_its_septum():
    """persival/model/arm/default_arm.toml: the septum reaches both muscles, turned so that
    each keeps to the side it is laid out on (the sides from its centre line's stations here, from
    its mesh nodes in the arm), with the whole centre line on that side."""
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.body import ArmBody
    from persival.model.arm.defaults import builtin_model_path

    frame = ArmBody.frame(builtin_model_path(), "coarse")  # no mesh
    normals = {}
    for name in ("biceps", "brachialis"):
        muscle = frame.spec.muscle(name)
        line = frame.centre_line(muscle)
        walls = {type(o).__name__: o for o in ArmModel._bones_of(frame, muscle, line)(muscle.mesh_angle_deg)}
        normals[name] = walls["Septum"].normal
        assert walls["Septum"].project(line)[0].max() <= 0.0
    assert normals["biceps"] @ [0.0, 1.0, 0.0] == pytest.approx(1.0)  # the biceps in front
    assert normals["brachialis"] @ [0.0, 1.0, 0.0] == pytest.approx(-1.0)  # the brachialis behind, on the bone
    assert "Capsule" in {type(o).__name__ for o in ArmModel._bones_of(frame, frame.spec.muscle("brachialis"),
                                                                        line)(20.0)}
    triceps = frame.spec.muscle("triceps")  # and the deep fascia behind the triceps keeps it on the bone
    line = frame.centre_line(triceps)
    walls = {type(o).__name__: o for o in ArmModel._bones_of(frame, triceps, line)(20.0)}
    fascia = walls["Septum"]
    assert fascia.normal @ [0.0, 1.0, 0.0] == pytest.approx(1.0) and fascia.project(line)[0].max() <= 0.0


def test_a_wall_that_turns_with_the_elbow_turns_about_its_pivot_smoothly():
    """``turns``: the fraction of the flexion beyond ``turns_from_deg``, a smooth onset; the plane
    turns about the axis through its pivot (a point there stays, one 100 mm away moves on a circle)."""
    from persival.model.anatomy.walls import turn_deg

    class Wall:  # a model-file entry that turns back with flexion about a pivot 140 mm up
        name, kind, segment = "septum", "septum", "upper_arm"
        point, normal, along, band, ramp = (0.0, 31.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (45.0, 140.0), 15.0
        turns, turns_from_deg, pivot, fades_deg, gives_mm = -0.06, 60.0, (0.0, 31.0, 140.0), None, 0.0

    assert abs(turn_deg(Wall, 20.0)) < 0.02  # at rest it has barely turned (0.011 deg)
    assert turn_deg(Wall, 145.0) == pytest.approx(-0.06 * 85.0, abs=1e-3)  # beyond the onset: the fraction
    angles = np.linspace(40.0, 80.0, 401)
    slope = np.gradient([turn_deg(Wall, a) for a in angles], angles)
    assert np.all(np.abs(np.diff(slope)) < 1e-3) and slope[0] > -0.01 and slope[-1] < -0.05  # smooth onset
    origin, axis = np.zeros(3), np.array([1.0, 0.0, 0.0])
    turned = wall_obstacles([Wall], origin, axis, 145.0, {})[0]
    phi = np.radians(turn_deg(Wall, 145.0))
    assert turned.project(np.array([[0.0, 31.0, 140.0]]))[0][0] == pytest.approx(0.0, abs=1e-9)  # the pivot stays
    below = np.array([[0.0, 31.0 + 100.0 * np.sin(phi), 140.0 - 100.0 * np.cos(phi)]])  # 100 mm down the turned plane
    assert turned.project(below)[0][0] == pytest.approx(0.0, abs=1e-9)
    assert below[0, 1] == pytest.approx(31.0 - 8.9, abs=0.1)  # the lower band 8.9 mm further back


def test_a_turning_wall_without_a_pivot_is_refused(tmp_path):
    from persival.model.anatomy.schema_base import ModelFileError
    from persival.model.arm.defaults import builtin_model_path
    from persival.model.arm.model_file import load_model_file

    text = builtin_model_path().read_text()
    edited = text.replace("band = [45.0, 140.0]\n", "band = [45.0, 140.0]\nturns = -0.06\n", 1)
    assert edited != text
    (tmp_path / "arm.toml").write_text(edited)
    with pytest.raises(ModelFileError, match="anterior_septum.*needs a pivot"):
        load_model_file(tmp_path / "arm.toml")


def test_a_wall_that_fades_with_the_elbow_holds_then_lets_go_smoothly(tmp_path):
    """``fades_deg`` = (a, b): the wall's penetration is whole up to a, none from b, a smoothstep
    between (slope 0 at both ends); a falling range is refused with the wall named."""
    from persival.model.anatomy.schema_base import ModelFileError
    from persival.model.anatomy.walls import fade_share
    from persival.model.arm.defaults import builtin_model_path
    from persival.model.arm.model_file import load_model_file

    class Wall:
        name, kind, segment = "septum", "septum", "upper_arm"
        point, normal, along, band, ramp = (0.0, 31.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (45.0, 140.0), 15.0
        turns, turns_from_deg, pivot, fades_deg, gives_mm = 0.0, 60.0, None, (125.0, 145.0), 0.0

    assert [fade_share(Wall, a) for a in (90.0, 125.0, 135.0, 145.0, 160.0)] == pytest.approx([1, 1, 0.5, 0, 0])
    angles = np.linspace(120.0, 150.0, 301)
    slope = np.gradient([fade_share(Wall, a) for a in angles], angles)
    assert abs(slope[0]) < 1e-6 and abs(slope[-1]) < 1e-6 and slope.min() == pytest.approx(-1.875 / 20, rel=1e-2)
    inside = np.array([[0.0, 26.0, 90.0]])  # 5 mm behind the plane, mid-band
    depth = [wall_obstacles([Wall], np.zeros(3), np.array([1.0, 0, 0]), a, {})[0].project(inside)[0][0]
             for a in (100.0, 135.0, 150.0)]
    assert depth == pytest.approx([5.0, 2.5, 0.0])
    faded = wall_obstacles([Wall], np.zeros(3), np.array([1.0, 0, 0]), 135.0, {})[0]
    moved = faded.transformed(np.eye(3), np.zeros(3))  # a muscle's frame: the share goes along
    assert moved.project(inside)[0][0] == pytest.approx(2.5)

    text = builtin_model_path().read_text()
    edited = text.replace("band = [45.0, 140.0]\n", "band = [45.0, 140.0]\nfades_deg = [140.0, 120.0]\n", 1)
    (tmp_path / "arm.toml").write_text(edited)
    with pytest.raises(ModelFileError, match="anterior_septum.*fades_deg must rise"):
        load_model_file(tmp_path / "arm.toml")
    fascia = 'kind = "septum"\npoint = [0.0, -40.0, 0.0]'
    sleeve = text.replace(fascia, 'kind = "sleeve"\ngives_mm = 2.0\npoint = [0.0, -40.0, 0.0]', 1)
    assert sleeve != text
    (tmp_path / "arm.toml").write_text(sleeve)
    with pytest.raises(ModelFileError, match="only a septum gives way"):
        load_model_file(tmp_path / "arm.toml")


def test_a_septum_that_gives_way_moves_away_from_the_muscle_it_holds():
    """``gives_mm`` over ``gives_deg``: kept from either side, the plane moves by the smoothstep's
    share of gives_mm towards the other side (the muscle it holds may go that much further)."""
    from persival.model.anatomy.walls import give_mm

    class Wall:
        name, kind, segment = "septum", "septum", "upper_arm"
        point, normal, along, band, ramp = (0.0, 31.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (45.0, 140.0), 15.0
        turns, fades_deg, gives_mm, gives_deg = 0.0, None, 5.0, (120.0, 140.0)

    assert [give_mm(Wall, a) for a in (100.0, 130.0, 150.0)] == pytest.approx([0.0, 2.5, 5.0])
    origin, axis = np.zeros(3), np.array([1.0, 0.0, 0.0])
    behind, ahead = np.array([[0.0, 28.0, 90.0]]), np.array([[0.0, 34.0, 90.0]])  # 3 mm past the plane either way
    for theta, depth in ((100.0, 3.0), (150.0, -2.0)):  # 5 mm given: 2 mm clear
        assert wall_obstacles([Wall], origin, axis, theta, {"septum": 1.0})[0].project(behind)[0][0] == pytest.approx(depth)
        assert wall_obstacles([Wall], origin, axis, theta, {"septum": -1.0})[0].project(ahead)[0][0] == pytest.approx(depth)
