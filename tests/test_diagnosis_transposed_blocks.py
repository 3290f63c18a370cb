"""Stiffness blocks stored untransposed (conformance.diagnosis.transposed_blocks): the mistaken
engines store K per edge here, the way users write it, not with the module's model of it; MJED
stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.differences import roundoff_dominated
from conformance.diagnosis.transposed_blocks import transposed_findings
from conformance.judge.compare import DOUBLE


def _case(material, seed=0):
    """(split, oracle force, oracle stiffness, scales) of MJED on a jittered box, deformed."""
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.array([[1.1, 0.2, 0.0], [0.0, 0.95, 0.1], [0.05, 0.0, 0.92]]).T
    x = x + 0.03 * rng.standard_normal(points.shape)
    return mjed_split(default_material(material), points, cells, x)


def _edge_storage(split, untransposed_lower=False, orientation=False):
    """K stored as node blocks and per-edge blocks (i < j), the lower block written from the
    edge block: K_ij^T (right), K_ij (``untransposed_lower``); ``orientation``: a cell's block
    added to its edge untransposed when the cell walks the edge from its larger node.
    """
    m, n = split.cells.shape[0], split.n
    Ke = split.Ke.reshape(m, 4, 3, 4, 3).transpose(0, 1, 3, 2, 4)  # (m, 4, 4, 3, 3)
    nodes = np.zeros((n, 3, 3))
    for a in range(4):
        np.add.at(nodes, split.cells[:, a], Ke[:, a, a])
    edges = {}
    for c in range(m):
        for a in range(4):
            for b in range(a + 1, 4):
                i, j = split.cells[c, a], split.cells[c, b]
                block = Ke[c, a, b]
                if i > j:
                    i, j = j, i
                    block = block if orientation else block.T
                edges[(i, j)] = edges.get((i, j), 0.0) + block
    K = np.zeros((3 * n, 3 * n))
    for i in range(n):
        K[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = nodes[i]
    for (i, j), block in edges.items():
        K[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] = block
        K[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] = block if untransposed_lower else block.T
    return sp.csr_matrix(K)


def test_right_edge_storage_is_the_oracle():
    split, f_o, K_o, s = _case("Yeoh")
    assert abs(_edge_storage(split) - K_o).max() < 1e-9 * abs(K_o).max()


def test_lower_blocks_untransposed_are_named():
    split, f_o, K_o, s = _case("Yeoh", seed=1)
    K = _edge_storage(split, untransposed_lower=True)
    found = transposed_findings(K, K_o, f_o, f_o, s, DOUBLE, split)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "storage-transposed-blocks"
    assert found[0].figures["pattern"] == "global-lower"
    assert "below the diagonal" in found[0].title and "untransposed" in found[0].title
    # ... and it is not round-off of differences: the error is confined to the lower blocks
    r = roundoff_dominated(split, K, K_o)
    assert r.exact_blocks > 0.5 and not r.holds, r


def test_edge_orientation_is_named():
    split, f_o, K_o, s = _case("NeoHookean", seed=2)
    K = _edge_storage(split, orientation=True)
    found = transposed_findings(K, K_o, f_o, f_o, s, DOUBLE, split)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures["pattern"] == "cell-against"
    assert "orientation" in found[0].title


def test_nearby_mistakes_are_not_transposed_blocks():
    """An antisymmetric perturbation of the same size, one cell's blocks scaled, a wrong force:
    no pattern of transposed blocks is named.
    """
    split, f_o, K_o, s = _case("Yeoh", seed=3)
    K_wrong = _edge_storage(split, untransposed_lower=True)
    D = (K_wrong - K_o).toarray()
    rng = np.random.default_rng(0)
    noise = rng.standard_normal(D.shape) * (D != 0)
    noise = (noise - noise.T) * np.linalg.norm(D) / np.linalg.norm(noise - noise.T)
    Ke = split.Ke.copy()
    Ke[4] *= 1.3
    from conformance.diagnosis.elements import assemble

    K_cell = assemble(split.cells, split.n, split.fe, Ke)[1]
    for K in (K_o + sp.csr_matrix(noise), K_cell):
        assert transposed_findings(K, K_o, f_o, f_o, s, DOUBLE, split) == []
    # the transposed K with a wrong force is not storage alone
    assert transposed_findings(K_wrong, K_o, 1.1 * f_o, f_o, s, DOUBLE, split) == []


def test_node_blocks_written_with_the_mirror_rule_are_named():
    """Each node block written at (i, i) and again transposed at (i, i); K doubled, or one
    node's block doubled, are not that.
    """
    split, f_o, K_o, s = _case("MooneyRivlin", seed=4)
    K = _edge_storage(split).tolil()
    for i in range(split.n):  # the engine's second write of each node block, transposed
        block = K[3 * i : 3 * i + 3, 3 * i : 3 * i + 3].toarray()
        K[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = block + block.T
    found = transposed_findings(K.tocsr(), K_o, f_o, f_o, s, DOUBLE, split)
    assert len(found) == 1 and found[0].figures["pattern"] == "node-mirror", found
    one = K_o.tolil()
    one[0:3, 0:3] = 2 * K_o[0:3, 0:3].toarray()
    for wrong in (2 * K_o, one.tocsr()):
        assert transposed_findings(wrong, K_o, f_o, f_o, s, DOUBLE, split) == []


def _triangle_storage(split, strict=False):
    """K from the element triplets with global row <= col (row < col: ``strict``) kept and
    written again with row and col exchanged: a symmetric store filled the way users do.
    """
    m = split.cells.shape[0]
    dof = (3 * split.cells[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    keep = rows < cols if strict else rows <= cols
    r, c, v = rows[keep], cols[keep], split.Ke.reshape(-1)[keep]
    n3 = 3 * split.n
    return sp.csr_matrix((np.r_[v, v], (np.r_[r, c], np.r_[c, r])), shape=(n3, n3))


def test_symmetric_storage_with_or_without_its_diagonal_is_named():
    split, f_o, K_o, s = _case("Yeoh", seed=4)
    for strict, pattern in ((False, "diagonal-doubled"), (True, "diagonal-dropped")):
        found = transposed_findings(_triangle_storage(split, strict), K_o, f_o, f_o, s, DOUBLE)
        assert [x.figures["pattern"] for x in found] == [pattern], [x.title for x in found]
        assert found[0].code == "storage-diagonal"
    assert (
        "doubled"
        in transposed_findings(_triangle_storage(split), K_o, f_o, f_o, s, DOUBLE)[0].title
    )


def test_node_blocks_doubled_or_a_diagonal_scaled_otherwise_are_not_the_diagonal():
    split, f_o, K_o, s = _case("NeoHookean", seed=5)
    blocks = sp.block_diag([K_o[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] for i in range(split.n)])
    found = transposed_findings(K_o + blocks, K_o, f_o, f_o, s, DOUBLE)
    assert [x.figures["pattern"] for x in found] == ["node-mirror"], [x.title for x in found]
    K = K_o + 0.5 * sp.diags(K_o.diagonal())  # the diagonal 1.5 times: no storage does that
    assert transposed_findings(K, K_o, f_o, f_o, s, DOUBLE) == []
