"""The constitutive law (SPEC 3.1): stress-free reference, symmetry, objectivity, tangent."""

import numpy as np
import pytest

from persival.model.fe.material import (
    DEFAULT_PARAMETERS,
    force_length,
    second_piola_kirchhoff,
    stress_and_tangent,
)

K_BULK = 50.0


def random_rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def stretched_along_fibre(rng, n, fibre_stretch):
    """Random F whose fibre stretch sqrt(a0.C a0) equals fibre_stretch (F = R U, U = lam a0 a0 + ...)."""
    F = np.empty((n, 3, 3))
    a0 = rng.standard_normal((n, 3))
    a0 /= np.linalg.norm(a0, axis=1)[:, None]
    for i in range(n):
        G = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
        x = G @ a0[i]
        G = G * fibre_stretch / np.linalg.norm(x)  # scales all stretches: fibre gets exactly lam
        F[i] = random_rotation(rng) @ G
    return F, a0


def test_stress_free_reference_state():
    for gm in (0.0, 0.3, 1.0):
        S = second_piola_kirchhoff(np.eye(3), [0.0, 0.6, 0.8], 0.0, gm, K_BULK)
        assert np.abs(S).max() < 1e-14


def test_activation_produces_fibre_tension_at_reference():
    a0 = np.array([0.0, 0.0, 1.0])
    S = second_piola_kirchhoff(np.eye(3), a0, 1.0, 1.0, K_BULK)
    f, _ = force_length(1.0)
    # at F = I only the active term remains: S = S_max f(1) M (SPEC 3.1)
    assert S[2, 2] == pytest.approx(DEFAULT_PARAMETERS.S_max * f, rel=1e-12)
    assert np.abs(S - S[2, 2] * np.outer(a0, a0)).max() < 1e-14


def test_symmetry_and_objectivity():
    rng = np.random.default_rng(1)
    F = np.eye(3) + 0.2 * rng.standard_normal((50, 3, 3))
    a0 = rng.standard_normal((50, 3))
    a0 /= np.linalg.norm(a0, axis=1)[:, None]
    act, gm = rng.uniform(0, 1, 50), rng.uniform(0, 1, 50)
    S = second_piola_kirchhoff(F, a0, act, gm, K_BULK, fibre_prestretch=1.2)
    assert np.abs(S - np.swapaxes(S, 1, 2)).max() < 1e-12 * np.abs(S).max()
    R = np.stack([random_rotation(rng) for _ in range(50)])
    S_rot = second_piola_kirchhoff(R @ F, a0, act, gm, K_BULK, fibre_prestretch=1.2)
    assert np.abs(S_rot - S).max() < 1e-12 * np.abs(S).max()
    # a pure rotation is stress free
    S_rigid = second_piola_kirchhoff(R, a0, 0.0, gm, K_BULK)
    assert np.abs(S_rigid).max() < 1e-13


@pytest.mark.parametrize("prestretch", [1.0, 1.27])  # SPEC 3.3 fibre reference lambda_0
@pytest.mark.parametrize("fibre_stretch", [0.9, 1.2, 1.5])  # below 1, between 1 and lambda_opt, above lambda_opt
@pytest.mark.parametrize("muscle_fraction", [1.0, 0.0, 0.5])
def test_consistent_tangent_matches_finite_differences(fibre_stretch, muscle_fraction, prestretch):
    rng = np.random.default_rng(int(fibre_stretch * 10) + int(muscle_fraction * 100))
    n = 40
    F, a0 = stretched_along_fibre(rng, n, fibre_stretch)
    act = rng.uniform(0.0, 1.0, n)
    lam = np.sqrt(np.einsum("ni,nji,njk,nk->n", a0, F, F, a0))
    assert np.allclose(lam, fibre_stretch)
    S, CC = stress_and_tangent(F, a0, act, muscle_fraction, K_BULK, fibre_prestretch=prestretch)
    assert np.abs(CC - CC.transpose(0, 3, 4, 1, 2)).max() <= 1e-12 * np.abs(CC).max()  # major symmetry
    assert np.abs(CC - CC.transpose(0, 2, 1, 3, 4)).max() <= 1e-12 * np.abs(CC).max()  # minor symmetry
    h = 1e-6
    worst = 0.0
    for _ in range(4):
        dF = rng.standard_normal((n, 3, 3))
        fd = (
            second_piola_kirchhoff(F + h * dF, a0, act, muscle_fraction, K_BULK, fibre_prestretch=prestretch)
            - second_piola_kirchhoff(F - h * dF, a0, act, muscle_fraction, K_BULK, fibre_prestretch=prestretch)
        ) / (2 * h)
        dC = 0.5 * (np.swapaxes(dF, 1, 2) @ F + np.swapaxes(F, 1, 2) @ dF)  # dS = CC : dC / 2 * 2
        analytic = np.einsum("nijkl,nkl->nij", CC, dC)
        err = np.linalg.norm(fd - analytic, axis=(1, 2)) / np.linalg.norm(analytic, axis=(1, 2))
        worst = max(worst, err.max())
    assert worst < 1e-6


@pytest.mark.parametrize("prestretch", [1.0, 1.15, 1.3])
def test_prestretch_moves_the_force_length_curve_and_nothing_else(prestretch):
    """SPEC 3.3 fibre reference: in an isochoric uniaxial stretch lambda_T along the fibre of pure
    muscle, the fibre's Cauchy stress minus the isotropic part is S_max f(lambda_0 lambda_T) at
    full activation (plus the passive c3 (lambda_M^c4 - 1)): lambda_0 does not scale the force."""
    p = DEFAULT_PARAMETERS
    a0 = np.array([0.0, 0.0, 1.0])
    for lam_T in (0.8, 1.0, 1.1, 1.3 / prestretch):
        F = np.diag([lam_T**-0.5, lam_T**-0.5, lam_T])
        sigma = [F @ second_piola_kirchhoff(F, a0, act, 1.0, K_BULK, fibre_prestretch=prestretch) @ F.T for act in (0.0, 1.0)]
        active = sigma[1][2, 2] - sigma[0][2, 2]  # the isotropic and passive parts cancel
        lam_M = prestretch * lam_T
        assert active == pytest.approx(p.S_max * force_length(lam_M)[0], rel=1e-12)
        passive = p.muscle.c3 * (lam_M**p.muscle.c4 - 1.0) if lam_M >= 1.0 else 0.0
        # the isotropic part alone: a fibre reference of 0.5 keeps lambda_M below 1 (no passive term)
        iso = F @ second_piola_kirchhoff(F, a0, 0.0, 1.0, K_BULK, fibre_prestretch=0.5) @ F.T
        assert sigma[0][2, 2] - iso[2, 2] == pytest.approx(passive, rel=1e-9, abs=1e-15)


@pytest.mark.parametrize("matrix", [0.85, 1.12])  # docs/theory.md 1.7: the matrix's stress-free stretch s
@pytest.mark.parametrize("muscle_fraction", [1.0, 0.4])
def test_consistent_tangent_with_a_matrix_prestretch(matrix, muscle_fraction):
    rng = np.random.default_rng(int(matrix * 100) + int(muscle_fraction * 10))
    n = 40
    F, a0 = stretched_along_fibre(rng, n, 1.2)
    act = rng.uniform(0.0, 1.0, n)
    kw = dict(fibre_prestretch=1.1, matrix_prestretch=matrix)
    S, CC = stress_and_tangent(F, a0, act, muscle_fraction, K_BULK, **kw)
    assert np.abs(CC - CC.transpose(0, 3, 4, 1, 2)).max() <= 1e-12 * np.abs(CC).max()
    assert np.abs(CC - CC.transpose(0, 2, 1, 3, 4)).max() <= 1e-12 * np.abs(CC).max()
    assert np.abs(S - second_piola_kirchhoff(F, a0, act, muscle_fraction, K_BULK, **kw)).max() < 1e-14
    h, worst = 1e-6, 0.0
    for _ in range(4):
        dF = rng.standard_normal((n, 3, 3))
        fd = (second_piola_kirchhoff(F + h * dF, a0, act, muscle_fraction, K_BULK, **kw)
              - second_piola_kirchhoff(F - h * dF, a0, act, muscle_fraction, K_BULK, **kw)) / (2 * h)
        dC = 0.5 * (np.swapaxes(dF, 1, 2) @ F + np.swapaxes(F, 1, 2) @ dF)
        analytic = np.einsum("nijkl,nkl->nij", CC, dC)
        worst = max(worst, (np.linalg.norm(fd - analytic, axis=(1, 2)) / np.linalg.norm(analytic, axis=(1, 2))).max())
    assert worst < 1e-6


def test_the_matrix_is_stress_free_at_its_prestretch_and_objective():
    """F0 = s M + s^(-1/2) (I - M) is the muscle matrix's stress-free state: S(F0) = 0 (s < 1 keeps
    the fibre below its slack length), also rotated; the mesh pose F = I is then stretched
    (s < 1: the matrix pulls along the fibre) or squeezed (s > 1: it pushes), and pure tendon is
    not prestretched."""
    rng = np.random.default_rng(7)
    a0 = np.array([0.36, 0.48, 0.8])
    M = np.outer(a0, a0)
    for s in (0.8, 0.95):
        F0 = s * M + s**-0.5 * (np.eye(3) - M)
        assert np.abs(second_piola_kirchhoff(F0, a0, 0.0, 1.0, K_BULK, matrix_prestretch=s)).max() < 1e-13
        R = random_rotation(rng)
        assert np.abs(second_piola_kirchhoff(R @ F0, a0, 0.0, 1.0, K_BULK, matrix_prestretch=s)).max() < 1e-13
    for s, sign in ((0.9, 1.0), (1.1, -1.0)):
        S = second_piola_kirchhoff(np.eye(3), a0, 0.0, 1.0, K_BULK, matrix_prestretch=s)
        assert sign * (a0 @ S @ a0) > 1e-3  # pulls (s < 1) or pushes (s > 1) along the fibre
        tendon = second_piola_kirchhoff(np.eye(3), a0, 0.0, 0.0, K_BULK, matrix_prestretch=s)
        assert np.abs(tendon).max() < 1e-14
    with pytest.raises(ValueError, match="matrix_prestretch"):
        second_piola_kirchhoff(np.eye(3), a0, 0.0, 1.0, K_BULK, matrix_prestretch=0.0)


def test_force_length_relation_shape():
    p = DEFAULT_PARAMETERS
    f, df = force_length(np.array([p.lambda_opt, 1.0, 1.6]))
    assert f[0] == pytest.approx(1.0)
    assert df[0] == pytest.approx(0.0, abs=1e-14)
    # ascending branch at 1.0: exp(-|(1/1.35 - 1)/0.25|^3)
    assert f[1] == pytest.approx(np.exp(-abs((1 / 1.35 - 1) / 0.25) ** 3), rel=1e-12)
    assert f[2] == pytest.approx(np.exp(-abs((1.6 / 1.35 - 1) / 0.15) ** 4), rel=1e-12)
    lam = np.linspace(0.7, 1.8, 101)
    fd = (force_length(lam + 1e-7)[0] - force_length(lam - 1e-7)[0]) / 2e-7
    assert np.allclose(force_length(lam)[1], fd, atol=1e-6)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"activation": np.nan}, "activation contains NaN"),
        ({"activation": 1.5}, r"activation must lie in \[0, 1\]"),
        ({"activation": -0.1}, r"activation must lie in \[0, 1\]"),
        ({"muscle_fraction": 1.2}, "muscle_fraction"),
        ({"bulk_modulus": -1.0}, "bulk_modulus"),
        ({"a0": [1.0, 1.0, 0.0]}, "unit vector"),
        ({"F": np.eye(2)}, "shape"),
        ({"F": np.diag([1.0, 1.0, -1.0])}, "inverted"),
    ],
)
def test_bad_input_is_refused(kwargs, message):
    args = {"F": np.eye(3), "a0": [0.0, 0.0, 1.0], "activation": 0.5, "muscle_fraction": 1.0, "bulk_modulus": K_BULK}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        second_piola_kirchhoff(**args)
