"""A fibre-frame strain routine's results taken back to the axes wrongly (conformance.diagnosis.
frame_routine): Costa with a random frame per cell; the engine is MJED's stress and tangent per
cell taken into the frame by this file's own loops (Voigt 11, 22, 33, 23, 13, 12), changed as
an engine's driver changes them (the 21-entry triangle packed row by row and unpacked column by
column; the shear stresses in the tensor convention; the tangent never rotated back), taken
back and assembled. Against them: a slip of another size, and an error that is none of them.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import (
    assemble,
    cell_piola,
    piola_element_forces,
    tangent_element_matrices,
)
from conformance.diagnosis.frame_routine import frame_routine_findings
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.judge.compare import DOUBLE
from mjed.materials import Costa

PAIRS = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


class _Out:
    def __init__(self, force, stiffness):
        self.force, self.stiffness = force, stiffness


@pytest.fixture(scope="module")
def case():
    points, cells = box_mesh(2, jitter=0.2, seed=5)
    rng = np.random.default_rng(5)
    x = points @ np.diag([1.12, 0.95, 0.92]).T + 0.04 * rng.standard_normal(points.shape)
    R = np.linalg.qr(rng.standard_normal((cells.shape[0], 3, 3)))[0]
    R = R * np.sign(np.linalg.det(R))[:, None, None]
    model = Costa(0.9, 3.0, 1.0, 0.3, 0.8, 0.2, 0.1, 0.5, frame=R)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, R, split, f_o, sp.csr_matrix(K_o), s


def _engine(case, change):
    """The oracle's per-cell (Sf, Df) in the frame as 6 and 6 x 6 Voigt arrays, changed by
    ``change(Sv, Dv, R) -> (S, CC)`` (global tensors), assembled.
    """
    _, R, split, _, _, _ = case
    t = cell_tensors(*cell_piola(split), split.F)
    m = R.shape[0]
    Sv, Dv = np.zeros((m, 6)), np.zeros((m, 6, 6))
    for A, (i, j) in enumerate(PAIRS):
        Sv[:, A] = np.einsum("mI,mIJ,mJ->m", R[:, :, i], t.S, R[:, :, j])
        for B, (k, l) in enumerate(PAIRS):
            Dv[:, A, B] = np.einsum(
                "mI,mJ,mK,mL,mIJKL->m", R[:, :, i], R[:, :, j], R[:, :, k], R[:, :, l], t.CC
            )
    S, CC = change(Sv, Dv, R)
    F = split.F
    A4 = np.einsum("mkJ,mJIML,mlM->mkIlL", F, CC, F) + np.einsum("kl,mLI->mkIlL", np.eye(3), S)
    f, K = assemble(
        split.cells,
        split.n,
        piola_element_forces(split.V0, split.D, F @ S),
        tangent_element_matrices(split.V0, split.D, A4),
    )
    return _Out(f, K)


def _tensors(Sv, Dv):
    m = Sv.shape[0]
    S, CC = np.zeros((m, 3, 3)), np.zeros((m, 3, 3, 3, 3))
    for A, (i, j) in enumerate(PAIRS):
        S[:, i, j] = S[:, j, i] = Sv[:, A]
        for B, (k, l) in enumerate(PAIRS):
            for a, b in ((i, j), (j, i)):
                for c, d in ((k, l), (l, k)):
                    CC[:, a, b, c, d] = Dv[:, A, B]
    return S, CC


def _back(S, CC, R, rotate_tangent=True):
    S = np.einsum("mIa,mab,mJb->mIJ", R, S, R)
    if rotate_tangent:
        CC = np.einsum("mIa,mJb,mKc,mLd,mabcd->mIJKL", R, R, R, R, CC)
    return S, CC


def _read(case, out):
    model, _, split, f_o, K_o, s = case
    return frame_routine_findings(split, model, out, f_o, K_o, s, DOUBLE)


def test_the_unchanged_round_trip_is_the_oracle(case):
    out = _engine(case, lambda Sv, Dv, R: _back(*_tensors(Sv, Dv), R))
    assert np.allclose(out.force, case[3], atol=1e-11 * np.abs(case[3]).max())
    assert abs(out.stiffness - case[4]).max() <= 1e-10 * abs(case[4]).max()
    assert _read(case, out) == []


def test_a_triangle_packed_by_rows_and_unpacked_by_columns_is_named(case):
    rows = [(i, j) for i in range(6) for j in range(i, 6)]
    cols = [(i, j) for j in range(6) for i in range(j + 1)]

    def change(Sv, Dv, R):
        packed = np.stack([Dv[:, i, j] for i, j in rows], axis=1)
        D2 = np.zeros_like(Dv)
        for p, (i, j) in enumerate(cols):
            D2[:, i, j] = D2[:, j, i] = packed[:, p]
        return _back(*_tensors(Sv, D2), R)

    (f,) = _read(case, _engine(case, change))
    assert "unpacked column by column" in f.title


def test_shear_stresses_doubled_and_a_tangent_left_in_the_frame_are_named(case):
    def doubled(Sv, Dv, R):
        S2 = Sv.copy()
        S2[:, 3:] *= 2.0
        return _back(*_tensors(S2, Dv), R)

    (f,) = _read(case, _engine(case, doubled))
    assert "shear entries doubled" in f.title and "tangent right" in f.title
    (f,) = _read(case, _engine(case, lambda Sv, Dv, R: _back(*_tensors(Sv, Dv), R, False)))
    assert "as if global" in f.title


def test_other_sizes_and_other_errors_are_not_named(case):
    def tripled(Sv, Dv, R):
        S2 = Sv.copy()
        S2[:, 3:] *= 3.0
        return _back(*_tensors(S2, Dv), R)

    assert _read(case, _engine(case, tripled)) == []
    _, _, _, f_o, K_o, _ = case
    assert _read(case, _Out(f_o, 1.01 * K_o)) == []
