"""On a state whose cells are alike (one J), a J-only change fits a float32 scalar's rounding as
well as a volumetric mistake (conformance.diagnosis.diagnose._volumetric_findings): the fit's
list of causes it cannot tell apart takes the rounding readings only where the error is of
float32's size.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh

import mjed
from common.cases import default_material
from conformance.diagnosis.diagnose import _volumetric_findings
from conformance.judge.compare import DOUBLE, errors, scales

ROUNDING = {"single-precision-intermediate", "single-precision-part-scalar"}


def _fits(relative: float) -> set:
    """The fits_codes of the volumetric reading for an engine whose k0 is off by ``relative``
    on a homogeneous stretch.
    """
    points, cells = box_mesh(2)
    x = points @ np.diag([1.2, 0.9, 0.95]).T
    model = default_material("MooneyRivlin")
    oracle = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f_o, K_o = oracle.force_and_stiffness(x)
    engine = mjed.HyperelasticForceField(
        mjed.TetMesh(points, cells), dataclasses.replace(model, k0=model.k0 * (1 + relative))
    )
    f, K = engine.force_and_stiffness(x)
    K_o, K = sp.csr_matrix(K_o), sp.csr_matrix(K)
    s = scales(0.5, 1.0, f_o, K_o)
    e = errors(f, K, None, f_o, K_o, 0.0, s)
    full, partial = [], []
    _volumetric_findings(
        points, cells, x, f - f_o, K - K_o, s, max(e.force, e.stiffness), DOUBLE, full, partial
    )
    found = [*full, *partial]
    assert found and found[0].code == "volumetric"
    return set(found[0].figures.get("fits_codes", ()))


def test_a_float32_sized_change_on_one_j_may_be_a_rounding():
    assert ROUNDING <= _fits(3e-8)
    assert not ROUNDING & _fits(1e-2)
