"""conformance.diagnosis.sparsity: a stiffness error on node pairs that share no cell is told as
misplaced entries (wrong indices), never as a formula's or a difference tangent's noise
(corpus 6: COO column indices tiled over the cells were read as a finite-difference step too
small).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.differences import RoundoffDifferences
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.sparsity import off_pattern_fraction, off_pattern_reading
from conformance.judge.compare import Errors
from mjed.materials import NeoHookean

MODEL = NeoHookean(mu=3448.2759, lam=31034.483)


def _case(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T + 0.04 * rng.standard_normal(points.shape)
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    return cells, sp.csr_matrix(K_o)


def _columns_tiled(K: sp.csr_matrix) -> sp.csr_matrix:
    """The COO column indices replaced by the column array tiled in another order."""
    C = sp.coo_matrix(K)
    cols = np.resize(np.sort(C.col), C.col.size)
    return sp.csr_matrix((C.data, (C.row, np.roll(cols, 7))), K.shape)


def _diagnosis(cells, K, K_o):
    unexplained = Finding("unexplained", "unexplained", OBSERVED, "", {})
    d = Diagnosis("c", "failed", Errors(0.0, 1.0, None, 0.0), [unexplained])
    ci, out, ref = (SimpleNamespace(cells=cells), SimpleNamespace(stiffness=K),
                    SimpleNamespace(stiffness=K_o))  # fmt: skip
    return off_pattern_reading(d, ci, out, ref, None)


def test_misplaced_columns_are_told_as_wrong_indices():
    cells, K_o = _case()
    K = _columns_tiled(K_o)
    assert off_pattern_fraction(cells, K - K_o) > 1e-3  # a small mesh: most pairs share a cell
    head = _diagnosis(cells, K, K_o).findings[0]
    assert head.code == "misplaced-stiffness-entries" and "indices" in head.title


def test_any_error_an_assembly_can_make_stays_on_the_pattern():
    """Nearby: an error on the mesh's pattern (every element matrix scaled, one 3x3 block
    transposed, noise on K's own entries) is not said to be misplaced.
    """
    cells, K_o = _case(1)
    rng = np.random.default_rng(2)
    noisy = K_o.copy()
    noisy.data *= 1 + 1e-8 * rng.standard_normal(noisy.data.size)
    dense = K_o.toarray()
    dense[0:3, 3:6] = dense[0:3, 3:6].T
    for K in (1.01 * K_o, noisy, sp.csr_matrix(dense)):
        assert off_pattern_fraction(cells, K - K_o) <= 1e-12
        assert _diagnosis(cells, K, K_o).findings[0].code == "unexplained"


def test_a_difference_tangents_noise_is_never_off_the_pattern():
    noise = RoundoffDifferences(0.7, 0.3, 0.0, 1.0, 1e-9, 0.0, 0.0)
    assert noise.holds
    assert not RoundoffDifferences(0.7, 0.3, 0.0, 1.0, 1e-9, 0.0, 0.5).holds
