"""A tangent dP/dF in the SVD basis by Teran et al.'s blocks with one piece wrong
(conformance.diagnosis.svd_blocks). Each mistaken engine is built here from MJED's output: the
oracle's per-cell P and dP/dF (its element split) rotated into the engine's own SVD basis, one
block changed, rotated back and assembled (the force kept). On the uniaxial state two singular
values are equal and the engine's U, V in their plane are turned by an angle of its own per cell
(as its round-off would choose), which the reading must read back.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import assemble, cell_piola
from conformance.diagnosis.svd_blocks import (
    PAIRS,
    VARIANTS,
    _scaled,
    block_tensor,
    svd_block_findings,
    teran_blocks,
)
from conformance.judge.compare import DOUBLE
from mjed.materials import NeoHookean, Ogden, Yeoh

MODELS = {
    "neo": NeoHookean(mu=3000.0, lam=20000.0),
    "ogden": Ogden(mu=5000.0, alpha=3.0, k0=30000.0),
    "yeoh": Yeoh(c10=2000.0, c20=300.0, c30=50.0, k0=40000.0),
}


def _state(uniaxial: bool, compressed: bool = False):
    points, cells = box_mesh(2, jitter=0.2, seed=1)
    if uniaxial:
        return points, cells, points @ np.diag([1.2, 0.95, 0.95])
    rng = np.random.default_rng(3)
    c, s_ = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    M = np.array([[1.15, 0.1, 0.0], [0.0, 0.95, 0.05], [0.05, 0.0, 0.9]])
    if compressed:
        M = M @ np.diag([0.6, 0.7, 1.0])
    x = points @ (R @ M).T
    return points, cells, x + 0.03 * rng.standard_normal(points.shape)


def _engine(split, change, turn_seed=7, geometric_missing=False):
    """Force and stiffness of an engine whose blocks are change(t) (t: the oracle's
    TeranBlocks, read in a frame turned per cell in the equal pair's plane).
    """
    P, A = cell_piola(split)
    t = teran_blocks(P, A, split.F)
    U, V = t.U.copy(), t.V.copy()
    phi = np.random.default_rng(turn_seed).uniform(0, np.pi, len(U))
    c, s_ = np.cos(phi)[:, None], np.sin(phi)[:, None]
    for n, (p, q) in enumerate(PAIRS):
        on = t.equal[:, n]
        for W in (U, V):
            wp, wq = c * W[:, :, p] + s_ * W[:, :, q], -s_ * W[:, :, p] + c * W[:, :, q]
            W[on, :, p], W[on, :, q] = wp[on], wq[on]
    Ah = block_tensor(change(t))
    A2 = np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", U, V, U, V, Ah)
    if geometric_missing:  # a nearby mistake: not a piece of Teran's blocks
        S = np.linalg.inv(split.F) @ P
        A2 = A2 - np.einsum("ik,mJL->miJkL", np.eye(3), S)
    Ke = np.einsum("maj,mijkl,mbl->maibk", split.D, A2, split.D)
    Ke = split.V0[:, None, None, None, None] * Ke
    return assemble(split.cells, split.n, split.fe, Ke.reshape(-1, 12, 12))


def _found(model, uniaxial, change, compressed=False, **kw):
    points, cells, x = _state(uniaxial, compressed)
    split, f_o, K_o, s = mjed_split(MODELS[model], points, cells, x)
    f, K = _engine(split, change, **kw)
    return [x.code for x in svd_block_findings(split, f, K, s, DOUBLE)], f, K, K_o


def _right(t):
    return t.blocks


def test_the_right_blocks_are_the_oracle_and_nothing_is_named():
    for uniaxial in (False, True):
        codes, f, K, K_o = _found("neo", uniaxial, _right)
        assert abs(K - K_o).max() <= 1e-9 * abs(K_o).max()
        assert codes == []


@pytest.mark.parametrize("uniaxial", [False, True])
@pytest.mark.parametrize(
    "model, code",
    [
        ("ogden", "blocks-doubled"),
        ("neo", "entries-exchanged"),
        ("yeoh", "one-ordering"),
        ("yeoh", "hessian-diagonal"),
        ("ogden", "plus-difference"),
    ],
)
def test_a_wrong_block_is_named_on_both_states(model, code, uniaxial):
    codes, *_ = _found(model, uniaxial, VARIANTS[code][1])
    assert codes == [f"svd-blocks-{code}"]


def test_the_clamped_minus_quotient_is_named_where_singular_values_are_equal():
    codes, *_ = _found("neo", True, VARIANTS["gap-clamped"][1])
    assert codes == ["svd-blocks-gap-clamped"]


def test_the_definiteness_fix_is_named_in_compressed_cells():
    codes, *_ = _found("neo", False, VARIANTS["definiteness-fix"][1], compressed=True)
    assert codes == ["svd-blocks-definiteness-fix"]


def test_another_factor_on_the_blocks_is_read_by_the_piece_fit():
    codes, *_ = _found("ogden", False, lambda t: _scaled(t, mij=1.5, mji=1.5, pij=1.5, pji=1.5))
    assert codes == ["svd-blocks-pieces"]
    # on the uniaxial state the pieces turn with the frame: no fit, and no variant is it
    codes, *_ = _found("ogden", True, lambda t: _scaled(t, mij=1.5, mji=1.5, pij=1.5, pji=1.5))
    assert codes == []


@pytest.mark.parametrize("uniaxial", [False, True])
def test_a_geometric_stiffness_missing_is_not_a_wrong_block(uniaxial):
    codes, *_ = _found("neo", uniaxial, _right, geometric_missing=True)
    assert codes == []
    codes, *_ = _found("neo", uniaxial, VARIANTS["blocks-doubled"][1], geometric_missing=True)
    assert codes == []


def test_the_turns_out_of_a_local_minimum_on_a_larger_uniaxial_mesh():
    # 162 cells, all with two equal singular values: Gauss-Newton on the angles alone stalls
    # here; the search in the fit's null space finds the engine's turns
    points, cells = box_mesh(3, jitter=0.2, seed=1)
    x = points @ np.diag([1.2, 0.95, 0.95])
    split, f_o, K_o, s = mjed_split(MODELS["ogden"], points, cells, x)
    f, K = _engine(split, VARIANTS["blocks-doubled"][1])
    codes = [x.code for x in svd_block_findings(split, f, K, s, DOUBLE)]
    assert codes == ["svd-blocks-blocks-doubled"]
    f, K = _engine(split, VARIANTS["hessian-diagonal"][1])
    codes = [x.code for x in svd_block_findings(split, f, K, s, DOUBLE)]
    assert codes == ["svd-blocks-hessian-diagonal"]
