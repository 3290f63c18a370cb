"""Vertex and edge blocks of K scaled apart (conformance.diagnosis.node_blocks): the mistaken
engines store K per vertex and per edge, the way SOFA-style force fields do, with the slip in
their loops; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.node_blocks import fit_node_blocks, node_block_findings
from conformance.judge.compare import DOUBLE


def _case(material="Demiray", seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T + 0.02 * rng.standard_normal(points.shape)
    return mjed_split(default_material(material), points, cells, x)


def _vertex_edge_storage(split, both_orientations=False, vertex_loops=1):
    """K from per-vertex and per-edge 3x3 blocks summed over the cells; each cell's pairs
    visited as a < b (right) or in both orientations, each adding K_ab to edge (min, max) in
    its own orientation; the vertex loop run ``vertex_loops`` times.
    """
    m, n = split.cells.shape[0], split.n
    Ke = split.Ke.reshape(m, 4, 3, 4, 3).transpose(0, 1, 3, 2, 4)  # (m, 4, 4, 3, 3)
    K = np.zeros((3 * n, 3 * n))
    for c in range(m):
        for a in range(4):
            i = split.cells[c, a]
            K[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += vertex_loops * Ke[c, a, a]
            for b in range(4):
                if a == b or (b < a and not both_orientations):
                    continue
                j = split.cells[c, b]
                block = Ke[c, a, b]
                K[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] += block
                K[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] += block.T
    return sp.csr_matrix(K)


def test_right_vertex_and_edge_storage_is_the_oracle_and_fits_one_and_one():
    split, f_o, K_o, s = _case()
    K = _vertex_edge_storage(split)
    assert abs(K - K_o).max() < 1e-9 * abs(K_o).max()
    fit = fit_node_blocks(K, K_o)
    assert abs(fit.alpha - 1) < 1e-12 and abs(fit.beta - 1) < 1e-12
    assert node_block_findings(K, K_o, s, DOUBLE, True) == []


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"both_orientations": True}, "edge (off-diagonal node) blocks doubled"),
        ({"vertex_loops": 2}, "vertex (diagonal node) blocks doubled"),
        ({"vertex_loops": 0}, "vertex (diagonal node) blocks left out"),
    ],
)
def test_a_loop_slip_is_named_by_the_blocks_it_scales(kw, words):
    split, f_o, K_o, s = _case("Yeoh", seed=1)
    found = node_block_findings(_vertex_edge_storage(split, **kw), K_o, s, DOUBLE, True)
    assert [f.code for f in found] == ["node-blocks"] and words in found[0].title, found


def test_a_global_factor_and_a_formula_error_are_not_node_blocks():
    split, f_o, K_o, s = _case("NeoHookean", seed=2)
    assert node_block_findings(2.0 * K_o, K_o, s, DOUBLE, True) == []
    K = K_o + 1e-3 * sp.diags(np.arange(K_o.shape[0], dtype=float))
    assert node_block_findings(K, K_o, s, DOUBLE, True) == []
