"""A spectral engine's principal block by differences of the principal Kirchhoff stresses
(conformance.diagnosis.principal_differences). The engine's error is written here from Ogden's
closed form, tau_a = mu/alpha (e_a - sum e / 3) + k0 ln J with e_a = exp(alpha (l_a - ln J / 3)),
l_a = ln lambda_a: its principal block d tau_a / d l_b differenced by the scheme under test
against the exact mu (e_a delta_ab - (e_a + e_b)/3 + sum e / 9) + k0, pushed into the stiffness
along n_a n_a n_b n_b (the pair terms exact); MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import assemble
from conformance.diagnosis.principal_differences import principal_difference_fits
from mjed import materials as M

MU, ALPHA, K0 = 2.0e3, 5.0, 4.0e4


def _tau(logs):
    """(m, 3) Ogden's principal Kirchhoff stresses at log-stretches logs (m, 3)."""
    L = logs.sum(axis=1, keepdims=True)
    e = np.exp(ALPHA * (logs - L / 3.0))
    return MU / ALPHA * (e - e.sum(axis=1, keepdims=True) / 3.0) + K0 * L


def _exact(logs):
    L = logs.sum(axis=1, keepdims=True)
    e = np.exp(ALPHA * (logs - L / 3.0))
    ea, eb = e[:, :, None], e[:, None, :]
    block = -(ea + eb) / 3.0 + e.sum(axis=1)[:, None, None] / 9.0 + K0 / MU
    return MU * (block + ea * np.eye(3))


def _differenced(logs, h, scheme):
    """The engine's d tau_a / d l_b: by differences of tau in l (forward or
    central), or as sigma_a sigma_b times the Hessian of Psi in sigma by forward differences of
    Psi_a = tau_a / sigma_a with the step h sigma_b, plus delta_ab tau_a ("sigma").
    """
    out = np.empty(logs.shape + (3,))
    sigma = np.exp(logs)
    for b in range(3):
        e = np.zeros(3)
        e[b] = 1.0
        if scheme == "forward":
            out[:, :, b] = (_tau(logs + h * e) - _tau(logs)) / h
        elif scheme == "central":
            out[:, :, b] = (_tau(logs + h * e) - _tau(logs - h * e)) / (2 * h)
        else:
            moved = logs + np.log1p(h) * e
            psi = (_tau(moved) / np.exp(moved) - _tau(logs) / sigma) / (h * sigma[:, b : b + 1])
            out[:, :, b] = sigma * sigma[:, b : b + 1] * psi
    if scheme == "sigma":
        out += np.einsum("ma,ab->mab", _tau(logs), np.eye(3))
    return out


@pytest.fixture(scope="module")
def case():
    points, cells = box_mesh(3, jitter=0.2, seed=5)
    rng = np.random.default_rng(5)
    x = points @ np.diag([1.2, 0.9, 0.97]).T + 0.04 * rng.standard_normal(points.shape)
    model = M.Ogden(mu=MU, alpha=ALPHA, k0=K0)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    return points, model, split, K_o


def _stiffness_error(split, dM):
    """The engine's K - K_o for a principal-block error dM (m, 3, 3) of J c."""
    x, n = np.linalg.eigh(split.F @ split.F.swapaxes(1, 2))
    nn = np.einsum("mia,mja->maij", n, n)
    Jc = np.einsum("mab,maij,mbkl->mijkl", dM, nn, nn)
    gN = np.einsum("maI,mIi->mai", split.D, np.linalg.inv(split.F))
    Ke = np.einsum("m,maj,mijkl,mbl->maibk", split.V0, gN, Jc, gN).reshape(-1, 12, 12)
    m = split.V0.size
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke)[1], 0.5 * np.log(x)


@pytest.mark.parametrize(
    "scheme, h, named",
    [
        ("forward", 1e-6, "forward-log"),
        ("central", 1e-3, "central-log"),
        ("sigma", 1e-6, "forward-relative-sigma"),
        # handed unsymmetrised to an eigen-solver that reads the lower triangle, the singular
        # values descending: the rows of the smaller stretches kept, mirrored
        ("sigma-eigh", 1e-6, "forward-relative-sigma+smaller"),
    ],
)
def test_the_principal_block_by_differences_is_named_with_its_step(case, scheme, h, named):
    points, model, split, K_o = case
    _, logs = _stiffness_error(split, np.zeros((split.V0.size, 3, 3)))
    dM = _differenced(logs, h, scheme.removesuffix("-eigh")) - _exact(logs)
    if scheme.endswith("-eigh"):
        descending = dM[:, ::-1, ::-1]  # the engine's order of the singular values
        low = np.tril(descending) + np.swapaxes(np.tril(descending, -1), 1, 2)
        dM = low[:, ::-1, ::-1]
    D, _ = _stiffness_error(split, dM)
    assert sp.linalg.norm(D) > 1e-12 * sp.linalg.norm(K_o)
    fits = principal_difference_fits(model, split, points, D.tocsr(), K_o)
    assert fits, "not named"
    part, found, fit = fits[0]
    assert found == named and part in ("", "mu")
    assert fit.step == pytest.approx(h, rel=0.05)
    assert fit.explained > 0.99


def test_a_principal_block_slip_that_is_not_a_difference_is_not_named(case):
    points, model, split, K_o = case
    _, logs = _stiffness_error(split, np.zeros((split.V0.size, 3, 3)))
    exact = _exact(logs)
    diagonal = exact * np.eye(3)  # the diagonal entries alone scaled
    for dM in (1e-6 * exact, 1e-6 * diagonal):
        D, _ = _stiffness_error(split, dM)
        assert sp.linalg.norm(D) > 1e-12 * sp.linalg.norm(K_o)
        assert principal_difference_fits(model, split, points, D.tocsr(), K_o) == []


def test_an_anisotropic_model_is_not_read():
    class Framed:
        frame = np.eye(3)

    assert principal_difference_fits(Framed(), None, None, None, None) == []


def test_scaling_modes_from_the_eigenvector_matrix_rows_are_named(case):
    """An SVD engine rebuilding its scaling block from eigh's eigenvector matrix read by rows
    (singular values descending), Ogden's Hessian in sigma from its closed form.
    """
    from conformance.diagnosis.principal_differences import scaling_rebuild_findings
    from conformance.judge.compare import DOUBLE, scales

    points, model, split, K_o = case
    _, logs = _stiffness_error(split, np.zeros((split.V0.size, 3, 3)))
    sigma = np.exp(logs)
    pair = sigma[:, :, None] * sigma[:, None, :]
    H = (_exact(logs) - np.einsum("ma,ab->mab", _tau(logs), np.eye(3))) / pair
    Hd = H[:, ::-1, ::-1]  # the engine's order: descending
    w, W = np.linalg.eigh(Hd)
    used = np.einsum("mki,mk,mkj->mij", W, w, W)[:, ::-1, ::-1]  # W^T diag(w) W
    D, _ = _stiffness_error(split, (used - H) * pair)
    s = scales(0.5, 1.0, np.ones((split.n, 3)), K_o)
    found = scaling_rebuild_findings(model, split, points, K_o + D, K_o, s, DOUBLE)
    assert [(f.code, f.figures["descending"]) for f in found] == [
        ("scaling-eigenvectors-as-rows", True)
    ]
    assert scaling_rebuild_findings(model, split, points, K_o + 1.01 * D, K_o, s, DOUBLE) == []


def test_a_volumetric_tangent_error_is_not_a_scheme(case):
    """k0 I (x) I where k0 / J I (x) I belongs (corpus 18's Yeoh UMAT), in the principal frame
    a constant block: on one J it is what the relative-step scheme on the volumetric part (linear
    in the log-stretches, off by k0 (ln(1 + h) / h - 1)) gives with a step of about 0.6, which
    is no finite-difference step; nor is the simulation's round-off of an exact part a scheme.
    """
    from common.cases import default_material

    for model in (case[1], default_material("Yeoh")):
        points, cells = box_mesh(3, jitter=0.2, seed=5)
        x = points @ np.diag([1.3, 0.9, 0.9]).T  # one J: the volumetric block is one number
        split, _, K_o, _ = mjed_split(model, points, cells, x)
        J = np.linalg.det(split.F)
        dM = (model.k0 * (J - 1.0))[:, None, None] * np.ones((1, 3, 3))
        D, _ = _stiffness_error(split, dM)
        assert sp.linalg.norm(D) > 1e-6 * sp.linalg.norm(K_o)
        assert principal_difference_fits(model, split, points, D.tocsr(), K_o) == [], model
