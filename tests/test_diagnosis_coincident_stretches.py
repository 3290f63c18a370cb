"""The tangent where two principal stretches coincide (conformance.diagnosis.coincident_stretches):
on the uniaxial state (two equal stretches) an engine whose tangent errs in the plane of the
equal stretches alone is named, one that errs between distinct stretches is not, and round-off
noise is not (no shared change fits it). The engine is a small Neo-Hookean engine of this
module's own (S and CC in closed form, CC edited in each cell's eigenbasis of C); MJED is the
oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import mjed_split, stretched_state

from conformance.diagnosis.coincident_stretches import coincident_findings
from conformance.diagnosis.elements import assemble, cell_kinematics
from conformance.judge.compare import DOUBLE
from mjed.materials import NeoHookean

MU, LAM = 3448.0, 31034.0
EYE = np.eye(3)


def _engine(points, cells, x, pair=None, factor=1.0):
    """Neo-Hookean with the pair terms CC_abab, CC_abba of eigen-indices ``pair`` scaled."""
    V, G, F = cell_kinematics(points, cells, x)
    C = np.swapaxes(F, 1, 2) @ F
    Ci = np.linalg.inv(C)
    lnJ = np.log(np.linalg.det(F))
    S = MU * (EYE - Ci) + LAM * lnJ[:, None, None] * Ci
    g = (MU - LAM * lnJ)[:, None, None, None, None]
    CC = LAM * np.einsum("mIJ,mKL->mIJKL", Ci, Ci) + g * (
        np.einsum("mIK,mJL->mIJKL", Ci, Ci) + np.einsum("mIL,mJK->mIJKL", Ci, Ci)
    )
    if pair is not None:
        _, N = np.linalg.eigh(C)
        hat = np.einsum("mIa,mJb,mKc,mLd,mIJKL->mabcd", N, N, N, N, CC)
        a, b = pair
        for i, j in ((a, b), (b, a)):
            hat[:, i, j, i, j] *= factor
            hat[:, i, j, j, i] *= factor
        CC = np.einsum("mIa,mJb,mKc,mLd,mabcd->mIJKL", N, N, N, N, hat)
    A = np.einsum("ik,mJL->miJkL", EYE, S) + np.einsum("miI,mIJKL,mkK->miJkL", F, CC, F)
    fe = -V[:, None, None] * np.einsum("miJ,maJ->mai", F @ S, G)
    Ke = V[:, None, None, None, None] * np.einsum("maJ,miJkL,mbL->maibk", G, A, G)
    return assemble(cells, len(points), fe, Ke.reshape(-1, 12, 12))


def _uniaxial(**mistake):
    points, cells, x = stretched_state(0, uniaxial=True)  # diag(1.2, 0.95, 0.95)
    split, f_o, K_o, s = mjed_split(NeoHookean(mu=MU, lam=LAM), points, cells, x)
    f, K = _engine(points, cells, x, **mistake)
    return split, f, K, K_o, s


def test_the_equal_stretches_pair_term_wrong_is_named():
    split, f, K, K_o, s = _uniaxial(pair=(0, 1), factor=0.7)  # eigh: 0.95^2, 0.95^2, 1.44
    found = coincident_findings(split, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["coincident-stretches"], found
    assert found[0].strength == "explains" and found[0].figures["explained"] > 0.999


def test_a_pair_term_between_distinct_stretches_is_not_this():
    split, f, K, K_o, s = _uniaxial(pair=(0, 2), factor=0.7)
    assert coincident_findings(split, f, K, s, DOUBLE) == []


def test_round_off_noise_is_not_a_shared_change():
    split, f, K, K_o, s = _uniaxial()
    rng = np.random.default_rng(1)
    Kc = sp.coo_matrix(K)
    noisy = sp.csr_matrix(
        (Kc.data * (1.0 + 1e-8 * rng.standard_normal(Kc.data.size)), (Kc.row, Kc.col)), Kc.shape
    )
    assert coincident_findings(split, f, noisy, s, DOUBLE) == []


def test_a_random_state_is_not_read():
    points, cells, x = stretched_state(0)
    split, f_o, K_o, s = mjed_split(NeoHookean(mu=MU, lam=LAM), points, cells, x)
    f, K = _engine(points, cells, x, pair=(0, 1), factor=0.7)
    assert coincident_findings(split, f, K, s, DOUBLE) == []
