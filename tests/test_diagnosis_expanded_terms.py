"""A power group expanded term by term (conformance.diagnosis.expanded_terms) and the MJED part
readings on it (conformance.diagnosis.mjed_parts); MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

import mjed
from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.expanded_terms import expanded_model
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.mjed_parts import mjed_part_findings, mjed_part_reading
from conformance.judge.compare import DOUBLE, errors
from conformance.judge.oracle import Reference
from mjed.kinematics import Kinematics


def _case(model, seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    return points, cells, x, *mjed_split(model, points, cells, x)


def test_yeohs_groups_expanded_are_the_same_energy_term_by_term():
    """c20 (u - 3)^2 + c30 (u - 3)^3 written out as J^(-2j/3) I1^j terms: the same force and
    stiffness as Yeoh's own groups; a material without power groups has nothing to expand.
    """
    model = default_material("Yeoh")
    points, cells, x, _, f_o, K_o, _ = _case(model)
    expanded = expanded_model(model)
    assert expanded is not None
    powers = sorted(t.g.n for g in expanded.decomposition() for t in g.terms if hasattr(t.g, "n"))
    assert powers == [1, 1, 1, 2, 2, 3], powers  # c10's, then the squares' and the cubes'
    f, K = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), expanded).force_and_stiffness(x)
    assert np.linalg.norm(f - f_o) <= 1e-11 * np.linalg.norm(f_o)
    assert sp.linalg.norm(sp.csr_matrix(K) - K_o) <= 1e-11 * sp.linalg.norm(sp.csr_matrix(K_o))
    assert expanded_model(default_material("MooneyRivlin")) is None


def test_cross_blocks_dropped_from_the_expanded_terms_are_named_as_such():
    """An engine of the expanded terms with every term's cross blocks f'(J) (dJ (x) F S D + its
    transpose) left out: nothing on Yeoh's own groups fits; the reading on the expanded terms
    names it, and says the expansion.
    """
    model = default_material("Yeoh")
    points, cells, x, split, f_o, K_o, s = _case(model, seed=2)
    F, D, J = split.F, split.D, np.linalg.det(split.F)
    kin = Kinematics(F)
    dJ = J[:, None, None] * np.einsum("mji,maj->mai", np.linalg.inv(F), D)
    Ke = np.zeros((len(J), 4, 3, 4, 3))
    for group in expanded_model(model).decomposition():
        for term in group.terms:
            S = term.g.stress(kin)
            if S is None:
                continue
            FSD = np.einsum("mij,mjk,mak->mai", F, np.broadcast_to(S, F.shape), D)
            f1 = np.broadcast_to(term.f(J)[1], J.shape)[:, None, None, None, None]
            Ke += (
                group.coefficient
                * f1
                * (np.einsum("mai,mbj->maibj", dJ, FSD) + np.einsum("mai,mbj->maibj", FSD, dJ))
            )
    m = len(J)
    V0 = split.V0[:, None, None, None, None]
    _, dK = assemble(split.cells, split.n, np.zeros((m, 4, 3)), (V0 * Ke).reshape(m, 12, 12))
    K = (K_o - dK).tocsr()
    case = (points, cells, x, f_o, K, f_o, K_o, s, DOUBLE)
    assert mjed_part_findings(model, *case) == []
    unexplained = [Finding("unexplained", "unexplained", OBSERVED, "", {})]
    e = errors(f_o, K, None, f_o, K_o, 0.0, s)
    diag = Diagnosis("c", "failed", e, unexplained, tolerances=DOUBLE)
    ci = type("Case", (), {"points": points, "cells": cells, "positions": x, "model": model})
    out = type("Out", (), {"force": f_o, "stiffness": K})
    read = mjed_part_reading(diag, ci, out, Reference(0.0, f_o, K_o), s)
    assert [f.code for f in read.causes] == ["mjed-part"], [f.title for f in read.findings]
    title = read.causes[0].title
    assert "cross blocks" in title and "left out" in title and "expanded" in title, title
