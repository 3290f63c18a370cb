"""The diagnosis' pure parts, without the oracle: consistency probes, convention corrections,
localisation.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh

from conformance.diagnosis.diagnose import diagnose
from conformance.diagnosis.hypotheses import component_major_to_node_major, describe_permutation
from conformance.judge.compare import scales
from conformance.judge.consistency import PROBE_TOL, consistency


def quartic(x):
    """W = sum x^4 / 4 + sum x_i x_{i+1}: force and exact Hessian."""
    flat = x.ravel()
    f = -(flat**3 + np.roll(flat, 1) + np.roll(flat, -1))
    n = flat.size
    off = sp.diags([np.ones(n - 1), np.ones(n - 1)], [-1, 1]) + sp.csr_matrix(
        ([1.0, 1.0], ([0, n - 1], [n - 1, 0])), shape=(n, n)
    )
    K = sp.diags(3 * flat**2) + off
    W = float(np.sum(flat**4) / 4 + np.sum(flat * np.roll(flat, -1)))
    return f.reshape(x.shape), K.tocsr(), W


def test_consistency_of_an_exact_and_a_wrong_tangent():
    rng = np.random.default_rng(0)
    x = rng.uniform(0.5, 1.5, (6, 3))
    d = rng.standard_normal(x.shape) * 1e-3
    probes = [(x + d / 2**k, *[quartic(x + d / 2**k)[i] for i in (0, 2)]) for k in range(4)]
    f, K, W = quartic(x)
    good = consistency(x, f, K, W, probes)
    assert good.force_stiffness < 1e-8 and good.energy_force < 1e-8
    assert all(abs(r - 2) < 0.05 for r in good.rates_force)
    bad = consistency(x, f, 1.01 * K, W, probes)
    assert (
        bad.force_stiffness == pytest.approx(0.01 / 1.01, rel=1e-6)
        and bad.force_stiffness > PROBE_TOL
    )  # relative to K d
    assert all(abs(r - 1) < 0.1 for r in bad.rates_force)
    assert (
        consistency(x, f, K, W, probes[:1]).force_stiffness is None
    )  # one probe: not measured, said so


def test_permutation_words():
    assert "offset by +1" in describe_permutation((np.arange(10) + 1) % 10)
    assert "1-based" in describe_permutation((np.arange(10) + 1) % 10)
    assert "nodes permuted: 2 of 10 nodes moved (3->4, 4->3)" in describe_permutation(
        np.array([0, 1, 2, 4, 3, 5, 6, 7, 8, 9])
    )


def test_component_major_map():
    n = 4
    f = np.arange(12.0).reshape(n, 3)  # node-major
    written = f.T.ravel()  # what a component-major engine writes
    assert np.array_equal(written[component_major_to_node_major(n)].reshape(n, 3), f)


def _synthetic(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    n = len(points)
    rng = np.random.default_rng(seed)
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(-1, 12)
    blocks = rng.standard_normal((len(cells), 12, 12))
    blocks = blocks @ np.swapaxes(blocks, 1, 2)
    K = sp.csr_matrix(
        (blocks.ravel(), (np.repeat(dofs, 12, axis=1).ravel(), np.tile(dofs, (1, 12)).ravel())),
        shape=(3 * n, 3 * n),
    )
    return points, cells, rng.standard_normal((n, 3)), K


def _diagnose_synthetic(points, cells, f, K, f_o, K_o):
    """The diagnosis of (f, K) against (f_o, K_o) at rest positions, without energies."""
    s = scales(0.5, 0.0, f_o, K_o)
    return diagnose(
        "synthetic",
        f=f,
        K=K,
        W=None,
        f_o=f_o,
        K_o=K_o,
        W_o=0.0,
        s=s,
        points=points,
        cells=cells,
        x=points,
    )


@pytest.mark.parametrize(
    "mistake, code",
    [
        (lambda f, K, cells: (-f, K), "force-sign"),
        (lambda f, K, cells: (f, -K), "stiffness-sign"),
        (lambda f, K, cells: (f.T.reshape(-1, 3), K), "dof-order-force"),
        (lambda f, K, cells: (0.5 * f, 0.5 * K), "scale"),
    ],
)
def test_conventions_named_without_the_oracle(mistake, code):
    points, cells, f_o, K_o = _synthetic()
    f, K = mistake(f_o, K_o, cells)
    d = _diagnose_synthetic(points, cells, f, K, f_o, K_o)
    assert d.verdict == "failed" and d.causes and d.causes[0].code == code, d.text()


def test_localised_error_lists_the_cell():
    points, cells, f_o, K_o = _synthetic(1)
    f = f_o.copy()
    f[cells[7]] += 1e-3
    d = _diagnose_synthetic(points, cells, f, K_o, f_o, K_o)
    (cause,) = d.causes
    assert (
        cause.code == "localised"
        and 7 in cause.figures["cells"]
        and len(cause.figures["nodes"]) == 4
    )
    assert d.node_error[cells[7]].min() > 0 and np.count_nonzero(d.node_error) == 4


def test_nothing_claimed_for_noise():
    points, cells, f_o, K_o = _synthetic(2)
    f = f_o + np.random.default_rng(9).standard_normal(f_o.shape) * 1e-3
    d = _diagnose_synthetic(points, cells, f, K_o, f_o, K_o)
    assert not d.causes and d.findings[0].code == "unexplained"
