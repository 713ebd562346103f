"""Finite-element verification (SPEC 3.2): patch test, uniaxial stretch, Newton, physics."""

import numpy as np
import pytest
from scipy.optimize import brentq

from persival.model.fe.assembly import MaterialField
from persival.model.fe.constraints import Dirichlet, Hinge
from persival.model.fe.geometry import box_mesh, spindle, spindle_material
from persival.model.fe.material import DEFAULT_PARAMETERS, force_length
from persival.model.fe.mesh import MeshError, Tet10Mesh
from persival.model.fe.solver import ConvergenceError, InvertedStartError, QuasiStaticSolver

X_FIBRE = np.array([1.0, 0.0, 0.0])


def uniform_material(mesh, muscle_fraction=1.0, bulk_modulus=50.0, fibre=X_FIBRE, prestretch=1.0):
    return MaterialField.from_cells(4, fibre, muscle_fraction, bulk_modulus, prestretch, n_cells=mesh.n_cells)


def distorted_box(rng, curved, n=(2, 2, 2), amplitude=0.12):
    """A box with its interior nodes moved at random: straight edges (corners moved, mid-side
    nodes at the edge midpoints) or curved edges (every interior node moved independently)."""
    mesh = box_mesh(n)
    interior = np.ones(mesh.n_nodes, dtype=bool)
    for nodes in mesh.node_sets.values():
        interior[nodes] = False
    spacing = 0.5 / max(n)
    mesh.points[interior] += amplitude * spacing * rng.uniform(-1, 1, (interior.sum(), 3))
    if not curved:
        mid = 0.5 * (mesh.points[mesh.cells[:, [0, 1, 0, 0, 1, 2]]] + mesh.points[mesh.cells[:, [1, 2, 2, 3, 3, 3]]])
        mesh.points[mesh.cells[:, 4:].ravel()] = mid.reshape(-1, 3)
    mesh.check()
    return mesh, interior


@pytest.mark.parametrize("curved, quadrature_order", [(False, 2), (True, 4)])
def test_patch_test_reproduces_affine_displacement(curved, quadrature_order):
    """Straight-edged distorted tet10 pass with the 4-point rule; curved ones need a rule exact
    for the cubic integrand cof(J) dN/dxi (the 11-point rule)."""
    rng = np.random.default_rng(3)
    mesh, interior = distorted_box(rng, curved)
    A = np.array([[0.08, 0.02, -0.03], [0.01, -0.05, 0.02], [0.04, 0.0, 0.06]])
    b = np.array([0.01, -0.02, 0.005])
    exact = mesh.points @ A.T + b
    boundary = np.flatnonzero(~interior)
    n_q = 4 if quadrature_order == 2 else 11
    solver = QuasiStaticSolver(
        mesh,
        MaterialField.from_cells(n_q, [0.6, 0.8, 0.0], 0.7, 50.0, n_cells=mesh.n_cells),
        [Dirichlet("boundary", boundary, end=exact[boundary])],
        quadrature_order=quadrature_order,
    )
    solution = solver.solve(0.4)
    err = np.abs(solution.displacement - exact).max()
    print(f"patch test (curved={curved}): max interior error {err:.2e} mm over {interior.sum()} interior nodes")
    assert err < 1e-10


def analytic_uniaxial_force(stretch, activation, muscle_fraction, bulk_modulus, prestretch=1.0):
    """Nominal stress P11 of the law under uniaxial fibre stretch, lateral stress zero.

    Independent scalar implementation of SPEC 3.1 for F = diag(lam, mu, mu), C = diag(lam^2, mu^2, mu^2),
    with the SPEC 3.3 fibre reference: the muscle's curves see lambda_M = lambda_0 lam, the 1/lam^2 does not.
    """
    p = DEFAULT_PARAMETERS
    c1 = muscle_fraction * p.muscle.c1 + (1 - muscle_fraction) * p.tendon.c1
    c2 = muscle_fraction * p.muscle.c2 + (1 - muscle_fraction) * p.tendon.c2

    def stresses(mu):
        lam = stretch
        I1 = lam**2 + 2 * mu**2
        I2 = 2 * lam**2 * mu**2 + mu**4
        J = lam * mu**2
        I3 = J**2
        B1 = 2 * c1 * I3 ** (-1 / 3) + 2 * c2 * I3 ** (-2 / 3) * I1
        B2 = -2 * c2 * I3 ** (-2 / 3)
        B3 = -2 / 3 * c1 * I3 ** (-1 / 3) * I1 - 4 / 3 * c2 * I3 ** (-2 / 3) * I2 + bulk_modulus * (J - 1) * J
        lam_m = prestretch * lam
        passive = p.muscle.c3 * (lam_m**p.muscle.c4 - 1) / lam**2 if lam_m >= 1 else 0.0
        phi_m = passive + activation * p.S_max * force_length(lam_m)[0] / lam**2
        phi_t = p.tendon.c3 * (lam**p.tendon.c4 - 1) / lam**2 if lam >= 1 else 0.0
        phi = muscle_fraction * phi_m + (1 - muscle_fraction) * phi_t
        S11 = B1 + B2 * lam**2 + B3 / lam**2 + phi
        S22 = B1 + B2 * mu**2 + B3 / mu**2
        return S11, S22

    mu = brentq(lambda m: stresses(m)[1], 0.5, 1.5, xtol=1e-15)
    return stretch * stresses(mu)[0]  # P11 = F11 S11


@pytest.mark.parametrize(
    "stretch, activation, muscle_fraction, prestretch",
    # the prestretched cases go through the assembled element kernel (numba-cached apart from the
    # law's module, persival.model.fe.kernel_cache): they fail if it ran a stale law
    [(1.2, 0.0, 1.0, 1.0), (1.25, 1.0, 1.0, 1.0), (0.9, 1.0, 1.0, 1.0), (1.04, 0.0, 0.0, 1.0), (1.1, 0.5, 0.5, 1.0),
     (1.0, 1.0, 1.0, 1.27), (0.85, 1.0, 1.0, 1.27), (1.1, 0.0, 1.0, 1.3)],
)
def test_uniaxial_fibre_stretch_matches_analytic_stress(stretch, activation, muscle_fraction, prestretch):
    mesh = box_mesh((2, 2, 2), (10.0, 10.0, 10.0))
    k = 200.0 if muscle_fraction > 0 else 2000.0
    sets = mesh.node_sets
    constraints = [
        Dirichlet("x0", sets["x0"], components=(True, False, False)),
        Dirichlet("y0", sets["y0"], components=(False, True, False)),
        Dirichlet("z0", sets["z0"], components=(False, False, True)),
        Dirichlet("x1", sets["x1"], end=[10.0 * (stretch - 1.0), 0, 0], components=(True, False, False)),
    ]
    solver = QuasiStaticSolver(mesh, uniform_material(mesh, muscle_fraction, k, prestretch=prestretch), constraints)
    solution = solver.solve(activation)
    force = solution.reactions["x1"].force[0]
    expected = analytic_uniaxial_force(stretch, activation, muscle_fraction, k, prestretch) * 100.0  # 10 x 10 mm face
    print(f"uniaxial lam={stretch} alpha={activation} gM={muscle_fraction}: FE {force:.6f} N, analytic {expected:.6f} N")
    assert force == pytest.approx(expected, rel=1e-2)
    assert solution.max_volume_change < 0.01  # nearly incompressible


@pytest.mark.parametrize("matrix", [0.95, 1.05])
def test_a_free_block_relaxes_to_its_matrix_prestretch(matrix):
    """docs/theory.md 1.7: on rollers only, a muscle block whose matrix is stress free at F0 = s M +
    s^(-1/2) (I - M) (fibre along x) takes that shape: 10 s mm long, 10 s^(-1/2) mm wide. The
    passive fibre (lambda_0 = 0.9 keeps it slack) and the tendon-free block leave the matrix alone."""
    mesh = box_mesh((2, 2, 2), (10.0, 10.0, 10.0))
    sets = mesh.node_sets
    rollers = [Dirichlet(name, sets[name], components=tuple(i == axis for i in range(3)))
               for axis, name in enumerate(("x0", "y0", "z0"))]
    material = MaterialField.from_cells(4, X_FIBRE, 1.0, 200.0, 0.9, n_cells=mesh.n_cells, matrix_prestretch=matrix)
    solution = QuasiStaticSolver(mesh, material, rollers).solve(0.0)
    u = solution.displacement.reshape(-1, 3)
    np.testing.assert_allclose(u[sets["x1"], 0], 10.0 * (matrix - 1.0), atol=1e-6)
    np.testing.assert_allclose(u[sets["y1"], 1], 10.0 * (matrix**-0.5 - 1.0), atol=1e-6)
    np.testing.assert_allclose(u[sets["z1"], 2], 10.0 * (matrix**-0.5 - 1.0), atol=1e-6)
    assert solution.max_volume_change < 1e-8


@pytest.fixture(scope="module")
def small_spindle():
    return spindle(length=80.0, belly_radius=8.0, tendon_radius=3.0, mesh_size=6.0, stations=15)


def test_newton_converges_quadratically(small_spindle, capsys):
    mesh = small_spindle
    solver = QuasiStaticSolver(
        mesh, spindle_material(mesh),
        [Dirichlet("origin", mesh.node_sets["origin"]), Dirichlet("insertion", mesh.node_sets["insertion"])]
    )
    solution = solver.solve(0.5)
    history = solution.statistics.residual_histories[-1]
    with capsys.disabled():
        print("\nNewton residual history (last load step):", " ".join(f"{r:.2e}" for r in history))
    r = np.array(history) / history[0]
    # once the residual is small, each iteration roughly squares it: r_{k+1} <= C r_k^2
    # (a linearly converging method gives b ~ c a, which breaks this bound once a < 1e-3)
    pairs = [(a, b) for a, b in zip(r[:-1], r[1:]) if a < 1e-3 and b > 1e-13]
    assert pairs, "no iteration in the asymptotic range"
    for a, b in pairs:
        assert b <= 200.0 * a * a
    # equilibrium: the two end reactions cancel
    total = solution.reactions["origin"].force + solution.reactions["insertion"].force
    assert np.linalg.norm(total) < 1e-6 * np.linalg.norm(solution.reactions["origin"].force)


def test_activated_spindle_shortens_belly_fibres_and_bulges(small_spindle):
    mesh = small_spindle
    solver = QuasiStaticSolver(
        mesh, spindle_material(mesh),
        [Dirichlet("origin", mesh.node_sets["origin"]), Dirichlet("insertion", mesh.node_sets["insertion"])]
    )
    solution = solver.solve(1.0)
    u = solution.displacement.ravel()
    F = solver.assembler.deformation_gradient(u)
    fibre = solver.material.fibre
    stretch = np.sqrt(np.einsum("mqi,mqji,mqjk,mqk->mq", fibre, F, F, fibre))
    s = mesh.cell_data["arclength"]
    belly = np.abs(s - 0.5) < 0.15
    tendon = np.minimum(s, 1 - s) < 0.08
    # isometric contraction: the belly shortens, the tendons are stretched
    assert stretch[belly].mean() < 0.97
    assert stretch[tendon].mean() > 1.0
    # the belly's cross-section grows: surface nodes near mid-length move outward
    surface = mesh.surface_nodes()
    X = mesh.points[surface]
    mid = np.abs(X[:, 2] - 40.0) < 4.0
    r0 = np.linalg.norm(X[mid, :2], axis=1)
    r1 = np.linalg.norm((X + solution.displacement[surface])[mid, :2], axis=1)
    area_ratio = (r1.mean() / r0.mean()) ** 2
    print(f"belly fibre stretch {stretch[belly].mean():.3f}, mid cross-section area x{area_ratio:.3f}, "
          f"max|J-1| {solution.max_volume_change:.2e}")
    assert area_ratio > 1.02
    assert solution.max_volume_change < 0.01


def test_tip_displacement_converges_under_mesh_refinement(capsys):
    tips, sizes = [], [8.0, 5.6, 4.0]
    for h in sizes:
        mesh = spindle(length=60.0, belly_radius=8.0, tendon_radius=4.0, mesh_size=h, stations=13)
        solver = QuasiStaticSolver(mesh, spindle_material(mesh), [Dirichlet("origin", mesh.node_sets["origin"])])
        solution = solver.solve(0.3)
        tip = solution.displacement[mesh.node_sets["insertion"], 2].mean()
        tips.append(tip)
    d1, d2 = abs(tips[0] - tips[1]), abs(tips[1] - tips[2])
    rate = np.log(d1 / d2) / np.log(sizes[0] / sizes[1])
    with capsys.disabled():
        print(f"\nmesh convergence: tip displacement {[f'{t:.5f}' for t in tips]} mm at h = {sizes} mm; observed rate {rate:.2f}")
    assert tips[0] < 0  # the activated muscle shortens
    assert d2 < d1
    assert abs(tips[2] - tips[1]) < 0.02 * abs(tips[2])


def test_prescribed_hinge_rotation_is_reproduced_without_stress():
    mesh = box_mesh((1, 1, 2), (10.0, 10.0, 20.0))
    ends = np.concatenate([mesh.node_sets["z0"], mesh.node_sets["z1"]])
    tie = Hinge("all", ends, centre=[0, 0, 0], axis=[1, 0, 0], start_deg=0.0, end_deg=30.0)
    solver = QuasiStaticSolver(mesh, uniform_material(mesh), [tie])
    solution = solver.solve(0.0)
    # the free interior follows the rigid rotation and the body is stress free
    R = np.array([[1, 0, 0], [0, np.cos(np.pi / 6), -np.sin(np.pi / 6)], [0, np.sin(np.pi / 6), np.cos(np.pi / 6)]])
    expected = mesh.points @ R.T - mesh.points
    assert np.abs(solution.displacement - expected).max() < 1e-9
    assert np.linalg.norm(solution.reactions["all"].force) < 1e-7  # N; element forces are O(10 N)


def test_inverted_and_degenerate_meshes_are_refused():
    mesh = box_mesh((1, 1, 1))
    cells = mesh.cells.copy()
    cells[0] = cells[0][[0, 2, 1, 3, 6, 5, 4, 7, 9, 8]]  # mirror one element
    with pytest.raises(MeshError, match="inverted"):
        Tet10Mesh(mesh.points, cells).check()
    flat = mesh.points.copy()
    flat[mesh.cells[0, 3]] = flat[mesh.cells[0, :3]].mean(axis=0)  # corner 3 into the opposite face
    with pytest.raises(MeshError):
        Tet10Mesh(flat, mesh.cells).check()
    with pytest.raises(MeshError, match="10 nodes"):
        Tet10Mesh(mesh.points, mesh.cells[:, :4])
    with pytest.raises(MeshError, match="do not exist"):
        Tet10Mesh(mesh.points, mesh.cells + mesh.n_nodes)


def test_an_inverted_start_is_refused_with_its_element_count():
    """Not a balanced start, nor a run of load-step halvings ending in "load step fell below"."""
    mesh = box_mesh((1, 1, 2), (10.0, 10.0, 20.0))
    steps = []
    solver = QuasiStaticSolver(mesh, uniform_material(mesh), [Dirichlet("z0", mesh.node_sets["z0"])])
    mirrored = np.zeros((mesh.n_nodes, 3))
    mirrored[:, 0] = -2.0 * mesh.points[:, 0]  # x -> -x: det F = -1 in every element
    with pytest.raises(InvertedStartError, match=f"the start has {mesh.n_cells} inverted element") as caught:
        solver.solve(0.0, initial_displacement=mirrored, progress=steps.append)
    assert isinstance(caught.value, ConvergenceError) and caught.value.n_inverted == mesh.n_cells and not steps
    # a free hinge posed at its start angle: the top face turned over folds the elements under it
    hinge = Hinge("top", mesh.node_sets["z1"], centre=[0, 5, 20], axis=[1, 0, 0], free=True)
    solver = QuasiStaticSolver(mesh, uniform_material(mesh), [Dirichlet("z0", mesh.node_sets["z0"]), hinge])
    assert solver.solve(0.0).hinge_angle_deg == pytest.approx(0.0, abs=1e-9)  # upright: balanced as it is
    with pytest.raises(InvertedStartError, match=r"posed at the hinge angle 180.00 deg has \d+ inverted element"):
        solver.solve(0.0, initial_angle=180.0, progress=steps.append)
    assert not steps


def test_bad_activation_is_refused():
    mesh = box_mesh((1, 1, 1))
    solver = QuasiStaticSolver(mesh, uniform_material(mesh), [Dirichlet("x0", mesh.node_sets["x0"])])
    with pytest.raises(ValueError, match="NaN"):
        solver.solve(np.nan)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        solver.solve(1.5)
    with pytest.raises(ValueError, match="one value per cell"):
        solver.solve(np.zeros(mesh.n_cells + 1))
