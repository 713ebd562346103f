"""The muscle-tendon constitutive law of docs/theory.md, section 1 (Roehrle et al. 2017 as used by the paper).

Second Piola-Kirchhoff stress, for a mixture of muscle (fraction ``gamma_M``) and tendon
(``gamma_ST = 1 - gamma_M``):

    S = S_iso(c1, c2 blended) + S_vol(k) + gamma_M (S_pas^M + alpha S_act) + gamma_ST S_pas^T

and its consistent material tangent ``CC = 2 dS/dC``.

The law is written once, per material point, and compiled with numba: the same function
serves the public vectorized API below and the element kernel of the FE assembly, where a
numpy formulation spends most of its time on 4th-order temporaries (see docs/fe_core.md for
the measurements that motivated this).

One module on purpose (a numerical kernel over 300 lines): the law and its consistent tangent
are one compiled function per material point, and the vectorized API must stay beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange


@dataclass(frozen=True)
class TissueParameters:
    """c1, c2 (Mooney-Rivlin, MPa), c3 (MPa) and c4 (-) of the passive fibre term."""

    c1: float
    c2: float
    c3: float
    c4: float


# docs/theory.md, 1.8 (the paper's Table A).
MUSCLE = TissueParameters(c1=3.56e-2, c2=3.86e-3, c3=3.57e-8, c4=42.6)
TENDON = TissueParameters(c1=2.31, c2=1.15e-6, c3=7.99, c4=16.6)


@dataclass(frozen=True)
class MaterialParameters:
    """All parameters of the law except the bulk modulus (docs/theory.md, 1.8)."""

    muscle: TissueParameters = field(default_factory=lambda: MUSCLE)
    tendon: TissueParameters = field(default_factory=lambda: TENDON)
    dW_asc: float = 0.25
    dW_desc: float = 0.15
    nu_asc: float = 3.0
    nu_desc: float = 4.0
    lambda_opt: float = 1.35
    S_max: float = 0.30

    def packed(self) -> np.ndarray:
        """The parameters as the flat float64 array the compiled kernels take."""
        m, t = self.muscle, self.tendon
        return np.array(
            [m.c1, m.c2, m.c3, m.c4, t.c1, t.c2, t.c3, t.c4,
             self.dW_asc, self.dW_desc, self.nu_asc, self.nu_desc, self.lambda_opt, self.S_max],
            dtype=np.float64,
        )


DEFAULT_PARAMETERS = MaterialParameters()


# --------------------------------------------------------------------------------------------
# Compiled point law. p = MaterialParameters.packed().
# --------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _force_length_point(lam, p):
    """Active force-length f(lambda) and df/dlambda (docs/theory.md, 1.4):
    f = exp(-|(lambda/lambda_opt - 1)/dW|^nu), ascending branch for lambda <= lambda_opt."""
    lam_opt = p[12]
    if lam <= lam_opt:
        dW, nu = p[8], p[10]
    else:
        dW, nu = p[9], p[11]
    t = (lam / lam_opt - 1.0) / dW
    at = abs(t)
    f = math.exp(-(at**nu))
    sgn = 1.0 if t > 0.0 else (-1.0 if t < 0.0 else 0.0)
    df = -f * nu * at ** (nu - 1.0) * sgn / (dW * lam_opt)
    return f, df


@njit(cache=True, inline="always")
def _passive_fibre_point(lam, c3, c4):
    """phi = c3/lambda^2 (lambda^c4 - 1) for lambda >= 1, else 0 (docs/theory.md, 1.3), and dphi/dlambda."""
    if lam < 1.0:
        return 0.0, 0.0
    return c3 * (lam ** (c4 - 2.0) - lam**-2.0), c3 * ((c4 - 2.0) * lam ** (c4 - 3.0) + 2.0 * lam**-3.0)


@njit(cache=True, inline="always")
def _matrix_inverse_prestretch(a0, s, G):
    """G = F0^-1 of the matrix's stress-free configuration (docs/theory.md, 1.7): F0 = s M +
    s^(-1/2) (I - M), a volume-preserving stretch s along the fibre; G is symmetric."""
    along, across = 1.0 / s, math.sqrt(s)
    for I in range(3):
        for J in range(3):
            G[I, J] = (along - across) * a0[I] * a0[J] + (across if I == J else 0.0)


@njit(cache=True)
def _pull_back(G, S, CC, with_tangent):
    """S <- G S G and CC_IJKL <- G_Ia G_Jb G_Kc G_Ld CC_abcd (G symmetric): the matrix's stress and
    tangent, computed in its stress-free configuration, brought back to the mesh pose (1.7)."""
    T = np.empty((3, 3))
    for I in range(3):
        for b in range(3):
            T[I, b] = G[I, 0] * S[0, b] + G[I, 1] * S[1, b] + G[I, 2] * S[2, b]
    for I in range(3):
        for J in range(3):
            S[I, J] = T[I, 0] * G[0, J] + T[I, 1] * G[1, J] + T[I, 2] * G[2, J]
    if not with_tangent:
        return
    A = np.empty((3, 3, 3, 3))
    for axis in range(4):  # one index at a time: 4 x 243 products instead of 6561
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    for m in range(3):
                        acc = 0.0
                        for c in range(3):
                            if axis == 0:
                                acc += G[i, c] * CC[c, j, k, m]
                            elif axis == 1:
                                acc += G[j, c] * CC[i, c, k, m]
                            elif axis == 2:
                                acc += G[k, c] * CC[i, j, c, m]
                            else:
                                acc += G[m, c] * CC[i, j, k, c]
                        A[i, j, k, m] = acc
        CC[:] = A


@njit(cache=True)
def _add_fibre_terms(a0, phi, a_mm, S, CC, with_tangent):
    """S += phi M and CC += 2 a_mm M (x) M: the fibre terms, which see the mesh pose's C (1.6, 1.9)."""
    for I in range(3):
        for J in range(3):
            S[I, J] += phi * a0[I] * a0[J]
            if with_tangent:
                for K in range(3):
                    for L in range(3):
                        CC[I, J, K, L] += 2.0 * a_mm * a0[I] * a0[J] * a0[K] * a0[L]


@njit(cache=True)
def _law_point(F, a0, act, gm, k, pre, p, S, CC, with_tangent, mpre=1.0):
    """S (3, 3) and, if asked, CC = 2 dS/dC (3, 3, 3, 3) at one point; returns det F."""
    C = np.empty((3, 3))
    for I in range(3):
        for J in range(3):
            C[I, J] = F[0, I] * F[0, J] + F[1, I] * F[1, J] + F[2, I] * F[2, J]
    Jdet = (
        F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
        - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
        + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0])
    )
    if Jdet <= 0.0:
        return Jdet
    # docs/theory.md, 1.7: the matrix (isotropic and volumetric terms) sees C_m = G C G, G = F0^-1;
    # the muscle's share gamma_M of the stretch, so pure tendon stays stress free in the mesh pose.
    stretch = 1.0 + gm * (mpre - 1.0)
    Cf = C  # the fibre terms always see the mesh pose's C
    G = C  # only read when stretch != 1 (no allocation on the common path)
    if stretch != 1.0:
        G = np.empty((3, 3))
        _matrix_inverse_prestretch(a0, stretch, G)
        Cm = np.empty((3, 3))
        for I in range(3):
            for J in range(3):
                acc = 0.0
                for a in range(3):
                    for b in range(3):
                        acc += G[I, a] * C[a, b] * G[b, J]
                Cm[I, J] = acc
        C = Cm
    I3 = Jdet * Jdet
    I1 = C[0, 0] + C[1, 1] + C[2, 2]
    trC2 = 0.0
    for I in range(3):
        for J in range(3):
            trC2 += C[I, J] * C[J, I]
    I2 = 0.5 * (I1 * I1 - trC2)
    Ci = np.empty((3, 3))  # C^-1 = cof(C) / I3 (C symmetric)
    Ci[0, 0] = (C[1, 1] * C[2, 2] - C[1, 2] * C[2, 1]) / I3
    Ci[0, 1] = (C[0, 2] * C[2, 1] - C[0, 1] * C[2, 2]) / I3
    Ci[0, 2] = (C[0, 1] * C[1, 2] - C[0, 2] * C[1, 1]) / I3
    Ci[1, 1] = (C[0, 0] * C[2, 2] - C[0, 2] * C[2, 0]) / I3
    Ci[1, 2] = (C[0, 2] * C[1, 0] - C[0, 0] * C[1, 2]) / I3
    Ci[2, 2] = (C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]) / I3
    Ci[1, 0], Ci[2, 0], Ci[2, 1] = Ci[0, 1], Ci[0, 2], Ci[1, 2]

    # docs/theory.md, 1.5: c1, c2 of the mixture blend linearly between muscle and tendon.
    gT = 1.0 - gm
    c1 = gm * p[0] + gT * p[4]
    c2 = gm * p[1] + gT * p[5]
    p13 = I3 ** (-1.0 / 3.0)
    p23 = p13 * p13
    B1 = 2.0 * c1 * p13 + 2.0 * c2 * p23 * I1
    B2 = -2.0 * c2 * p23
    B3 = -(2.0 / 3.0) * c1 * p13 * I1 - (4.0 / 3.0) * c2 * p23 * I2
    g_vol = k * (Jdet - 1.0) * Jdet  # S_vol = k (J - 1) J C^-1

    # Fibre terms (docs/theory.md, 1.6, fibre reference). lambda_T = sqrt(a0 . C a0) is the stretch from
    # the mesh pose, lambda_M = lambda_0 lambda_T the muscle fibre's stretch from its slack
    # length. The muscle's terms are g(lambda_M) / lambda_T^2 M with g = c3 (lambda_M^c4 - 1) +
    # act S_max f(lambda_M): lambda_0 shifts the force-length and passive curves and nothing
    # else, so the fibre's Cauchy stress (J = 1) is S_max f(lambda_M) whatever the mesh pose.
    # The helpers give g(lam) / lam^2 at lam = lambda_M; times lambda_0^2 that is g / lambda_T^2.
    # The tendon's collagen is slack in the mesh pose: its passive term sees lambda_T only
    # (lambda_0 on the tendon would pre-tension it by c3 (1.2^c4 - 1) ~ 100 MPa at 1.2).
    aCa = 0.0
    for I in range(3):
        for J in range(3):
            aCa += a0[I] * Cf[I, J] * a0[J]
    lam_T = math.sqrt(aCa)
    lam = pre * lam_T
    f, df = _force_length_point(lam, p)
    phi_act = p[13] * f / (lam * lam)
    dphi_act = p[13] * (df - 2.0 * f / lam) / (lam * lam)
    phi_pm, dphi_pm = _passive_fibre_point(lam, p[2], p[3])
    phi_pt, dphi_pt = _passive_fibre_point(lam_T, p[6], p[7])
    pre2 = pre * pre
    phi = gm * pre2 * (phi_pm + act * phi_act) + gT * phi_pt
    b3v = B3 + g_vol
    # without a matrix prestretch the fibre terms go in with the matrix's, in one pass (the common,
    # hot path); with one they are added after the matrix's part is pulled back (_add_fibre_terms)
    inline = 1.0 if stretch == 1.0 else 0.0
    for I in range(3):
        for J in range(3):
            S[I, J] = B2 * C[I, J] + b3v * Ci[I, J] + inline * phi * a0[I] * a0[J]
        S[I, I] += B1
    if not with_tangent:
        if stretch != 1.0:
            _pull_back(G, S, CC, False)
            _add_fibre_terms(a0, phi, 0.0, S, CC, False)
        return Jdet

    # CC = 2 dS/dC collected by tensor structure (derivation in docs/fe_core.md):
    # 2 [ 2 c2 p23 I(x)I + a_ci (I(x)Ci + Ci(x)I) + a_cc (C(x)Ci + Ci(x)C) + a_vv Ci(x)Ci
    #     + B2 sym(I) - (B3 + g_vol) sym(Ci) + a_mm M(x)M ]
    a_ii = 2.0 * c2 * p23
    a_ci = -(2.0 / 3.0) * c1 * p13 - (4.0 / 3.0) * c2 * p23 * I1
    a_cc = (4.0 / 3.0) * c2 * p23
    a_vv = (2.0 / 9.0) * c1 * p13 * I1 + (8.0 / 9.0) * c2 * p23 * I2 + 0.5 * k * (2.0 * Jdet - 1.0) * Jdet
    # d(lambda_M)/dC = lambda_0^2 / (2 lambda_M) M, d(lambda_T)/dC = M / (2 lambda_T); the muscle
    # term carries the lambda_0^2 of phi as well
    a_mm = gm * (dphi_pm + act * dphi_act) * pre2 * pre2 / (2.0 * lam) + gT * dphi_pt / (2.0 * lam_T)
    for I in range(3):
        for J in range(3):
            dIJ = 1.0 if I == J else 0.0
            for K in range(3):
                dIK = 1.0 if I == K else 0.0
                dJK = 1.0 if J == K else 0.0
                for L in range(3):
                    dKL = 1.0 if K == L else 0.0
                    dJL = 1.0 if J == L else 0.0
                    dIL = 1.0 if I == L else 0.0
                    v = (
                        a_ii * dIJ * dKL
                        + a_ci * (dIJ * Ci[K, L] + Ci[I, J] * dKL)
                        + a_cc * (C[I, J] * Ci[K, L] + Ci[I, J] * C[K, L])
                        + a_vv * Ci[I, J] * Ci[K, L]
                        + 0.5 * B2 * (dIK * dJL + dIL * dJK)
                        - 0.5 * b3v * (Ci[I, K] * Ci[J, L] + Ci[I, L] * Ci[J, K])
                        + inline * a_mm * a0[I] * a0[J] * a0[K] * a0[L]
                    )
                    CC[I, J, K, L] = 2.0 * v
    if stretch != 1.0:
        _pull_back(G, S, CC, True)
        _add_fibre_terms(a0, phi, a_mm, S, CC, True)
    return Jdet


@njit(cache=True, parallel=True)
def _law_many(F, a0, act, gm, k, pre, mpre, p, S, CC, with_tangent):
    n = F.shape[0]
    bad = 0
    for i in prange(n):
        if _law_point(F[i], a0[i], act[i], gm[i], k[i], pre[i], p, S[i], CC[i], with_tangent, mpre[i]) <= 0.0:
            bad += 1
    return bad


# --------------------------------------------------------------------------------------------
# Public vectorized API.
# --------------------------------------------------------------------------------------------
def _prepare(F, a0, activation, muscle_fraction, bulk_modulus, fibre_prestretch, matrix_prestretch, check):
    F = np.asarray(F, dtype=float)
    a0 = np.asarray(a0, dtype=float)
    if F.shape[-2:] != (3, 3):
        raise ValueError(f"F must have shape (..., 3, 3), got {F.shape}")
    if a0.shape[-1:] != (3,):
        raise ValueError(f"a0 must have shape (..., 3), got {a0.shape}")
    lead = np.broadcast_shapes(
        F.shape[:-2], a0.shape[:-1], np.shape(activation), np.shape(muscle_fraction),
        np.shape(bulk_modulus), np.shape(fibre_prestretch), np.shape(matrix_prestretch),
    )
    scal = lambda v: np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=float), lead)).reshape(-1)  # noqa: E731
    act, gm, k, pre, mpre = (scal(v) for v in (activation, muscle_fraction, bulk_modulus, fibre_prestretch,
                                               matrix_prestretch))
    F = np.ascontiguousarray(np.broadcast_to(F, lead + (3, 3))).reshape(-1, 3, 3)
    a0 = np.ascontiguousarray(np.broadcast_to(a0, lead + (3,))).reshape(-1, 3)
    if check:
        if not np.all(np.isfinite(F)):
            raise ValueError("deformation gradient F contains NaN or inf")
        if not np.all(np.isfinite(act)):
            raise ValueError("activation contains NaN or inf")
        if np.any((act < 0.0) | (act > 1.0)):
            raise ValueError(f"activation must lie in [0, 1], got values in [{act.min()}, {act.max()}]")
        if not np.all(np.isfinite(gm)) or np.any((gm < 0.0) | (gm > 1.0)):
            raise ValueError("muscle_fraction (gamma_M) must be finite and lie in [0, 1]")
        if not np.all(np.isfinite(k)) or np.any(k <= 0.0):
            raise ValueError("bulk_modulus must be finite and positive (MPa)")
        if not np.all(np.isfinite(pre)) or np.any(pre <= 0.0):
            raise ValueError("fibre_prestretch (lambda_0) must be finite and positive")
        if not np.all(np.isfinite(mpre)) or np.any(mpre <= 0.0):
            raise ValueError("matrix_prestretch must be finite and positive")
        if not np.allclose(np.linalg.norm(a0, axis=-1), 1.0, atol=1e-8):
            raise ValueError("fibre direction a0 must be a unit vector")
    return lead, F, a0, act, gm, k, pre, mpre


def _run(F, a0, activation, muscle_fraction, bulk_modulus, fibre_prestretch, matrix_prestretch, parameters, check,
         with_tangent):
    lead, F, a0, act, gm, k, pre, mpre = _prepare(F, a0, activation, muscle_fraction, bulk_modulus, fibre_prestretch,
                                                  matrix_prestretch, check)
    n = F.shape[0]
    S = np.empty((n, 3, 3))
    CC = np.empty((n, 3, 3, 3, 3) if with_tangent else (n, 1, 1, 1, 1))
    bad = _law_many(F, a0, act, gm, k, pre, mpre, parameters.packed(), S, CC, with_tangent)
    if bad:
        raise ValueError(f"det F <= 0 at {bad} point(s): inverted material (an element turned inside out)")
    return S.reshape(lead + (3, 3)), (CC.reshape(lead + (3, 3, 3, 3)) if with_tangent else None)


def second_piola_kirchhoff(
    F,
    a0,
    activation,
    muscle_fraction,
    bulk_modulus,
    fibre_prestretch=1.0,
    parameters: MaterialParameters = DEFAULT_PARAMETERS,
    check: bool = True,
    matrix_prestretch=1.0,
) -> np.ndarray:
    """Second Piola-Kirchhoff stress S (MPa) of the muscle-tendon mixture, shape ``F.shape``.

    F: (..., 3, 3) deformation gradient; a0: (..., 3) unit fibre direction in the reference
    configuration; activation alpha in [0, 1], scalar or (...); muscle_fraction gamma_M in
    [0, 1] with gamma_ST = 1 - gamma_M; bulk_modulus k in MPa; fibre_prestretch lambda_0 (the
    muscle fibres' stretch in the mesh pose relative to their slack length, docs/theory.md, 1.6; the
    tendon term is not prestretched); matrix_prestretch s: the muscle matrix's stress-free
    configuration is the mesh pose stretched by s along the fibre, volume preserved
    (docs/theory.md, 1.7). Every other parameter comes from ``parameters`` (Table A by default).
    """
    return _run(F, a0, activation, muscle_fraction, bulk_modulus, fibre_prestretch, matrix_prestretch, parameters,
                check, False)[0]


def stress_and_tangent(
    F,
    a0,
    activation,
    muscle_fraction,
    bulk_modulus,
    fibre_prestretch=1.0,
    parameters: MaterialParameters = DEFAULT_PARAMETERS,
    check: bool = True,
    matrix_prestretch=1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """S (..., 3, 3) and the consistent material tangent CC = 2 dS/dC (..., 3, 3, 3, 3)."""
    return _run(F, a0, activation, muscle_fraction, bulk_modulus, fibre_prestretch, matrix_prestretch, parameters,
                check, True)


@njit(cache=True)
def _force_length_many(lam, p, f, df):
    for i in range(lam.shape[0]):
        f[i], df[i] = _force_length_point(lam[i], p)


def force_length(lam, parameters: MaterialParameters = DEFAULT_PARAMETERS) -> tuple[np.ndarray, np.ndarray]:
    """The active force-length relation f(lambda) and its derivative, for any array of stretches."""
    lam = np.asarray(lam, dtype=float)
    flat = np.ascontiguousarray(lam).reshape(-1)
    f, df = np.empty_like(flat), np.empty_like(flat)
    _force_length_many(flat, parameters.packed(), f, df)
    return f.reshape(lam.shape), df.reshape(lam.shape)
