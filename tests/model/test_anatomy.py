"""Overlap between bodies and bed gaps (persival.model.anatomy.overlap, `persival anatomy`).

Known answers on simple closed surfaces (boxes overlapping by an exact depth, spheres, a tube
beside a rod at a known gap), and on the coarse arm's hanging state: the library's inside test
agrees with an independent generalized winding number on real muscle surfaces.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from persival.model.anatomy.overlap import Body, bed_gaps, overlaps


def _surface(mesh, shift=(0.0, 0.0, 0.0)):
    mesh = mesh.triangulate().clean()
    return np.asarray(mesh.points, dtype=float) + shift, np.asarray(mesh.faces).reshape(-1, 4)[:, 1:]


def _box(lo, hi, level=8):
    import pyvista as pv

    return _surface(pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]), level=level, quads=False))


def winding_number(x: np.ndarray, points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Generalized winding number of points x w.r.t. a closed triangle surface (1 inside, 0
    outside): the solid angles of the triangles seen from x (Van Oosterom and Strackee)."""
    a, b, c = (points[triangles[:, k]][None] - x[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
    det = np.einsum("nki,nki->nk", a, np.cross(b, c))
    div = la * lb * lc + np.einsum("nki,nki->nk", a, b) * lc + np.einsum("nki,nki->nk", b, c) * la \
        + np.einsum("nki,nki->nk", c, a) * lb
    return np.abs(2.0 * np.arctan2(det, div).sum(axis=1) / (4.0 * np.pi))


def test_boxes_overlapping_by_two_mm_give_that_depth_and_the_nodes_inside():
    pa, ta = _box((0, 0, 0), (10, 10, 10))
    pb, tb = _box((8, -1, -1), (18, 11, 11))
    rows = {(r["body"], r["inside"]): r for r in overlaps([Body("a", pa, ta), Body("b", pb, tb)])}
    assert rows[("a", "b")]["deepest_mm"] == pytest.approx(2.0, abs=1e-6)
    assert rows[("b", "a")]["deepest_mm"] == pytest.approx(2.0, abs=1e-6)
    # a's nodes strictly beyond x = 8 are all inside b (b spans a's whole y and z range)
    assert rows[("a", "b")]["nodes"] == int(np.count_nonzero(pa[:, 0] > 8.0 + 1e-9))
    # reversed winding of a surface changes nothing (it is oriented before the distance)
    again = overlaps([Body("a", pa, ta[:, ::-1]), Body("b", pb, tb)])
    assert again[0]["nodes"] == rows[("a", "b")]["nodes"] and again[0]["deepest_mm"] == pytest.approx(2.0, abs=1e-6)


def test_spheres_penetrate_by_twice_the_radius_less_the_distance():
    import pyvista as pv

    p, t = _surface(pv.Sphere(radius=10.0, theta_resolution=80, phi_resolution=80))
    a, b = Body("a", p, t), Body("b", p + [15.0, 0.0, 0.0], t)
    row = overlaps([a, b])[0]
    assert row["deepest_mm"] == pytest.approx(5.0, abs=0.05)  # 2 R - d
    r = np.linalg.norm(p - [15.0, 0.0, 0.0], axis=1)  # distance to b's centre
    # inside the faceted b: all nodes clear of its facets, none beyond its vertices
    assert np.count_nonzero(r < 10.0 - 0.05) <= row["nodes"] <= np.count_nonzero(r < 10.0)
    assert overlaps([a, Body("far", p + [25.0, 0.0, 0.0], t)]) == []


def test_nodes_near_a_muscles_ends_are_attachments_not_overlap():
    pa, ta = _box((0, 0, 0), (10, 10, 10))
    pb, tb = _box((8, -1, -1), (18, 11, 11))
    # a muscle whose insertion end sits in the overlap: the nodes within 4 mm of it are left out
    ends = np.array([[-50.0, 5.0, 5.0], [9.0, 5.0, 5.0]])
    inside = pa[:, 0] > 8.0 + 1e-9
    near = np.linalg.norm(pa - ends[1], axis=1) < 4.0
    row = overlaps([Body("m", pa, ta, ends), Body("bone", pb, tb)], attachment_mm=4.0)[0]
    assert row["body"] == "m" and row["nodes"] == int(np.count_nonzero(inside & ~near)) < np.count_nonzero(inside)
    assert np.linalg.norm(np.array(row["at"]) - ends[1]) >= 4.0
    # the whole overlap lies within 10 mm of that end (its farthest node is 7.1 mm away)
    assert overlaps([Body("m", pa, ta, ends), Body("bone", pb, tb)], attachment_mm=10.0) == []


def test_a_tube_beside_a_rod_has_the_gap_between_them():
    import pyvista as pv

    rod = _surface(pv.Cylinder(center=(0, 0, 100), direction=(0, 0, 1), radius=10.0, height=300, resolution=120))
    tube = _surface(pv.Line((0, 0, 0), (0, 0, 200), resolution=40).tube(radius=5.0, n_sides=120, capping=True),
                    shift=(0.0, 20.0, 0.0))
    ends = np.array([[0.0, 20.0, 0.0], [0.0, 20.0, 200.0]])
    bodies = [Body("biceps", *tube, ends), Body("humerus", *rod)]
    row = bed_gaps(bodies, beds={"biceps": ("humerus",)})[0]
    assert row["largest_gap_mm"] == pytest.approx(5.0, abs=0.05) and row["bed"] == ["humerus"]
    touching = [Body("biceps", tube[0] - [0.0, 6.0, 0.0], tube[1], ends - [0.0, 6.0, 0.0]), Body("humerus", *rod)]
    assert bed_gaps(touching, beds={"biceps": ("humerus",)})[0]["largest_gap_mm"] == 0.0


@pytest.mark.slow
def test_the_coarse_hanging_arm_inside_test_agrees_with_the_winding_number(tmp_path):
    """On the coarse arm's hanging state (meshing and the cached rest states: about 30 s), the
    nodes `persival anatomy` counts inside another muscle are exactly those whose winding number
    says so (away from the surface, where faceting decides), and the CLI writes the same JSON."""
    from typer.testing import CliRunner

    from persival.cli import app
    from persival.evaluate.anatomy import check_state_dirs
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.output import write_state

    arm = ArmModel(profile="coarse")
    state_dir = write_state(arm, arm.base_state(), tmp_path / "run" / "fe" / "hanging")
    result = check_state_dirs([state_dir])[0]
    assert result["elbow_angle_deg"] == pytest.approx(arm.base_state().elbow_angle_deg)
    assert {r["muscle"] for r in result["bed_gaps"]} == {"biceps", "brachialis", "brachioradialis", "triceps", "anconeus"}

    import meshio

    from persival.evaluate.anatomy import _muscle_ends, _tet10_surface
    from persival.model.anatomy.overlap import signed_distance

    def body(name):
        mesh = meshio.read(state_dir / f"{name}.vtu")
        return Body(name, *_tet10_surface(np.asarray(mesh.points, float), mesh.cells_dict["tetra10"]),
                    _muscle_ends(arm, result["elbow_angle_deg"])[name])

    brachialis, biceps = body("brachialis"), body("biceps")
    d = signed_distance(brachialis.points, biceps)
    clear = np.abs(d) > 0.5  # off the faceted surface
    w = winding_number(brachialis.points[clear], biceps.points, biceps.triangles)
    assert np.array_equal(w > 0.5, d[clear] < 0)
    counted = next((r for r in result["overlaps"] if (r["body"], r["inside"]) == ("brachialis", "biceps")), None)
    away = ~(brachialis.near_ends(brachialis.points, 10.0) | biceps.near_ends(brachialis.points, 10.0))
    assert (counted["nodes"] if counted else 0) == int(np.count_nonzero((d < 0) & away))

    out = tmp_path / "anatomy.json"
    run = CliRunner().invoke(app, ["anatomy", str(state_dir), "--out", str(out)])
    assert run.exit_code == 0, run.output
    written = json.loads(out.read_text())
    assert written["states"][0]["overlaps"] == json.loads(json.dumps(result["overlaps"]))
    assert "surface nodes of a body inside another" in run.output

    # the run's anatomy stage measures the same state: its table row is the pair's deepest
    from persival.evaluate.anatomy_run import measure_run

    table = measure_run(tmp_path / "run")
    row = next(r for r in table["rows"] if r["pair"] == "brachialis in biceps")
    assert row["fe_mm"] == pytest.approx(counted["deepest_mm"]) and row["held_mm"] is None
    assert (tmp_path / "run" / "anatomy" / "anatomy.md").is_file()
    assert json.loads((tmp_path / "run" / "anatomy" / "states.json").read_text())["states"][0]["state"] == "hanging"


def test_the_run_table_counts_a_pair_once_per_state_against_its_limit():
    """Two states: the first has the pair both ways over the 2 mm limit and a bone pair (no limit),
    the second a muscle-bone overlap under its 1 mm limit; so one pair-state over the limits."""
    from persival.evaluate.anatomy_run import anatomy_table

    def state(name, theta, overlaps):
        return {"state": name, "elbow_angle_deg": theta, "overlaps": [
            {"body": a, "inside": b, "nodes": 3, "of": 100, "deepest_mm": d} for a, b, d in overlaps],
            "bed_gaps": [{"muscle": "triceps", "bed": ["humerus"], "largest_gap_mm": 4.0 + theta / 100, "at_fraction": 0.5}]}

    fe = [state("hanging", 30.0, [("biceps", "brachialis", 3.0), ("brachialis", "biceps", 2.5), ("radius", "ulna", 5.0)])]
    held = [state("held_out/0", 90.0, [("biceps", "humerus", 0.8)])]
    table = anatomy_table(fe, held, "arm")
    rows = {r["pair"]: r for r in table["rows"]}
    assert table["pair_states_over_limit"] == 1 and table["states_within_limits"] == 1 and table["states"] == 2
    assert rows["biceps in brachialis"]["over"] == "1/2" and rows["biceps in humerus"]["over"] == "0/2"
    assert rows["radius in ulna"]["limit_mm"] is None and rows["radius in ulna"]["over"] == "-"
    assert rows["biceps in humerus"]["fe_mm"] is None and rows["biceps in humerus"]["held_mm"] == 0.8
    assert rows["triceps off its bed (humerus)"]["fe_mm"] == 4.3 and rows["triceps off its bed (humerus)"]["held_mm"] == 4.9


def test_beyond_the_functional_arc_the_limits_widen_and_the_triceps_bed_is_limited():
    """SPEC 3.3: at 140 deg muscle-muscle may reach 5 mm and muscle-bone 2 mm (3.0 and 1.5 mm are
    within), at 130 deg the arc's 2 and 1 mm hold (the same depths are over); a triceps belly 12 mm
    off the humerus is over its 10 mm in any state."""
    from persival.evaluate.anatomy import limit_text, pair_limit_mm
    from persival.evaluate.anatomy_run import anatomy_table

    assert [pair_limit_mm("biceps", "brachialis", a) for a in (None, 130.0, 130.5)] == [2.0, 2.0, 5.0]
    assert [pair_limit_mm("biceps", "humerus", a) for a in (None, 130.0, 140.0)] == [1.0, 1.0, 2.0]
    assert pair_limit_mm("radius", "ulna", 140.0) is None and limit_text("biceps", "radius") == "1 (2 beyond 130 deg)"

    def state(name, theta, gap):
        return {"state": name, "elbow_angle_deg": theta, "overlaps": [
            {"body": "biceps", "inside": "brachialis", "nodes": 3, "of": 100, "deepest_mm": 3.0},
            {"body": "biceps", "inside": "humerus", "nodes": 3, "of": 100, "deepest_mm": 1.5}],
            "bed_gaps": [{"muscle": "triceps", "bed": ["humerus"], "largest_gap_mm": gap, "at_fraction": 0.5}]}

    table = anatomy_table([state("flexed", 140.0, 4.0), state("arc", 130.0, 4.0)], [state("held_out/0", 140.0, 12.0)], "arm")
    rows = {r["pair"]: r for r in table["rows"]}
    assert rows["biceps in brachialis"]["over"] == "1/3" and rows["biceps in humerus"]["over"] == "1/3"
    assert rows["triceps off its bed (humerus)"]["over"] == "1/3" and rows["triceps off its bed (humerus)"]["limits"] == "10"
    assert table["states_within_limits"] == 1 and table["pair_states_over_limit"] == 3


def test_outlines_are_the_muscles_cross_sections_and_overlaps_are_refused_by_name():
    """The model file's outlines across the humerus (before meshing): where a centre line runs
    nearly along the humerus its outline is a circle of the station's radius about it; the
    default's overlapping outlines are refused in one message naming the muscles and the level."""
    from persival.model.anatomy.muscle_sweep import muscle_profile
    from persival.model.arm.cross_sections import OutlineOverlapError, check_outlines, outlines_at
    from persival.model.arm.kinematics import ArmKinematics

    arm = ArmKinematics()
    z = 150.0
    triceps = arm.spec.muscle("triceps")
    line = arm.centre_line(triceps)
    radius, _ = muscle_profile(triceps, np.linspace(0.0, 1.0, len(line)), arm.centre_line_length(triceps))
    ring = outlines_at(arm, z)["triceps"]
    assert len(ring) == 1 and np.allclose(ring[0][:, 2], z)
    i = np.flatnonzero((line[:-1, 2] - z) * (line[1:, 2] - z) <= 0)[0]
    t = (z - line[i, 2]) / (line[i + 1, 2] - line[i, 2])
    centre, r = line[i] + t * (line[i + 1] - line[i]), radius[i] + t * (radius[i + 1] - radius[i])
    distance = np.linalg.norm(ring[0][:, :2] - centre[:2], axis=1)
    tilt = np.linalg.norm(line[i + 1] - line[i]) / abs(line[i + 1, 2] - line[i, 2])  # 1 / cos of the tilt
    assert distance.min() == pytest.approx(r, rel=1e-6) and distance.max() == pytest.approx(r * tilt, rel=1e-3)
    with pytest.raises(OutlineOverlapError, match=r"brachialis in biceps at 30 % of the humerus \(z = 81.7 mm"):
        check_outlines(arm)


def test_a_layout_that_leaves_the_skin_is_refused_naming_the_muscle_and_level(tmp_path):
    """The built-in arm's file draws the skin: its outlines lie inside it; the skin is the
    model file's ellipses, interpolated between their heights; the same file with a mid-arm skin
    10 mm narrower front to back is refused before anything is meshed, naming the biceps."""
    from persival.model.arm.cross_sections import OutlineOverlapError, outline_overlaps, skin_at
    from persival.model.arm.defaults import builtin_model_path
    from persival.model.arm.kinematics import ArmKinematics

    source = builtin_model_path()
    atlas = ArmKinematics(source)  # checked on loading: nothing overlaps or leaves the skin
    assert not outline_overlaps(atlas)
    ring = skin_at(atlas.spec, 145.0)
    assert np.allclose([ring[:, 0].min(), ring[:, 0].max(), ring[:, 1].min(), ring[:, 1].max()],
                       [4.0 - 45.0, 4.0 + 45.0, 11.0 - 55.0, 11.0 + 55.0], atol=1e-9)
    halfway = skin_at(atlas.spec, 82.5)  # between the outlines at 20 and 145 mm
    assert halfway[:, 1].max() == pytest.approx(10.5 + 53.5) and np.allclose(halfway[:, 2], 82.5)
    narrow = tmp_path / "narrow_skin.toml"
    narrow.write_text(source.read_text().replace("semi_axes = [55.0, 45.0]", "semi_axes = [45.0, 44.0]"))
    with pytest.raises(OutlineOverlapError, match=r"outlines overlap or leave the skin: .*biceps outside the skin at "
                                                  r"50 % of the humerus \(z = 144.7 mm, 4.5 mm out\)"):
        ArmKinematics(narrow)
