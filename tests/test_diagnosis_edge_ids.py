"""An edge-based engine's table of edge ids read in the other layout
(conformance.diagnosis.edge_ids): the mistaken engine builds its edge table and its blocks here,
loop by loop as such engines do, independently of the module's vectorised model; MJED stands in
for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.edge_ids import PAIRS, edge_id_findings, slipped_stiffness
from conformance.judge.compare import DOUBLE


def _case(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T
    x = x + 0.02 * np.random.default_rng(seed).standard_normal(points.shape)
    return mjed_split(default_material("Yeoh"), points, cells, x)


def _edge_engine(split, layout):
    """K of an engine with an edge table built pair-major, read as ``layout`` says."""
    cells, n = split.cells, split.n
    m = len(cells)
    edges = sorted({tuple(sorted((c[a], c[b]))) for c in cells for a, b in PAIRS})
    index = {e: i for i, e in enumerate(edges)}
    built = np.array([index[tuple(sorted((c[a], c[b])))] for a, b in PAIRS for c in cells])
    ids = built.reshape(6, m).T if layout == "right" else built.reshape(m, 6)
    Kb = split.Ke.reshape(m, 4, 3, 4, 3)
    blocks = np.zeros((len(edges), 3, 3))
    K = np.zeros((3 * n, 3 * n))
    for c in range(m):
        for p, (a, b) in enumerate(PAIRS):
            block = Kb[c, a, :, b, :]
            blocks[ids[c, p]] += block.T if cells[c, a] > cells[c, b] else block
        for a in range(4):
            i = cells[c, a]
            K[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += Kb[c, a, :, a, :]
    for (lo, hi), block in zip(edges, blocks):
        K[3 * lo : 3 * lo + 3, 3 * hi : 3 * hi + 3] += block
        K[3 * hi : 3 * hi + 3, 3 * lo : 3 * lo + 3] += block.T
    return sp.csr_matrix(K)


def test_the_right_table_is_the_oracle_and_the_model_agrees_with_the_loops():
    split, f_o, K_o, s = _case()
    assert abs(_edge_engine(split, "right") - K_o).max() < 1e-9 * abs(K_o).max()
    slipped = _edge_engine(split, "slipped")
    model = slipped_stiffness(split, "pair-major-read-as-cell-major")
    assert abs(slipped - model).max() < 1e-12 * abs(K_o).max()
    assert abs(slipped - K_o).max() > 1e-3 * abs(K_o).max()


def test_a_pair_major_table_read_cell_major_is_named_and_the_oracle_is_not():
    split, f_o, K_o, s = _case(1)
    found = edge_id_findings(split, f_o, _edge_engine(split, "slipped"), s, DOUBLE)
    assert [f.code for f in found] == ["edge-ids-pair-major-read-as-cell-major"], found
    assert edge_id_findings(split, f_o, K_o, s, DOUBLE) == []


def test_an_unknown_slip_is_refused():
    split, *_ = _case()
    with pytest.raises(ValueError, match="unknown slip"):
        slipped_stiffness(split, "sideways")
