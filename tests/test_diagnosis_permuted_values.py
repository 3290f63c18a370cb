"""The right stiffness values at the wrong entries (conformance.diagnosis.permuted_values): the
mistaken engines write CSR arrays the way users do (indices from a summed, sorted matrix, values
from their own triplets); MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.differences import roundoff_dominated
from conformance.diagnosis.permuted_values import permuted_values
from conformance.judge.compare import DOUBLE, Tolerances

#: single-precision limits of the size the check sets for a float32 engine
SINGLE = Tolerances(1e-5, 1e-5, 1e-5, "single", "a test's")


def _case(material="MooneyRivlin", seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.array([[1.1, 0.2, 0.0], [0.0, 0.95, 0.1], [0.05, 0.0, 0.92]]).T
    x = x + 0.03 * rng.standard_normal(points.shape)
    return mjed_split(default_material(material), points, cells, x)


def _csr_with_values_from(K_o: sp.csr_matrix, values: np.ndarray) -> sp.csr_matrix:
    """K_o's own indptr and indices with ``values`` in their place."""
    return sp.csr_matrix((values, K_o.indices.copy(), K_o.indptr.copy()), shape=K_o.shape)


def test_csr_values_in_node_block_order_are_named_as_moved_across_rows():
    split, f_o, K_o, s = _case()
    K_o = sp.csr_matrix(K_o)
    K_o.sort_indices()
    # the values in the engine's 3x3 block order (block by block, each row-major), the indices
    # row-major as a sorted CSR has them
    C = K_o.tocoo()
    block_order = np.lexsort((C.col % 3, C.row % 3, C.col // 3, C.row // 3))
    K = _csr_with_values_from(K_o, C.data[block_order])
    assert abs(K - K_o).max() > 1e-3 * abs(K_o).max()
    p = permuted_values(K, K_o, DOUBLE)
    assert p is not None and not p.within_rows, p
    assert p.gap < 1e-14 and p.moved > 0.3, p


def test_each_row_reversed_is_named_as_moved_within_rows():
    split, f_o, K_o, s = _case("Yeoh", seed=1)
    K_o = sp.csr_matrix(K_o)
    K_o.sort_indices()
    values = K_o.data.copy()
    for r in range(K_o.shape[0]):
        a, b = K_o.indptr[r], K_o.indptr[r + 1]
        values[a:b] = values[a:b][::-1]
    p = permuted_values(_csr_with_values_from(K_o, values), K_o, DOUBLE)
    assert p is not None and p.within_rows, p


def test_a_formula_error_and_float32_storage_are_not_permutations():
    split, f_o, K_o, s = _case("NeoHookean", seed=2)
    K_o = sp.csr_matrix(K_o)
    # a systematic error (a tenth of K's diagonal added), and values rounded to float32
    assert permuted_values(K_o + 0.1 * sp.diags(K_o.diagonal()), K_o, DOUBLE) is None
    K32 = sp.csr_matrix(K_o.astype(np.float32), dtype=np.float64)
    assert permuted_values(K32, K_o, DOUBLE) is None
    # at single precision the float32 values are within tolerance in place: nothing moved
    assert permuted_values(K32, K_o, SINGLE) is None


def test_the_roundoff_reading_refuses_a_step_below_the_spacing_of_the_coordinates():
    """Permuted values look like noise (asymmetric, unbalanced), but the step they would imply
    is below the spacing of doubles at the nodes: no difference quotient can make them.
    """
    split, f_o, K_o, s = _case()
    K_o = sp.csr_matrix(K_o)
    K_o.sort_indices()
    rng = np.random.default_rng(3)
    K = _csr_with_values_from(K_o, rng.permutation(K_o.data))
    r = roundoff_dominated(split, K, K_o)
    assert r is not None and not r.possible_step and not r.holds, r
    assert permuted_values(K, K_o, DOUBLE) is not None
