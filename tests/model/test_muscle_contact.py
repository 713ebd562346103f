"""Muscle-muscle contact (docs/theory.md, 3.5): the exact tangent, Newton's
third law, and two blocks pressed into each other solved as one body."""

import numpy as np
import pytest
from contact_differences import differences

from persival.model.arm.muscle_contact import ContactBody, MutualContact, onset_slope
from persival.model.fe.assembly import MaterialField
from persival.model.fe.constraints import Dirichlet
from persival.model.fe.geometry import box_mesh
from persival.model.fe.mesh import Tet10Mesh
from persival.model.fe.solver import QuasiStaticSolver, SolverOptions


def two_blocks(overlap: float, shift=(0.3, 0.2), divisions=(2, 2, 2)):
    """Two 10 mm cubes side by side along x, the second pushed ``overlap`` mm into the first."""
    a = box_mesh(divisions, (10.0, 10.0, 10.0))
    mesh = Tet10Mesh(np.vstack([a.points, a.points + [10.0 - overlap, *shift]]), np.vstack([a.cells, a.cells + a.n_nodes]))
    return a, mesh


def test_contact_of_two_blocks_has_its_exact_tangent_and_third_law():
    cube, mesh = two_blocks(0.05, divisions=(1, 1, 1))  # few DOFs: the differences take one column each
    contact = MutualContact([(ContactBody(cube, 0), ContactBody(cube, cube.n_nodes)),
                             (ContactBody(cube, cube.n_nodes), ContactBody(cube, 0))], penalty=1.0)
    x = mesh.points + np.random.default_rng(0).normal(scale=0.005, size=mesh.points.shape)
    assert contact.energy(x) > 0
    assert 0.04 < contact.penetration(x) < 0.09
    f, _ = contact.force_and_tangent(x)
    # the bodies push each other apart with equal and opposite forces
    first, second = f.reshape(-1, 3)[: cube.n_nodes].sum(axis=0), f.reshape(-1, 3)[cube.n_nodes:].sum(axis=0)
    assert first[0] > 0.1 and second[0] < -0.1  # residuals: the first body pushed towards -x
    np.testing.assert_allclose(first + second, 0.0, atol=1e-12)
    asymmetry, tangent_error, force_error = differences(contact, x, h=1e-6)
    assert asymmetry < 1e-12 and tangent_error < 1e-5 and force_error < 1e-5
    apart = mesh.points.copy()
    apart[: cube.n_nodes, 0] -= 0.2
    assert contact.energy(apart) == 0.0 and contact.penetration(apart) == 0.0


@pytest.mark.parametrize(("push", "secant_predictor"), [(0.5, True), (1.5, False)])
def test_two_blocks_pressed_into_each_other_part_at_the_penalty_depth(push, secant_predictor):
    """Two blocks 0.01 mm apart, each clamped on its far face; the right clamp moves ``push`` mm
    towards the left. The blocks meet and both compress: the two clamps carry equal and opposite
    forces and the surfaces overlap by no more than the depth that carries the contact pressure
    (each load step predicted along the last one's secant, or from the tangent as groups do)."""
    cube, mesh = two_blocks(-0.01)
    n = cube.n_nodes
    surfaces = [ContactBody(cube, 0, exclude=cube.node_sets["x0"]), ContactBody(cube, n, exclude=cube.node_sets["x1"])]
    penalty = 1.0
    contact = MutualContact([(surfaces[0], surfaces[1]), (surfaces[1], surfaces[0])], penalty)
    material = MaterialField.from_cells(4, [0.0, 0.0, 1.0], 1.0, 50.0, n_cells=mesh.n_cells)
    clamps = [Dirichlet("left", cube.node_sets["x0"]), Dirichlet("right", cube.node_sets["x1"] + n, end=[-push, 0, 0])]
    # the force turns where a point passes from one element of the other block into the next:
    # Newton stops at the group's floor (persival.model.arm.muscle_group.MuscleGroup.contact_atol)
    options = SolverOptions(atol=1e-3, secant_predictor=secant_predictor)
    solver = QuasiStaticSolver(mesh, material, clamps, options, extra_terms=[contact])
    solution = solver.solve(0.0)
    x = mesh.points + solution.displacement
    depth = contact.penetration(x)
    left, right = solution.reactions["left"].force, solution.reactions["right"].force
    assert left[0] > 1e-3  # the clamp holds the left block against the push towards -x
    # equal and opposite up to the free nodes' residuals, which Newton leaves below atol
    np.testing.assert_allclose(left, -right, rtol=0, atol=options.atol)
    assert abs(left[0] + right[0]) < 1e-4 * abs(left[0])
    mean_pressure = abs(left[0]) / 100.0  # N/mm^2 over the 10 x 10 mm contact face
    assert 0 < onset_slope(depth) < 5 * mean_pressure / penalty
    # the contact faces met half-way: each block took half of the closing (push less the 0.01 mm
    # gap less the overlap), the right block's contact face overlapping the left one by the depth
    middle = x[cube.n_nodes:][np.isin(np.arange(n), cube.node_sets["x0"]), 0]
    closing = push - 0.01 - depth
    assert abs(np.median(middle) - (10.01 - push + closing / 2)) < 0.1 * push


def touching_arm(tmp_path):
    """A copy of the shipped variant whose biceps and brachialis touch each other."""
    from persival.model.arm.defaults import builtin_model_path

    path = tmp_path / "touching.toml"
    path.write_text((builtin_model_path().parent / "variants" / "atlas_touching.toml").read_text())
    return path


@pytest.mark.slow
def test_a_group_apart_gives_each_muscle_its_own_units_state(tmp_path):
    """Opened from the 60 deg mesh pose to 65 deg, biceps and brachialis do not touch (from 57 deg
    down they do): solved as one group in the world frame, each muscle's moment, slope, tension
    and shape are those of its own unit."""
    from persival.model.arm.arm_model import ArmModel
    from persival.tables.response_table import ResponseTable

    arm = ArmModel(touching_arm(tmp_path), profile="coarse")
    group = arm.groups["biceps"]
    assert arm.groups["brachialis"] is group and "triceps" not in arm.groups
    with pytest.raises(ValueError, match="biceps \\+ brachialis touch each other"):
        ResponseTable.create_or_open(tmp_path / "tables", arm)  # one muscle per (theta, a) cannot hold them
    assert not (tmp_path / "tables").exists()
    rest = {n: arm.units[n].rest_state() for n in group.names}
    # apart, nothing sets a floor on the group's residual: solve it as tightly as the units
    group.contact_atol = arm.options.atol
    group.options = arm.options
    grouped = group.solve(65.0, {"biceps": 0.0, "brachialis": 0.0}, rest)
    assert group.penetration(grouped) == 0.0
    for name, a in (("biceps", 0.0), ("brachialis", 0.0)):
        alone = arm.units[name].solve(65.0, a, rest[name])
        state = grouped[name]
        assert state.moment == pytest.approx(alone.moment, rel=1e-6, abs=1e-3)
        assert state.tension == pytest.approx(alone.tension, rel=1e-6, abs=1e-4)
        assert state.moment_slope == pytest.approx(alone.moment_slope, rel=1e-4, abs=1e-2)
        np.testing.assert_allclose(state.displacement, alone.displacement, atol=1e-5)


def test_a_model_file_refuses_a_muscle_in_two_groups_or_an_unknown_one(tmp_path):
    from persival.model.arm.model_file import load_model_file

    path = touching_arm(tmp_path)
    for groups, word in (('[["biceps", "brachialis"], ["biceps", "triceps"]]', "one group at most"),
                         ('[["biceps", "deltoid"]]', "known muscles"), ('[["biceps"]]', "two or more")):
        path.write_text(path.read_text().replace('touching = [["biceps", "brachialis"]]', f"touching = {groups}"))
        with pytest.raises(ValueError, match=word):
            load_model_file(path)
        path = touching_arm(tmp_path)
