"""An SVD engine's chain through the singular values with one invariant's piece wrong
(conformance.diagnosis.singular_value_pieces, read by hand_derived). The mistaken engines are
MJED's force and stiffness plus the change an invertible-FEM engine's mistake makes in
P = U diag(psi) V^T and Teran's SVD-basis blocks, written out here per cell and per pair for
the compressible Neo-Hookean W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2, whose
dW/dJ = (lam ln J - mu)/J.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh
from diagnosis_stubs import CaseStub as _Case
from diagnosis_stubs import MjedCache as _Cache
from diagnosis_stubs import OutputStub as _Out

from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.hand_derived import hand_derived_reading
from conformance.judge.compare import errors, scales
from conformance.judge.oracle import Reference


def _state():
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    return points, cells, points + 0.06 * np.random.default_rng(5).standard_normal(points.shape)


def _engine(points, cells, x, model, stress_psi: bool, plus_psi: bool, minus_J: float):
    """MJED's output with the volumetric part of psi_i = dPsi/dsigma_i written dW/dJ (the chain
    factor J/sigma_i dropped) in the stress (stress_psi) and in the plus quotient (plus_psi),
    and J's divided difference -sigma_k times ``minus_J`` in the minus quotient.
    """
    from mjed.mesh import shape_vectors

    r = _Cache().reference(_Case(points, cells, x, model))
    V0, D = shape_vectors(points, cells)
    V0 = np.abs(V0)
    F = np.einsum("mai,maj->mij", x[cells], D)
    U, s, Vt = np.linalg.svd(F)
    V = Vt.swapaxes(1, 2)
    J = np.prod(s, axis=1)
    WJ = (model.lam * np.log(J) - model.mu) / J
    dpsi = WJ[:, None] * (1.0 - J[:, None] / s)
    m = len(cells)
    Ah = np.zeros((m, 3, 3, 3, 3))
    for i, j, k in ((0, 1, 2), (0, 2, 1), (1, 2, 0)):
        plus = (dpsi[:, i] + dpsi[:, j]) / (s[:, i] + s[:, j]) if plus_psi else 0.0
        minus = WJ * (minus_J - 1.0) * -s[:, k]
        Ah[:, i, j, i, j] = Ah[:, j, i, j, i] = 0.5 * (minus + plus)
        Ah[:, i, j, j, i] = Ah[:, j, i, i, j] = 0.5 * (minus - plus)
    dP = np.einsum("mia,ma,mja->mij", U, dpsi, V) if stress_psi else np.zeros((m, 3, 3))
    dA = np.einsum("mka,mIb,mlc,mLd,mabcd->mkIlL", U, V, U, V, Ah)
    fe = -V0[:, None, None] * np.einsum("mkI,maI->mak", dP, D)
    Ke = (V0[:, None, None, None, None] * np.einsum("maI,mkIlL,mbL->makbl", D, dA, D)).reshape(
        m, 12, 12
    )
    df, dK = assemble(cells, points.shape[0], fe, Ke)
    return r.force + df, (sp.csr_matrix(r.stiffness) + dK).tocsr(), r.force, r.stiffness


def _read(points, cells, x, model, **mistake):
    f, K, f_o, K_o = _engine(points, cells, x, model, **mistake)
    s = scales(0.5, 1.0, f_o, K_o)
    e = errors(f, K, None, f_o, K_o, 0.0, s)
    diag = Diagnosis("c", "failed", e, [Finding("unexplained", "unexplained", OBSERVED, "", {})])
    ref = Reference(0.0, f_o, sp.csr_matrix(K_o))
    ci = _Case(points, cells, x, model)
    return hand_derived_reading(diag, _Cache(), ci, _Out(f, sp.csr_matrix(K)), ref, s)


def test_the_chain_factor_of_j_dropped_in_psi_and_its_plus_quotient_is_named():
    model = default_material("NeoHookean")
    d = _read(*_state(), model, stress_psi=True, plus_psi=True, minus_J=1.0)
    assert [f.code for f in d.causes] == ["sigma-gradient-J-dropped"], [f.title for f in d.findings]
    assert "dJ/dsigma_i = J/sigma_i dropped" in d.causes[0].title


def test_the_stress_alone_with_that_chain_factor_dropped_is_not_named_so():
    """The nearby mistake: the stress's psi wrong, the tangent right (its plus quotient from the
    right psi): not the slip carried into the blocks.
    """
    model = default_material("NeoHookean")
    d = _read(*_state(), model, stress_psi=True, plus_psi=False, minus_J=1.0)
    assert not any(f.code.startswith("sigma-") for f in d.findings), [f.title for f in d.findings]


def test_the_divided_difference_of_j_with_its_sign_flipped_is_named():
    model = default_material("NeoHookean")
    d = _read(*_state(), model, stress_psi=False, plus_psi=False, minus_J=-1.0)
    assert [f.code for f in d.causes] == ["sigma-difference-J--1"], [f.title for f in d.findings]
    assert "(psi_i - psi_j)/(sigma_i - sigma_j)" in d.causes[0].title


def test_that_divided_difference_halved_is_not_named_as_its_sign_flipped():
    model = default_material("NeoHookean")
    d = _read(*_state(), model, stress_psi=False, plus_psi=False, minus_J=0.75)
    assert not any(f.code.startswith("sigma-") for f in d.findings), [f.title for f in d.findings]
