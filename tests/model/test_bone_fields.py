"""A shaped bone as a contact obstacle: the sampled distance field against an exact sphere."""

import numpy as np
import pytest
import pyvista as pv

from persival.model.anatomy.bone_fields import sampled_field
from persival.model.fe.rotations import rotation_about

RADIUS = 12.0


@pytest.fixture(scope="module")
def sphere_field():
    surface = pv.Sphere(radius=RADIUS, theta_resolution=120, phi_resolution=120).triangulate()
    triangles = surface.faces.reshape(-1, 4)[:, 1:]
    return sampled_field(np.asarray(surface.points, dtype=float), triangles, "ball", spacing=1.0)


def _points_near_surface(count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return directions * rng.uniform(RADIUS - 3.0, RADIUS + 3.0, size=(count, 1))


def test_the_penetration_and_normal_are_a_spheres_within_a_tenth_of_a_millimetre(sphere_field):
    x = _points_near_surface(400)
    g, n, _ = sphere_field.project(x)
    d = np.linalg.norm(x, axis=1)
    # the triangulated sphere lies inside the exact one by at most R (1 - cos(pi/120)) = 4e-3 mm
    assert np.max(np.abs(g - (RADIUS - d))) < 0.1
    assert np.max(np.linalg.norm(n - x / d[:, None], axis=1)) < 0.02


def test_normal_and_its_gradient_are_the_exact_derivatives_of_the_penetration(sphere_field):
    x = _points_near_surface(50, seed=1)
    g, n, dn_dx = sphere_field.project(x)
    h = 1e-5
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = h
        g_plus, n_plus, _ = sphere_field.project(x + step)
        g_minus, n_minus, _ = sphere_field.project(x - step)
        np.testing.assert_allclose(-(g_plus - g_minus) / (2 * h), n[:, axis], atol=1e-6)
        np.testing.assert_allclose((n_plus - n_minus) / (2 * h), dn_dx(np.ones(len(x), bool))[:, :, axis], atol=1e-5)


def test_a_turned_and_moved_field_is_the_bone_turned_and_moved(sphere_field):
    Q = rotation_about(np.array([1.0, 0.0, 0.0]), 70.0)
    centre = np.array([0.0, 0.0, -40.0])
    moved = sphere_field.transformed(Q, centre)
    ball_centre = centre + Q @ (np.zeros(3) - centre)
    x = ball_centre + _points_near_surface(100, seed=2)
    g, n, _ = moved.project(x)
    g0, n0, _ = sphere_field.project(x - ball_centre)
    np.testing.assert_allclose(g, g0, atol=0.05)  # the grid turned: other samples, same sphere
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=0.02)
    d = x - ball_centre
    np.testing.assert_allclose(n, d / np.linalg.norm(d, axis=1, keepdims=True), atol=0.02)


def test_points_off_the_grid_are_not_in_contact(sphere_field):
    g, n, dn_dx = sphere_field.project(np.array([[0.0, 0.0, 60.0], [200.0, 0.0, 0.0]]))
    assert np.all(g < 0) and np.all(n == 0.0)


def _block_on_ball(field, ends=None, end_distance=0.0):
    """A 10 mm block whose lower face dips into the ball's top, its contact at the surface nodes."""
    from persival.model.fe.contact import ObstacleContact
    from persival.model.fe.geometry import box_mesh

    mesh = box_mesh((2, 2, 2), (10.0, 10.0, 10.0))
    x = mesh.points + [-5.0, -5.0, RADIUS - 1.5]
    contact = ObstacleContact.at_nodes(mesh, [field], 1.0, ends=ends, end_distance=end_distance)
    return contact, x


def test_contact_with_a_field_has_the_exact_tangent(sphere_field):
    from contact_differences import differences

    contact, x = _block_on_ball(sphere_field)
    assert contact.penetration(x).max() == pytest.approx(1.5, abs=0.05)
    asymmetry, tangent_error, force_error = differences(contact, x)
    assert asymmetry < 1e-12 and tangent_error < 1e-5 and force_error < 1e-5


def test_a_faded_field_scales_the_energy_by_its_share_squared(sphere_field):
    from persival.model.anatomy.obstacles import Faded

    contact, x = _block_on_ball(sphere_field)
    full = contact.energy(x)
    contact.obstacles = (Faded(sphere_field, 0.5),)
    assert contact.energy(x) == pytest.approx(0.25 * full, rel=1e-12)


def test_a_muscles_attachment_does_not_touch_the_bone_it_is_attached_to(sphere_field):
    from dataclasses import replace

    contact, x = _block_on_ball(sphere_field, ends=[[0.0, 0.0, 0.0]], end_distance=4.0)  # mesh-pose corner
    spared = contact.near_ends
    assert 0 < spared.sum() < len(spared)
    g_spared = contact.penetration(x)
    contact.obstacles = (replace(sphere_field, spares_ends=False),)
    g_all = contact.penetration(x)
    assert np.all(g_spared[spared] == 0.0) and g_all[spared].max() > 0.5
    np.testing.assert_array_equal(g_spared[~spared], g_all[~spared])


def test_a_forearm_bone_turns_with_the_elbow_by_its_shaped_surface():
    """The built-in arm's radius as a contact obstacle (bone_obstacles with its field): at 90 deg its
    shaped surface, turned about the hinge, is the field's zero level."""
    from persival.model.anatomy.bone_shapes import bone_shapes
    from persival.model.anatomy.obstacles import bone_obstacles
    from persival.model.arm.defaults import builtin_model_path
    from persival.model.arm.model_file import load_model_file

    spec, _ = load_model_file(builtin_model_path())
    points, triangles = bone_shapes(spec)["radius"]
    radius = spec.bone("radius")
    field = sampled_field(points, triangles, "radius")
    centre, axis = np.asarray(spec.joint.centre), np.asarray(spec.joint.axis)
    (turned,) = bone_obstacles([radius], centre, axis, 90.0, {"radius": field})
    surface = centre + (points[::7] - centre) @ rotation_about(axis, 90.0).T
    g, n, _ = turned.project(surface)
    print(np.quantile(np.abs(g), [0.5, 0.95, 1.0]), np.quantile(np.linalg.norm(n, axis=1), [0.05, 0.5, 0.95]))
    assert np.quantile(np.abs(g), 0.95) < 0.1 and np.abs(g).max() < 0.3
    assert np.median(np.linalg.norm(n, axis=1)) == pytest.approx(1.0, abs=0.05)


@pytest.mark.slow
def test_a_model_with_bone_surfaces_gives_its_muscles_the_shaped_bones(tmp_path):
    """`[contact] bone_surfaces = true`: the bones a muscle wraps reach it as distance fields (its
    walls stay planes), with its attachments spared; without it, as capsules."""
    from persival.model.anatomy.bone_fields import DistanceField
    from persival.model.anatomy.obstacles import Capsule
    from persival.model.arm.arm_model import ArmModel
    from persival.model.arm.body import ArmBody
    from persival.model.arm.defaults import builtin_model_path

    text = builtin_model_path().read_text()
    shaped = tmp_path / "shaped.toml"
    shaped.write_text(text.replace("[joint]", "[contact]\nbone_surfaces = true\n\n[joint]", 1))
    kinds = {}
    for path in (builtin_model_path(), shaped):
        frame = ArmBody.frame(path, "coarse")
        muscle = frame.spec.muscle("brachialis")
        obstacles = ArmModel._bones_of(frame, muscle, frame.centre_line(muscle))(30.0)
        kinds[path.name] = {type(o).__name__ for o in obstacles}
        if path == shaped:
            (humerus,) = [o for o in obstacles if isinstance(o, DistanceField)]
            assert humerus.name == "humerus" and humerus.spares_ends
            assert frame.spec.contact.attachment_mm == 10.0
    assert kinds == {"default_arm.toml": {Capsule.__name__, "Septum"}, "shaped.toml": {"DistanceField", "Septum"}}
