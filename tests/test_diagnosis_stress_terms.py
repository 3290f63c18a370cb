"""A hand-written stress with B where C belongs (conformance.diagnosis.stress_terms). The
mistaken engine is built here: MJED's Mooney-Rivlin stress per cell, plus the c2 term's
-2 c2 J^(-4/3) (B - C) that an engine writing B for C adds, differentiated by complex step.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.stress_terms import b_for_c_findings
from conformance.judge.compare import DOUBLE, scales


def _mistaken(points, cells, x, c2):
    """(f, K, f_o, K_o): MJED's Mooney-Rivlin, and the same with S + beta (B - C)."""
    import mjed
    from mjed.mesh import shape_vectors

    model = default_material("MooneyRivlin")
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f_o, K_o = field.force_and_stiffness(x)
    V0, D = shape_vectors(points, cells)
    V0 = np.abs(V0)

    def extra(F):  # beta F (B - C), beta = -2 c2 J^(-4/3)
        Ft = F.swapaxes(1, 2)
        beta = -2.0 * c2 * np.linalg.det(F) ** (-4.0 / 3.0)
        return beta[:, None, None] * (F @ (F @ Ft - Ft @ F))

    F = np.einsum("mai,maj->mij", x[cells], D)
    dP = np.empty((len(cells), 3, 3, 3, 3))
    for k in range(3):
        for i in range(3):
            Fc = F.astype(complex)
            Fc[:, k, i] += 1e-30j
            dP[:, :, :, k, i] = extra(Fc).imag / 1e-30
    fe = -V0[:, None, None] * np.einsum("mki,mai->mak", extra(F), D)
    Ke = V0[:, None, None, None, None] * np.einsum("mai,mkilj,mbj->makbl", D, dP, D)
    df, dK = assemble(cells, points.shape[0], fe, Ke.reshape(-1, 12, 12))
    return f_o + df, sp.csr_matrix(K_o) + dK, f_o, sp.csr_matrix(K_o)


def test_b_for_c_in_the_stress_is_named_in_a_random_state():
    points, cells = box_mesh(2, jitter=0.2, seed=7)
    x = points + 0.05 * np.random.default_rng(7).standard_normal(points.shape)
    f, K, f_o, K_o = _mistaken(points, cells, x, 400.0)
    s = scales(0.5, 1.0, f_o, K_o)
    found = b_for_c_findings(points, cells, x, f - f_o, (K - K_o).tocsr(), s, DOUBLE)
    assert [f.figures["term"] for f in found] == ["C"], [f.title for f in found]
    assert "B = F F^T used for C" in found[0].title
    # an error that is not of that form: nothing
    none = b_for_c_findings(points, cells, x, f - f_o, (K_o * 1e-3).tocsr(), s, DOUBLE)
    assert none == []


def test_b_for_c_in_a_stretch_along_the_axes_is_ambiguous():
    """F diagonal with two equal stretches (a uniaxial state): B = C, and the C and C^-1 terms
    cannot be told apart (with three distinct stretches they can).
    """
    points, cells = box_mesh(2)
    x = points @ np.diag([1.2, 0.92, 0.92]).T
    f, K, f_o, K_o = _mistaken(points, cells, x, 400.0)
    s = scales(0.5, 1.0, f_o, K_o)
    found = b_for_c_findings(points, cells, x, f - f_o, (K - K_o).tocsr(), s, DOUBLE)
    assert found[0].code == "ambiguous" and len(found) == 3, [f.title for f in found]
