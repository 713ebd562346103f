"""The free hinge (SPEC 3.3 joint equilibrium) on a small real problem: one muscle lifting a lever.

A fusiform muscle runs from a fixed origin to a lever that rotates about the x axis; its end
faces ride on the hinge as ball joints aligned with the line of action (the arm model's
mechanism). The lever carries a weight-like moment -W sin(theta).
"""

import numpy as np
import pytest

from persival.model.fe.constraints import Hinge
from persival.model.fe.geometry import spindle_material, swept_solid_mesh
from persival.model.fe.solver import QuasiStaticSolver, SolverOptions

ORIGIN = np.array([0.0, 15.0, 120.0])
INSERTION = np.array([0.0, 8.0, -30.0])  # lever frame at theta = 0
MESH_ANGLE = 90.0
WEIGHT = 400.0  # N mm


def rotate_x(p, theta_deg):
    t = np.radians(theta_deg)
    R = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    return p @ R.T


def external(theta_rad):
    return -WEIGHT * np.sin(theta_rad), -WEIGHT * np.cos(theta_rad)


@pytest.fixture(scope="module")
def lever():
    insertion = rotate_x(INSERTION, MESH_ANGLE)
    s = np.linspace(0.0, 1.0, 13)[:, None]
    line = ORIGIN + s * (insertion - ORIGIN)
    radii = 3.0 + 6.0 * np.sqrt(np.sin(np.pi * s[:, 0]))
    mesh = swept_solid_mesh(line, radii, 6.0)
    material = spindle_material(mesh, prestretch=1.0)
    ends = np.concatenate([mesh.node_sets["origin"], mesh.node_sets["insertion"]])
    is_insertion = np.isin(ends, mesh.node_sets["insertion"])
    lines = (ORIGIN, insertion, is_insertion)
    return mesh, material, ends, lines


def make_hinge(lever, **kwargs):
    mesh, material, ends, lines = lever
    return Hinge("lever", ends, [0, 0, 0], [1, 0, 0], MESH_ANGLE, muscle_lines=lines, **kwargs)


@pytest.mark.slow
def test_free_hinge_reaches_moment_equilibrium(lever, capsys):
    mesh, material, _, _ = lever
    hinge = make_hinge(lever, start_deg=MESH_ANGLE, free=True, external_moment=external)
    solver = QuasiStaticSolver(mesh, material, [hinge], SolverOptions(moment_atol=1e-6))
    passive = solver.solve(0.0)
    active = solver.solve(0.6, initial_displacement=passive.displacement, initial_angle=passive.hinge_angle_deg)
    with capsys.disabled():
        print(f"\nlever: passive {passive.hinge_angle_deg:.3f} deg, active {active.hinge_angle_deg:.3f} deg, "
              f"moment residual {active.hinge_moment_residual:.1e} N mm")
    # the weight pulls the lever down (theta decreases); the activated muscle lifts it
    assert passive.hinge_angle_deg < MESH_ANGLE
    assert active.hinge_angle_deg > passive.hinge_angle_deg + 5.0
    assert abs(active.hinge_moment_residual) < 1e-6

    # Independent check by virtual work: with theta prescribed at theta* +- delta and the muscle
    # re-equilibrated, the muscle's moment (its end forces times their virtual velocities)
    # balances the external moment at theta*, and the net moment restores theta*.
    theta_star = active.hinge_angle_deg
    net = []
    for delta in (-0.5, 0.0, 0.5):
        fixed = make_hinge(lever, start_deg=theta_star, end_deg=theta_star + delta)
        prescribed = QuasiStaticSolver(mesh, material, [fixed])
        state = prescribed.solve(0.6, initial_displacement=active.displacement, initial_activation=0.6)
        f = prescribed.assembler.internal_force(state.displacement.ravel(), material, np.full(mesh.n_cells, 0.6)).reshape(-1, 3)
        h = 1e-4
        x_plus = fixed.positions(mesh.points, theta_star + delta + np.degrees(h))
        x_minus = fixed.positions(mesh.points, theta_star + delta - np.degrees(h))
        muscle_moment = -np.sum(f[fixed.nodes] * (x_plus - x_minus) / (2 * h))
        net.append(muscle_moment + external(np.radians(theta_star + delta))[0])
    scale = WEIGHT
    assert abs(net[1]) < 1e-4 * scale
    assert net[0] > 0 > net[2]  # stable: pushed down it lifts, pushed up it sinks

    # the joint stiffness (Schur complement of the bordered Hessian) is the slope of that
    # net moment: the derivative ArmModel's staggered joint iteration relies on
    g, stiffness = solver.hinge_balance(active.displacement, theta_star, np.full(mesh.n_cells, 0.6))
    slope = -(net[2] - net[0]) / np.radians(1.0)
    with capsys.disabled():
        print(f"joint stiffness {stiffness:.1f} N mm/rad, slope of the net moment {slope:.1f}")
    assert abs(g) < 1e-6
    assert stiffness == pytest.approx(slope, rel=0.05)
