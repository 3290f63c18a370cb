"""A material tangent by differences of S in the Voigt strain components
(conformance.diagnosis.strain_differences). The engine is built here: per cell, S(C) of the
project's classical law for Mooney-Rivlin, its Voigt tangent by forward differences (step h in
each strain component, engineering shear), assembled with the engineering B matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh
from diagnosis_stubs import CaseStub as _Case
from diagnosis_stubs import OutputStub as _Out
from diagnosis_stubs import classical_cells

from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.strain_differences import strain_difference_reading
from conformance.judge.compare import errors, scales
from conformance.judge.oracle import Reference

VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))


def _engine(points, cells, x, model, h: float, central: bool):
    """(f, K, f_o, K_o): MJED's force and stiffness, and K with the differenced Voigt tangent."""
    import mjed
    from mjed.mesh import shape_vectors
    from reference_fem.classical import ClassicalGalerkin

    law = ClassicalGalerkin(points, cells, model).law
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f_o, K_o = field.force_and_stiffness(x)
    V0, D = shape_vectors(points, cells)
    V0 = np.abs(V0)
    F = np.einsum("mai,maj->mij", x[cells], D)
    C = F.swapaxes(1, 2) @ F

    def S_of(Cs):
        return law.stress(Cs, np.sqrt(np.linalg.det(Cs)))

    S = S_of(C)
    Dv = np.empty((len(cells), 6, 6))
    for B, (k, ll) in enumerate(VOIGT):
        dC = np.zeros((3, 3))
        dC[k, ll] += h
        dC[ll, k] += h
        up = S_of(C + dC)
        diff = (up - S_of(C - dC)) / (2 * h) if central else (up - S) / h
        Dv[:, :, B] = diff[:, [p[0] for p in VOIGT], [p[1] for p in VOIGT]]
    Bm = np.empty((len(cells), 6, 4, 3))
    for A, (i, j) in enumerate(VOIGT):
        Bm[:, A] = np.einsum("ma,mk->mak", D[:, :, j], F[:, :, i])
        if i != j:
            Bm[:, A] += np.einsum("ma,mk->mak", D[:, :, i], F[:, :, j])
    Bm = Bm.reshape(-1, 6, 12)
    geo = np.einsum("mab,kl->makbl", np.einsum("mai,mij,mbj->mab", D, S, D), np.eye(3))
    Ke = V0[:, None, None] * (np.einsum("mAi,mAB,mBj->mij", Bm, Dv, Bm) + geo.reshape(-1, 12, 12))
    K = assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke)[1]
    return np.asarray(f_o), K, np.asarray(f_o), sp.csr_matrix(K_o)


def _read(h: float, central: bool, engine=None):
    """strain_difference_reading's diagnosis of ``engine`` (default: the strain scheme's)."""
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    x = points + 0.06 * np.random.default_rng(5).standard_normal(points.shape)
    model = default_material("MooneyRivlin")
    f, K, f_o, K_o = (engine or _engine)(points, cells, x, model, h, central)
    s = scales(0.5, 1.0, f_o, K_o)
    e = errors(f, K, None, f_o, K_o, 0.0, s)
    diag = Diagnosis("c", "failed", e, [Finding("unexplained", "unexplained", OBSERVED, "", {})])

    ref = Reference(0.0, f_o, K_o)
    return strain_difference_reading(diag, _Case(points, cells, x, model), _Out(f, K), ref, s)


def test_forward_differences_in_the_voigt_strain_are_named_with_their_step():
    d = _read(1e-6, central=False)
    top = d.findings[0]
    assert top.code == "strain-finite-difference", [f.title for f in d.findings]
    assert "forward differences of the stress S" in top.title
    assert abs(top.figures["step"] / 1e-6 - 1) < 1e-3


def test_central_differences_with_a_large_step_are_not_named_so():
    d = _read(1e-3, central=True)
    assert d.errors.stiffness > 1e-8  # a failing tangent, not named as forward differences
    assert d.findings[0].code == "unexplained", [f.title for f in d.findings]


def _miehe_engine(points, cells, x, model, eps: float, central: bool):
    """(f, K, f_o, K_o): MJED's force and stiffness, and K of an updated-Lagrangian engine whose
    spatial tangent is Miehe's: tau differenced under F + eps sym(e_k e_l) F, over J, less the
    Jaumann rate's terms; B from grad N = D F^-1 (engineering shear), integrals over v = J V0.
    """
    f_o, K_o, V0, D, F, J, tau_of = classical_cells(points, cells, x, model)
    tau = tau_of(F)
    sig = tau / J[:, None, None]
    I3 = np.eye(3)
    c6 = np.empty((len(cells), 6, 6))
    for col, (k, ll) in enumerate(VOIGT):
        E = np.zeros((3, 3))
        E[k, ll] += 0.5
        E[ll, k] += 0.5
        up = tau_of((I3 + eps * E) @ F)
        diff = (up - tau_of((I3 - eps * E) @ F)) / (2 * eps) if central else (up - tau) / eps
        jaumann = E @ sig + sig @ E  # the rate terms' column kl
        dc = diff / J[:, None, None] - jaumann
        c6[:, :, col] = dc[:, [p[0] for p in VOIGT], [p[1] for p in VOIGT]]
    gN = D @ np.linalg.inv(F)
    Bm = np.zeros((len(cells), 6, 4, 3))
    for A, (i, j) in enumerate(VOIGT):
        Bm[:, A, :, i] += gN[:, :, j]
        if i != j:
            Bm[:, A, :, j] += gN[:, :, i]
    Bm = Bm.reshape(-1, 6, 12)
    v = J * np.abs(V0)
    geo = np.einsum("mab,kl->makbl", np.einsum("mai,mij,mbj->mab", gN, sig, gN), I3)
    Ke = v[:, None, None] * (np.einsum("mAi,mAB,mBj->mij", Bm, c6, Bm) + geo.reshape(-1, 12, 12))
    K = assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke)[1]
    return np.asarray(f_o), K, np.asarray(f_o), sp.csr_matrix(K_o)


def _read_miehe(eps: float, central: bool):
    return _read(eps, central, _miehe_engine)


def test_miehe_forward_perturbation_is_named_with_its_step_and_not_as_strain_steps():
    d = _read_miehe(1e-4, central=False)
    codes = [f.code for f in d.findings]
    assert codes[0] == "perturbation-finite-difference", [f.title for f in d.findings]
    assert "strain-finite-difference" not in codes
    assert "forward differences of the Kirchhoff stress" in d.findings[0].title
    assert abs(d.findings[0].figures["step"] / 1e-4 - 1) < 1e-2
    # ... and the strain scheme's engine is not said to be a perturbation of F
    assert "perturbation-finite-difference" not in [f.code for f in _read(1e-6, False).findings]


def test_miehe_central_perturbation_with_a_large_step_is_not_named_forward():
    d = _read_miehe(1e-2, central=True)
    assert d.errors.stiffness > 1e-8
    assert d.findings[0].code == "unexplained", [f.title for f in d.findings]
