"""conformance.judge.colouring: groups of nodes that share no cell, and the oracle's column
derivatives computed a group at a time (OracleCache.column_derivatives), which must equal, bit
for bit, the same differences taken one dof at a time.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, perturbed

from common.cases import DEFAULT_MATERIALS
from conformance.judge.colouring import independent_node_groups
from reference_fem import dolfinx_available


@pytest.mark.parametrize("n", [1, 3])
def test_groups_cover_every_node_once_and_share_no_cell(n):
    points, cells = box_mesh(n, jitter=0.2)
    groups = independent_node_groups(cells, points.shape[0])
    assert np.array_equal(np.sort(np.concatenate(groups)), np.arange(points.shape[0]))
    of = np.empty(points.shape[0], dtype=int)
    for g, nodes in enumerate(groups):
        of[nodes] = g
    # no cell holds two nodes of one group
    assert all(len(set(of[c])) == 4 for c in cells)
    # far fewer groups than nodes on a mesh of many nodes (the point of grouping)
    if n == 3:
        assert len(groups) < points.shape[0] / 2


def test_a_node_in_no_cell_gets_a_group():
    cells = np.array([[0, 1, 2, 3]])
    groups = independent_node_groups(cells, 5)
    assert sorted(np.concatenate(groups).tolist()) == [0, 1, 2, 3, 4]


def _one_dof_at_a_time(oracle, x, step):
    """The differences the grouped computation replaces: 6n stiffness assemblies."""
    K0 = sp.csc_matrix(oracle.stiffness(x.reshape(-1, 3)))
    first, second = [], []
    for j in range(x.size):
        cols = []
        for sign in (1.0, -1.0):
            y = x.copy()
            y[j] += sign * step[j]
            cols.append(sp.csc_matrix(oracle.stiffness(y.reshape(-1, 3)))[:, j])
        first.append((cols[0] - cols[1]) / (2.0 * step[j]))
        second.append((cols[0] - 2.0 * K0[:, j] + cols[1]) / step[j] ** 2)
    return sp.hstack(first).tocsr(), sp.hstack(second).tocsr()


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
@pytest.mark.parametrize("material", ["Ogden", "Costa"])
def test_grouped_column_derivatives_equal_one_dof_at_a_time(material):
    from conformance.judge.oracle import OracleCache, _key
    from conformance.kit.spec import CaseInput

    points, cells = box_mesh(2, jitter=0.2, seed=3)
    x = perturbed(points, np.random.default_rng(5), 0.05)
    case = CaseInput("grouped", points, cells, x, DEFAULT_MATERIALS[material])
    step = 1e-3 * (1.0 + np.arange(x.size) / x.size)  # a different step for every dof
    cache = OracleCache()
    G1, G2 = cache.column_derivatives(case, step)
    R1, R2 = _one_dof_at_a_time(cache._oracles[_key(case)], x.ravel().copy(), step)
    for got, want in ((G1, R1), (G2, R2)):
        assert got.shape == want.shape and abs(want).max() > 0
        assert (got != want).nnz == 0  # equal bit for bit, not only close
