"""The vectorised Jacobi eigensolver against LAPACK (numpy.linalg.eigh), hard cases included."""

from __future__ import annotations

import numpy as np
import pytest

from mjed.eigen3 import symmetric_eigh

N = 500


def _rotations(rng, n):
    Q = np.linalg.qr(rng.standard_normal((n, 3, 3)))[0]
    return Q


def _with_eigenvalues(rng, lam):
    Q = _rotations(rng, N)
    return Q @ (np.asarray(lam, dtype=float)[None, :, None] * np.swapaxes(Q, 1, 2))


CASES = {
    "random symmetric": lambda rng: (lambda A: A + np.swapaxes(A, 1, 2))(
        rng.standard_normal((N, 3, 3))
    ),
    "identity": lambda rng: np.broadcast_to(np.eye(3), (N, 3, 3)).copy(),
    "diagonal": lambda rng: np.einsum("mi,ij->mij", rng.uniform(0.1, 3.0, (N, 3)), np.eye(3)),
    "double eigenvalue": lambda rng: _with_eigenvalues(rng, [1.0, 1.0, 2.0]),
    "nearly triple": lambda rng: _with_eigenvalues(rng, [1.0, 1.0 + 1e-12, 1.0 - 1e-12]),
    "nearly double": lambda rng: _with_eigenvalues(rng, [0.5, 2.0, 2.0 + 1e-9]),
    "wide scales": lambda rng: _with_eigenvalues(rng, [1e-8, 1.0, 1e8]),
    "indefinite": lambda rng: _with_eigenvalues(rng, [-3.0, 0.0, 2.0]),
    "rotations (C = Q^T Q, rest)": lambda rng: (lambda Q: np.swapaxes(Q, 1, 2) @ Q)(
        _rotations(rng, N)
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_jacobi_is_as_exact_as_lapack(case):
    rng = np.random.default_rng(5)
    C = CASES[case](rng)
    C = 0.5 * (C + np.swapaxes(C, 1, 2))
    lam, V = symmetric_eigh(np.ascontiguousarray(np.moveaxis(C, 0, -1)))
    ref = np.linalg.eigh(C)[0]
    scale = np.abs(C).max(axis=(1, 2))[:, None]
    eps = np.finfo(float).eps
    assert (np.diff(lam, axis=1) >= 0).all()  # ascending, like eigh
    assert np.abs(lam - ref).max() <= 20 * eps * scale.max()
    assert (np.abs(lam - ref) <= 20 * eps * scale).all()
    recon = V @ (lam[:, :, None] * np.swapaxes(V, 1, 2))
    assert (np.abs(recon - C).max(axis=(1, 2)) <= 20 * eps * scale[:, 0]).all()
    assert np.abs(np.swapaxes(V, 1, 2) @ V - np.eye(3)).max() <= 20 * eps


def test_exact_diagonal_input_needs_no_rotation():
    C = np.zeros((3, 3, 2))
    C[0, 0], C[1, 1], C[2, 2] = [3.0, 1.0], [2.0, 1.0], [1.0, 1.0]
    lam, V = symmetric_eigh(C)
    assert np.array_equal(lam, [[1.0, 2.0, 3.0], [1.0, 1.0, 1.0]])
    assert np.array_equal(np.abs(V[0]), np.eye(3)[:, ::-1])


def test_refuses_bad_input():
    with pytest.raises(ValueError, match="shape"):
        symmetric_eigh(np.zeros((3, 3)))
    C = np.zeros((3, 3, 4))
    C[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        symmetric_eigh(C)
