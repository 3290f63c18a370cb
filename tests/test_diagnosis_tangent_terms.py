"""Tangent terms of a material's own form, one unknown per cell (conformance.diagnosis.
spectral_tangent: Ogden's coaxial tangent; conformance.diagnosis.fibre_tangent: Costa's d2Q not
symmetrised). The mistaken engines are built here from MJED's stiffness and the mistaken term,
written independently of the readings (a matrix function differentiated numerically; Voigt
entries picked one by one).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh
from diagnosis_stubs import mjed_cell_stress

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.fibre_tangent import fibre_tangent_findings
from conformance.diagnosis.spectral_tangent import spectral_findings

VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))


def _state():
    points, cells = box_mesh(2, jitter=0.2, seed=11)
    x = points + 0.07 * np.random.default_rng(2).standard_normal(points.shape)
    return points, cells, x


def _kin(points, cells, x):
    from mjed.mesh import shape_vectors

    V0, D = shape_vectors(points, cells)
    return np.abs(V0), D, np.einsum("mai,maj->mij", x[cells], D)


def _oracle(points, cells, x, model):
    import mjed

    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    return sp.csr_matrix(field.force_and_stiffness(x)[1])


def _assemble_tangent(points, cells, x, dCC):
    """The assembled V0 sym(F^T grad v) : dCC : sym(F^T grad w)."""
    V0, D, F = _kin(points, cells, x)
    Ke = np.einsum("maI,mkJ,mJIML,mlM,mbL->makbl", D, F, dCC, F, D)
    Ke = (V0[:, None, None, None, None] * Ke).reshape(-1, 12, 12)
    return assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke)[1]


def _dfC(C, q, fixed):
    """D f(C)/dC (m, 3, 3, 3, 3), f(C) = q C^(q-1), by central differences along each
    symmetric direction; fixed: the eigenvectors of C held fixed (coaxial).
    """
    h = 1e-6
    lam0, N0 = np.linalg.eigh(C)
    out = np.zeros(C.shape + (3, 3))
    for r in range(3):
        for s in range(3):
            E = np.zeros((3, 3))
            E[r, s] += 0.5
            E[s, r] += 0.5
            vals = []
            for sign in (1, -1):
                lam, N = np.linalg.eigh(C + sign * h * E)
                if fixed:
                    lam = np.einsum("mpi,mpq,mqi->mi", N0, C + sign * h * E, N0)
                    N = N0
                vals.append(np.einsum("mpi,mi,mqi->mpq", N, q * lam ** (q - 1), N))
            out[:, :, :, r, s] = (vals[0] - vals[1]) / (2 * h)
    return out


def test_ogden_coaxial_tangent_is_named_and_a_scaled_tangent_is_not():
    model = default_material("Ogden")
    points, cells, x = _state()
    K_o = _oracle(points, cells, x, model)
    F = _kin(points, cells, x)[2]
    C = F.swapaxes(1, 2) @ F
    q = model.alpha / 2
    psi = model.mu / model.alpha**2 * np.linalg.det(F) ** (-model.alpha / 3)
    dCC = 4 * psi[:, None, None, None, None] * (_dfC(C, q, True) - _dfC(C, q, False))
    K = (K_o + _assemble_tangent(points, cells, x, dCC)).tocsr()
    found = spectral_findings(model, points, cells, x, K, K_o, 1e-8)
    assert [f.code for f in found] == ["tangent-coaxial"]
    assert spectral_findings(model, points, cells, x, 1.001 * K_o, K_o, 1e-8) == []
    # not an Ogden model: nothing asked
    assert spectral_findings(default_material("NeoHookean"), points, cells, x, K, K_o, 1) == []


def test_ogden_coaxial_tangent_on_a_uniaxial_stretch_is_named_with_the_stress_slope():
    """Two equal eigenvalues: the coaxial engine's eigenvectors in their plane are its
    round-off's; named with dW/dP read from the stress, and not when the dropped term is
    twice as large (a coefficient the stress does not give).
    """
    model = default_material("Ogden")
    points, cells = box_mesh(2, jitter=0.2, seed=11)
    x = points @ np.diag([1.3, 1.0, 1.0]).T
    K_o = _oracle(points, cells, x, model)
    F = _kin(points, cells, x)[2]
    C = F.swapaxes(1, 2) @ F
    q = model.alpha / 2
    psi = model.mu / model.alpha**2 * np.linalg.det(F) ** (-model.alpha / 3)
    dfC = _dfC(C, q, True) - _dfC(C, q, False)
    S = mjed_cell_stress(points, cells, x, model)
    for factor, named in ((1.0, True), (2.0, False)):
        dCC = 4 * factor * psi[:, None, None, None, None] * dfC
        K = (K_o + _assemble_tangent(points, cells, x, dCC)).tocsr()
        found = spectral_findings(model, points, cells, x, K, K_o, 1e-8, S)
        assert [f.code for f in found] == (["tangent-coaxial"] if named else [])
    # without the stress, nothing is said on such a state
    assert spectral_findings(model, points, cells, x, K, K_o, 1.0) == []


def _voigt_engine(points, cells, x, dCC_unsym):
    """The stiffness change of an engine whose Voigt tangent picks entries (p<=q, r<=s) of a
    tensor that is not minor-symmetric, contracted with the engineering B matrix.
    """
    V0, D, F = _kin(points, cells, x)
    m = len(cells)
    Dv = np.empty((m, 6, 6))
    for A, (i, j) in enumerate(VOIGT):
        for B, (k, ll) in enumerate(VOIGT):
            Dv[:, A, B] = dCC_unsym[:, i, j, k, ll]
    Bm = np.empty((m, 6, 4, 3))
    for A, (i, j) in enumerate(VOIGT):
        Bm[:, A] = np.einsum("ma,mk->mak", D[:, :, j], F[:, :, i])
        if i != j:
            Bm[:, A] += np.einsum("ma,mk->mak", D[:, :, i], F[:, :, j])
    Bm = Bm.reshape(m, 6, 12)
    Ke = V0[:, None, None] * np.einsum("mAi,mAB,mBj->mij", Bm, Dv, Bm)
    return assemble(cells, points.shape[0], np.zeros((m, 4, 3)), Ke)[1]


def test_costa_d2q_not_symmetrised_is_named_and_the_other_pair_is_not():
    model = default_material("Costa")
    points, cells, x = _state()
    K_o = _oracle(points, cells, x, model)
    B = np.array(
        [
            [model.b_ff, model.b_fs, model.b_fn],
            [model.b_fs, model.b_ss, model.b_sn],
            [model.b_fn, model.b_sn, model.b_nn],
        ]
    )
    T = 0.5 * np.einsum("ij,pi,qj,ri,sj->pqrs", B, np.eye(3), np.eye(3), np.eye(3), np.eye(3))
    c = 500.0 + 100.0 * np.random.default_rng(3).random(len(cells))
    sym = 0.5 * (T + T.swapaxes(2, 3))
    # named: T kept where sym(T) belongs; not: the whole d2Q term missing (another mistake)
    for change, named in ((T - sym, True), (-sym, False)):
        dCC = c[:, None, None, None, None] * change[None]
        K = (K_o + _voigt_engine(points, cells, x, dCC)).tocsr()
        found = fibre_tangent_findings(model, points, cells, x, K, K_o, 1e-8)
        assert [f.code for f in found] == (["tangent-fibre-unsymmetrised"] if named else [])
