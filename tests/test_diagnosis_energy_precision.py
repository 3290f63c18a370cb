"""The energy alone computed in float32 (conformance.diagnosis.roundoff.energy_precision, read by
the diagnosis when force and stiffness match): the mistaken engine sums its cells' energies in
float32 here; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh

import mjed
from common.cases import default_material
from conformance.diagnosis.diagnose import diagnose
from conformance.judge.compare import scales


def _case(seed=0):
    points, cells = box_mesh(3, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.15, 0.93, 0.95]).T + 0.02 * rng.standard_normal(points.shape)
    model = default_material("Yeoh")
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f_o, K_o = field.force_and_stiffness(x)
    return points, cells, x, f_o, sp.csr_matrix(K_o), float(field.energy(x)), field


def _diagnose(points, cells, x, f_o, K_o, W_o, W):
    s = scales(0.5, 1.0, f_o, K_o)
    return diagnose(
        "c", f=f_o, K=K_o, W=W, f_o=f_o, K_o=K_o, W_o=W_o, s=s, points=points, cells=cells, x=x
    )


def test_energy_summed_in_float32_is_named():
    points, cells, x, f_o, K_o, W_o, field = _case()
    # the engine's mistake: each cell's V0 W in double, the sum accumulated in float32
    from mjed.forcefield import Want

    per_cell = np.asarray(field.evaluate(x, want=Want.ENERGY).energy, dtype=np.float64)
    assert abs(per_cell.sum() - W_o) < 1e-12 * abs(W_o)
    acc = np.float32(0.0)
    for w in per_cell:  # a float32 accumulator, as a C loop with `float sum` has it
        acc = np.float32(acc + np.float32(w))
    W = float(acc)
    d = _diagnose(points, cells, x, f_o, K_o, W_o, W)
    assert d.verdict == "failed", d
    assert d.findings[0].code == "energy-float32", d.findings[0]
    assert "single precision (float32)" in d.findings[0].title
    assert d.findings[0].strength == "explains"


def test_a_small_energy_mistake_in_double_is_not_float32():
    """An energy off by 3e-7 (a constant with seven digits) computed in double; and a float32
    number off by 1e-4 (a mistake stored in float32): neither is named float32.
    """
    points, cells, x, f_o, K_o, W_o, _ = _case(1)
    for W in (W_o * (1 + 3e-7), float(np.float32(W_o * (1 + 1e-4)))):
        d = _diagnose(points, cells, x, f_o, K_o, W_o, W)
        assert d.verdict == "failed"
        assert d.findings[0].code == "energy", d.findings[0]
