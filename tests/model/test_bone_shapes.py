"""Bones with their shapes (persival.model.anatomy.bone_shapes): closed surfaces, sizes from the anatomy
literature (docs/design/arm_model_record.md, "Bones"), the hinge through the trochlea and the capitulum, and the
forearm bones turning about the humerus without entering it over the range the fossae take in."""

from __future__ import annotations

import numpy as np
import pytest

from persival.model.anatomy.bone_shapes import ElbowFrame, _solids, articular_layout, bone_shapes
from persival.model.anatomy.overlap import Body, overlaps, signed_distance
from persival.model.arm.kinematics import ArmKinematics


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


@pytest.fixture(scope="module")
def shapes(arm):
    return bone_shapes(arm.spec)


def _body(name, shapes):
    return Body(name, *shapes[name])


def test_every_bone_is_a_closed_manifold_surface_wound_outward(shapes):
    import pyvista as pv

    for name, (points, triangles) in shapes.items():
        surface = pv.PolyData(points, np.column_stack([np.full(len(triangles), 3), triangles]).ravel())
        assert surface.n_open_edges == 0 and surface.is_manifold, name
        p = points[triangles]
        assert np.einsum("ki,ki->k", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() > 0, name


def test_the_surfaces_enclose_the_volume_of_their_solids(arm, shapes):
    """The decimated surface's volume against the solid's own, counted on a 2 mm lattice."""
    frame = ElbowFrame.of(arm.spec)
    for name, (solid, lower, upper) in _solids(arm.spec, frame).items():
        axes = [np.arange(lo, hi, 2.0) for lo, hi in zip(lower, upper)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        counted = 8.0 * np.count_nonzero(solid(grid) < 0)
        points, triangles = shapes[name]
        p = points[triangles]
        meshed = np.einsum("ki,ki->k", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
        assert meshed == pytest.approx(counted, rel=0.02), name


def test_sizes_lie_in_the_published_ranges(arm, shapes):
    frame = ElbowFrame.of(arm.spec)
    humerus = frame.local(shapes["humerus"][0])
    length = np.ptp(humerus[:, 2])
    shape = arm.spec.bone("humerus").drawn_shape()
    assert length == pytest.approx(shape.length, abs=1.0)
    assert 307.1 - 2 * 20.8 <= length <= 307.1 + 2 * 20.8  # Akman et al. 2006, maximum length
    width = np.ptp(humerus[:, 0])
    assert width == pytest.approx(shape.epicondylar_width, abs=1.5)
    assert 58.4 - 2 * 4.4 <= width <= 58.4 + 2 * 4.4  # Fahrioglu et al. 2019
    section = _body("humerus", shapes).surface.slice(normal=frame.axes[2], origin=frame.world(np.array([0.0, 0.0, 150.0])))
    diameter = np.ptp(frame.local(np.asarray(section.points))[:, 0])
    assert 19.3 - 2 * 2.3 <= diameter <= 19.3 + 2 * 2.3  # Murdoch et al. 2002, MRI
    radius = frame.local(shapes["radius"][0])
    assert 207.0 <= np.ptp(radius[:, 2]) <= 269.0  # van Riet et al. 2004, range
    top = radius[:, 2].max()
    head = radius[radius[:, 2] > top - 8.0]
    assert 22.5 - 2 * 2.0 <= np.ptp(head[:, 0]) <= 24.2 + 2 * 2.2  # Surg Radiol Anat 2019: smallest, largest


def test_the_hinge_axis_runs_through_the_trochlea_and_the_capitulum(arm, shapes):
    """Around the axis, at the trochlear groove and the capitulum's centre, the articular surface
    is a circle of the trochlea's and the capitulum's radius over the arc the forearm bones use
    (phi from 0, distal, over anterior to 120 deg and back to -90, posterior)."""
    frame = ElbowFrame.of(arm.spec)
    shape = arm.spec.bone("humerus").drawn_shape()
    layout = articular_layout(shape, frame.local(arm.spec.bone("radius").start)[0])
    groove = layout.trochlea[1] - 2.0 - 0.45 * shape.trochlea_width
    humerus = _body("humerus", shapes)
    phi = np.radians(np.arange(-90.0, 121.0, 15.0))
    for x, radius in ((groove, shape.trochlea_radius), (layout.capitulum_centre, shape.capitulum_radius)):
        for rho, inside in ((radius - 0.5, True), (radius + 0.5, False)):
            ring = np.column_stack([np.full_like(phi, x), rho * np.sin(phi), -rho * np.cos(phi)])
            assert np.all((signed_distance(frame.world(ring), humerus) < 0) == inside), (x, rho)


@pytest.mark.parametrize("theta", [0.0, 50.0, 100.0, 140.0])
def test_the_forearm_bones_turn_about_the_humerus_without_entering_it(arm, shapes, theta):
    bodies = [_body("humerus", shapes)]
    for name in ("ulna", "radius"):
        points, triangles = shapes[name]
        bodies.append(Body(name, arm.forearm_point(points, theta), triangles))
    deepest = max((r["deepest_mm"] for r in overlaps(bodies)), default=0.0)
    assert deepest < 0.5, overlaps(bodies)


def test_a_model_file_sets_the_shape_and_keeps_its_defaults(tmp_path):
    from persival.model.anatomy.schema_base import ModelFileError
    from persival.model.arm.defaults import default_model_path
    from persival.model.arm.model_file import load_model_file

    text = default_model_path().read_text()
    marker = 'radius = 10.0\n'
    assert text.count(marker) == 1
    custom = tmp_path / "arm.toml"
    custom.write_text(text.replace(marker, marker + '[bones.shape]\nkind = "humerus"\nepicondylar_width = 56.0\n'))
    spec, _ = load_model_file(custom)
    assert spec.bone("humerus").drawn_shape().epicondylar_width == 56.0
    assert spec.bone("humerus").drawn_shape().trochlea_width == 22.0
    assert load_model_file()[0].bone("ulna").drawn_shape().kind == "ulna"  # by name, without a table
    custom.write_text(text.replace(marker, marker + '[bones.shape]\nkind = "femur"\n'))
    with pytest.raises(ModelFileError, match=r"bones\[humerus\]\.shape"):
        load_model_file(custom)


@pytest.mark.parametrize("theta", [0.0, 90.0])
def test_the_viewer_skeleton_draws_the_shaped_bones_where_the_fe_states_write_them(arm, theta):
    """The export's skeleton (docs/deployment.md) holds the shaped surfaces at 0 deg; turned by
    its own hinge formula they land on the bones the FE states are written with (output.py)."""
    from persival.campaign.skeleton import skeleton_for
    from persival.model.arm.output import bone_surfaces
    from persival.model.fe.rotations import rotation_about

    skeleton = skeleton_for("arm", {})
    centre, axis = np.array(skeleton["hinge"]["centre"]), np.array(skeleton["hinge"]["axis"])
    written = bone_surfaces(arm, theta)
    assert [b["name"] for b in skeleton["bones"]] == list(written)
    for bone in skeleton["bones"]:
        points, triangles = np.array(bone["points"]), np.array(bone["triangles"])
        if bone["segment"] == "forearm":
            points = centre + (points - centre) @ rotation_about(axis, theta).T
        assert np.array_equal(triangles, written[bone["name"]][1]), bone["name"]
        assert np.abs(points - written[bone["name"]][0]).max() < 0.01, bone["name"]
    humerus = np.array(skeleton["bones"][0]["points"])
    # the epicondyles: the distal humerus is far wider than its shaft (a tube would be 20 mm)
    assert np.ptp(humerus[humerus[:, 2] < 20.0, 0]) > 50.0
