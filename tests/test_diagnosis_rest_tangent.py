"""The tangent frozen at rest (conformance.diagnosis.rest_tangent): a Neo-Hookean engine whose
force is the law's (MJED, the oracle's stand-in) and whose stiffness uses the linear-elastic
lam I (x) I + 2 mu II at every state, assembled here spatially or in the total-Lagrangian
form; the nearby mistakes (the rest tangent scaled, the law's own tangent) are not named.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh
from diagnosis_stubs import CaseStub, MjedCache, OutputStub, cell_gradients

from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.rest_tangent import rest_tangent_reading
from conformance.judge.compare import errors, scales
from conformance.judge.oracle import Reference

EYE = np.eye(3)
IXI = np.einsum("ij,kl->ijkl", EYE, EYE)
II = 0.5 * (np.einsum("ik,jl->ijkl", EYE, EYE) + np.einsum("il,jk->ijkl", EYE, EYE))


def _engine(points, cells, x, how, scale=1.0):
    """(f, K): the law's force and a stiffness with c0 = scale (lam I (x) I + 2 mu II)."""
    model = default_material("NeoHookean")
    ref = MjedCache().reference(CaseStub(points, cells, x, model))
    c0 = scale * (model.lam * IXI + 2.0 * model.mu * II)
    V0, D, F, J = cell_gradients(points, cells, x)
    C = F.swapaxes(1, 2) @ F
    S = model.mu * (EYE - np.linalg.inv(C)) + model.lam * np.log(J)[:, None, None] * np.linalg.inv(
        C
    )
    if how == "spatial":
        g = D @ np.linalg.inv(F)
        sigma = F @ S @ F.swapaxes(1, 2) / J[:, None, None]
        Ke = np.einsum("m,maj,ijkl,mbl->maibk", J * V0, g, c0, g)
        Ke = Ke + np.einsum("m,mai,mij,mbj,kl->makbl", J * V0, g, sigma, g, EYE)
    else:
        A = np.einsum("miI,IJKL,mkK->miJkL", F, c0, F)
        Ke = np.einsum("m,maJ,miJkL,mbL->maibk", V0, D, A, D)
        Ke = Ke + np.einsum("m,maI,mIJ,mbJ,ik->maibk", V0, D, S, D, EYE)
    _, K = assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke.reshape(-1, 12, 12))
    return ref, ref.force, K


def _read(how, scale=1.0):
    points, cells = box_mesh(2, jitter=0.2, seed=6)
    x = points @ np.diag([1.1, 0.93, 0.97]).T
    x = x + 0.04 * np.random.default_rng(6).standard_normal(points.shape)
    ci = CaseStub(points, cells, x, default_material("NeoHookean"))
    ref, f, K = _engine(points, cells, x, how, scale)
    s = scales(0.5, 1.0, ref.force, ref.stiffness)
    e = errors(f, K, None, ref.force, ref.stiffness, 0.0, s)
    diag = Diagnosis("c", "failed", e, [Finding("unexplained", "unexplained", OBSERVED, "", {})])
    ref = Reference(0.0, ref.force, sp.csr_matrix(ref.stiffness))
    return rest_tangent_reading(diag, MjedCache(), ci, OutputStub(f, K), ref, s)


@pytest.mark.parametrize("how", ["spatial", "material"])
def test_the_linear_elastic_tangent_kept_at_every_state_is_named(how):
    d = _read(how)
    assert [c.code for c in d.causes] == ["rest-tangent"], d.text()
    assert d.causes[0].figures["assembly"] == how


def test_a_scaled_rest_tangent_is_not_named():
    d = _read("spatial", scale=0.9)
    assert d.causes == [], d.text()
