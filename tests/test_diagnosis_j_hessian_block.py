"""MJED's J-Hessian block with a wrong factor (conformance.diagnosis.j_hessian_block): the
mistaken engine writes the block here from NeoHookean's own psi_J = (lam ln J - mu) / J and its
own dJ_a = J F^-T D_a, not with the module's functions; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.j_hessian_block import j_hessian_findings
from conformance.judge.compare import DOUBLE


def _case(seed=0):
    model = default_material("NeoHookean")
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, points, cells, x, split, f_o, K_o, s


def _engine_block(model, split, psi_factor=1.0):
    """The engine's per-cell block psi_J V0 (dJ_a dJ_b^T - dJ_b dJ_a^T) / J, assembled."""
    F, D, V0 = split.F, split.D, split.V0
    J = np.linalg.det(F)
    psi = psi_factor * (model.lam * np.log(J) - model.mu) / J
    dJ = J[:, None, None] * np.einsum("mji,maj->mai", np.linalg.inv(F), D)  # (m, 4, 3)
    B = (np.einsum("mai,mbj->maibj", dJ, dJ) - np.einsum("mbi,maj->maibj", dJ, dJ)) / J[
        :, None, None, None, None
    ]
    Ke = ((psi * V0)[:, None, None, None, None] * B).reshape(-1, 12, 12)
    m = split.cells.shape[0]
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke)[1]


def test_the_j_hessian_block_with_its_sign_flipped_is_named():
    model, points, cells, x, split, f_o, K_o, s = _case()
    K = K_o - 2.0 * _engine_block(model, split)  # the engine's block, sign flipped
    found = j_hessian_findings(model, points, cells, x, f_o, K, f_o, K_o, s, DOUBLE)
    assert len(found) == 1, [f.title for f in found]
    assert found[0].figures["factor"] == -2.0 and "sign flipped" in found[0].title


def test_the_block_left_out_is_named_and_nearby_mistakes_are_not():
    model, points, cells, x, split, f_o, K_o, s = _case(1)
    K = K_o - _engine_block(model, split)
    found = j_hessian_findings(model, points, cells, x, f_o, K, f_o, K_o, s, DOUBLE)
    assert [f.figures["factor"] for f in found] == [-1.0]
    # the block flipped with psi_J off by 10 %, the whole K scaled, a wrong force
    for wrong in (
        K_o - 2.0 * _engine_block(model, split, psi_factor=0.9),
        1.01 * K_o,
    ):
        assert j_hessian_findings(model, points, cells, x, f_o, wrong, f_o, K_o, s, DOUBLE) == []
    K = K_o - 2.0 * _engine_block(model, split)
    assert j_hessian_findings(model, points, cells, x, 1.1 * f_o, K, f_o, K_o, s, DOUBLE) == []


def _cross(v):
    """(m, 3, 3) [v]x, v x w = [v]x w."""
    z = np.zeros(v.shape[0])
    return np.stack(
        [
            np.stack([z, -v[:, 2], v[:, 1]], -1),
            np.stack([v[:, 2], z, -v[:, 0]], -1),
            np.stack([-v[:, 1], v[:, 0], z], -1),
        ],
        1,
    )


def _hessian_j_blocks(vectors):
    """d2J/dF2 as (m, 3, 3, 3, 3) [k, I, l, L] from 3 x 3 blocks (I, L) built of the
    cross-product matrices of ``vectors`` (m, 3 (M), 3): [[0, -[v2], [v1]], [[v2], 0, -[v0]],
    [-[v1], [v0], 0]] (F's columns give the Hessian).
    """
    v0, v1, v2 = (_cross(vectors[:, M]) for M in range(3))
    Z = np.zeros_like(v0)
    rows = [[Z, -v2, v1], [v2, Z, -v0], [-v1, v0, Z]]
    return np.stack([np.stack(r, 1) for r in rows], 1).transpose(0, 3, 1, 4, 2)


def test_the_hessian_of_j_from_the_rows_of_f_is_named():
    """An engine building d2J/dF2's blocks from F's rows where its columns belong."""
    from conformance.diagnosis.elements import tangent_element_matrices

    model, points, cells, x, split, f_o, K_o, s = _case(2)
    F = split.F
    J = np.linalg.det(F)
    psi = (model.lam * np.log(J) - model.mu) / J
    right = _hessian_j_blocks(F.swapaxes(1, 2))  # vectors[:, M] = column M of F
    rows = _hessian_j_blocks(F)  # vectors[:, M] = row M
    m = cells.shape[0]
    ones = tangent_element_matrices(split.V0, split.D, right)
    assert np.allclose(  # the columns' blocks are the Hessian of J
        assemble(cells, split.n, np.zeros((m, 4, 3)), psi[:, None, None] * ones)[1].toarray(),
        _engine_block(model, split).toarray(),
    )
    dA = psi[:, None, None, None, None] * (rows - right)
    K = (
        K_o
        + assemble(
            cells, split.n, np.zeros((m, 4, 3)), tangent_element_matrices(split.V0, split.D, dA)
        )[1]
    )
    found = j_hessian_findings(model, points, cells, x, f_o, K, f_o, K_o, s, DOUBLE)
    assert [f.code for f in found] == ["j-hessian-rows"], [f.title for f in found]
