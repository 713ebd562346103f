"""A tendon over a wrap cylinder on the hinge axis (SPEC 3.3 muscle paths, persival.model.anatomy.wrapping)."""

import numpy as np
import pytest

from persival.model.anatomy.wrapping import WrapCylinder
from persival.model.fe.rotations import rotation_about

AXIS, CENTRE = np.array([1.0, 0.0, 0.0]), np.zeros(3)
ORIGIN, INSERTION = np.array([0.0, -22.0, 280.0]), np.array([3.0, -18.0, 16.0])  # a triceps


def geometry(cylinder, theta_deg, origin=ORIGIN, insertion=INSERTION):
    point = insertion @ rotation_about(AXIS, theta_deg).T
    rate = np.cross(AXIS, point)
    return cylinder.geometry(origin, point, rate, np.cross(AXIS, rate))


def test_a_clear_path_is_the_straight_segment_and_a_wrapped_one_has_the_radius_as_moment_arm():
    cylinder, straight = WrapCylinder(CENTRE, AXIS, 18.0, turn=1), WrapCylinder(CENTRE, AXIS, 0.0, turn=1)
    for theta in (0.0, 20.0):  # the segment passes more than 18 mm behind the hinge
        assert geometry(cylinder, theta) == pytest.approx(geometry(straight, theta), rel=1e-12)
    for theta in (100.0, 130.0, 160.0):
        L, dL, _ = geometry(cylinder, theta)
        assert geometry(straight, theta)[1] < 14.0  # the straight line loses its lever
        # tangent-arc-tangent: the arc grows by r per radian; the axial offset tilts it by planar / L
        planar = np.sqrt(L**2 - INSERTION[0] ** 2)
        assert dL == pytest.approx(18.0 * planar / L, rel=1e-12)
        assert dL > 17.99


@pytest.mark.parametrize("turn", [1, -1])
def test_length_derivatives_match_finite_differences_and_are_continuous_at_the_onset(turn):
    # a flexor wraps the other way, in front of the hinge
    insertion = INSERTION if turn == 1 else np.array([3.0, 10.0, -40.0])
    origin = ORIGIN if turn == 1 else np.array([0.0, 22.0, 280.0])
    cylinder = WrapCylinder(CENTRE, AXIS, 18.0, turn=turn)
    h = 1e-4
    thetas = np.linspace(0.0, 160.0, 321)
    lengths, rates = [], []
    for theta in thetas:
        L, dL, d2L = geometry(cylinder, theta, origin, insertion)
        plus, minus = (geometry(cylinder, theta + s * np.degrees(h), origin, insertion) for s in (1, -1))
        assert dL == pytest.approx((plus[0] - minus[0]) / (2 * h), abs=1e-6)
        if abs(plus[2] - minus[2]) < 1e-3:  # d2L jumps where the wrap begins (the path is C1 there)
            assert d2L == pytest.approx((plus[1] - minus[1]) / (2 * h), abs=1e-5)
        lengths.append(L)
        rates.append(dL)
    steps, rates = np.diff(lengths), np.array(rates)
    assert np.all(turn * steps > 0)  # monotone, and no jump where the path starts to wrap:
    assert np.max(np.abs(steps)) < 45.0 * np.radians(0.5)  # at most a 45 mm moment arm times 0.5 deg
    assert np.max(np.abs(np.diff(rates))) < 1.0  # mm/rad per 0.5 deg: dL/dtheta is continuous too
    assert np.sum(np.abs(rates - turn * 18.0) < 0.2) > 20  # and it wraps over part of the range


def test_the_first_segment_is_tangent_to_the_cylinder():
    cylinder = WrapCylinder(CENTRE, AXIS, 18.0, turn=1)
    insertion = INSERTION @ rotation_about(AXIS, 140.0).T
    e = cylinder.first_direction(ORIGIN, insertion)
    # distance of the hinge axis from the line O + s e, in the plane normal to the axis
    q = CENTRE - ORIGIN
    n = np.cross(AXIS, e)
    assert abs(q @ n) / np.linalg.norm(n) == pytest.approx(18.0, rel=1e-9)
    # and it continues the straight segment at the onset of wrapping
    clear = INSERTION @ rotation_about(AXIS, 0.0).T
    assert cylinder.first_direction(ORIGIN, clear) == pytest.approx((clear - ORIGIN) / np.linalg.norm(clear - ORIGIN))


def test_an_end_inside_the_cylinder_is_refused():
    with pytest.raises(ValueError, match="inside its wrap cylinder"):
        WrapCylinder(CENTRE, AXIS, 30.0, turn=1).geometry(ORIGIN, INSERTION, np.zeros(3), np.zeros(3))


def test_an_unwrapped_body_ends_exactly_at_the_insertion():
    """Bit for bit: the mesh pose's centre line feeds gmsh, whose loft meshes a line that differs
    in the 14th digit differently (the brachioradialis: 1754 instead of 2548 nodes)."""
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.model_file import load_model_file

    arm = ArmModel.__new__(ArmModel)  # geometry only: no meshing
    arm.spec, _ = load_model_file()
    arm.axis, arm.centre = np.array([1.0, 0.0, 0.0]), np.zeros(3)
    for name, theta in (("biceps", 60.0), ("brachialis", 60.0), ("triceps", 20.0), ("anconeus", 60.0)):
        muscle = arm.spec.muscle(name)
        assert muscle.wrap_radius > 0
        assert np.array_equal(arm.body_end(muscle, theta), arm.forearm_point(muscle.insertion, theta)), name
    # wrapped: the end lies on the first segment, L(theta) from the origin
    biceps = arm.spec.muscle("biceps")
    end = arm.body_end(biceps, 0.0)
    assert np.linalg.norm(end - np.array(biceps.origin)) == pytest.approx(arm.muscle_length(biceps, 0.0)[0])
    assert not np.allclose(end, arm.forearm_point(biceps.insertion, 0.0), atol=1.0)
