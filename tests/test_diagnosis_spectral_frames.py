"""A spectral engine's principal frame wrong (conformance.diagnosis.spectral_frames): the
eigenvectors of b for those of C, the eigenvalues paired with the wrong eigenvectors. The engine
is a small Neo-Hookean engine of this module's own: S and CC in closed form, then moved as the
mistake moves them; MJED is the oracle.
"""

from __future__ import annotations

import numpy as np
from conftest import mjed_split, stretched_state

from conformance.diagnosis.elements import assemble, cell_kinematics
from conformance.diagnosis.spectral_frames import spectral_frame_findings
from conformance.judge.compare import DOUBLE
from mjed.materials import NeoHookean

MU, LAM = 3448.0, 31034.0
EYE = np.eye(3)


def _rot(CC, Q):
    return np.einsum("mIa,mJb,mKc,mLd,mabcd->mIJKL", Q, Q, Q, Q, CC)


def _engine(points, cells, x, frame="C", order=(0, 1, 2)):
    """Neo-Hookean assembled on the eigenvectors of C (or of b: frame="b"), the eigenvalue of
    index order[a] paired with eigenvector a.
    """
    V, G, F = cell_kinematics(points, cells, x)
    C = np.swapaxes(F, 1, 2) @ F
    lam2, N = np.linalg.eigh(C)
    if frame == "b":
        N = np.linalg.eigh(F @ np.swapaxes(F, 1, 2))[1]
    lam2 = lam2[:, list(order)]
    # in the principal frame: C_hat = diag(lam2); S and CC of Neo-Hookean there
    J = np.sqrt(np.prod(lam2, axis=1))
    inv = 1.0 / lam2
    S_hat = np.zeros((len(cells), 3, 3))
    for a in range(3):
        S_hat[:, a, a] = MU * (1.0 - inv[:, a]) + LAM * np.log(J) * inv[:, a]
    Ci = np.zeros_like(S_hat)
    for a in range(3):
        Ci[:, a, a] = inv[:, a]
    g = (MU - LAM * np.log(J))[:, None, None, None, None]
    CC_hat = LAM * np.einsum("mIJ,mKL->mIJKL", Ci, Ci) + g * (
        np.einsum("mIK,mJL->mIJKL", Ci, Ci) + np.einsum("mIL,mJK->mIJKL", Ci, Ci)
    )
    S = N @ S_hat @ np.swapaxes(N, 1, 2)
    CC = _rot(CC_hat, N)
    A = np.einsum("ik,mJL->miJkL", EYE, S) + np.einsum("miI,mIJKL,mkK->miJkL", F, CC, F)
    fe = -V[:, None, None] * np.einsum("miJ,maJ->mai", F @ S, G)
    Ke = V[:, None, None, None, None] * np.einsum("maJ,miJkL,mbL->maibk", G, A, G)
    return assemble(cells, len(points), fe, Ke.reshape(-1, 12, 12))


def _found(uniaxial=False, **mistake):
    points, cells, x = stretched_state(0, uniaxial)
    split, f_o, K_o, s = mjed_split(NeoHookean(mu=MU, lam=LAM), points, cells, x)
    f, K = _engine(points, cells, x, **mistake)
    return spectral_frame_findings(split, f, K, s, DOUBLE), f, K, f_o, K_o


def test_the_right_spectral_engine_is_the_oracle_and_nothing_is_named():
    found, f, K, f_o, K_o = _found()
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max()
    assert abs(K - K_o).max() <= 1e-9 * abs(K_o).max()
    assert found == []


def test_the_eigenvectors_of_b_are_named():
    found, *_ = _found(frame="b")
    assert [x.code for x in found] == ["spectral-frame-b"], found
    assert "b = F F^T" in found[0].title and "force and the stiffness" in found[0].title


def test_eigenvalues_sorted_descending_with_the_vectors_left_ascending_are_named():
    found, *_ = _found(order=(2, 1, 0))
    assert [x.code for x in found] == ["spectral-pairing-210"], found
    assert "smallest eigenvector with the largest" in found[0].title


def test_uniaxial_state_a_swap_of_the_equal_stretches_explains_nothing():
    """Two stretches equal (eigh's two smallest): swapping them is the oracle and nothing is
    named; swapping one of them with the largest is two pairings at once, said as ambiguous.
    """
    found, f, K, f_o, K_o = _found(uniaxial=True, order=(1, 0, 2))
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max() and found == []
    found, *_ = _found(uniaxial=True, order=(0, 2, 1))
    assert found[0].code == "ambiguous", found
    assert {x.code for x in found[1:]} == {"spectral-pairing-021", "spectral-pairing-120"}
