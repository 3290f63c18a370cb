"""Ogden's spectral tangent with its shear (a != b) terms, its -2 tau_a n_a^4 term or its
mean term wrong (conformance.diagnosis.spectral_tangent: SHEAR_VARIANTS, shear_term_findings,
stress_term_findings; conformance.diagnosis.split_parts for the mean term). The engine is
built here as a ported spectral UMAT: per cell the principal Kirchhoff stresses of the isochoric
stretches, the spectral tangent J c (the a == b terms by their log-stretch derivatives, the
a != b terms by the divided difference gam_ab, times ``shear``), the volumetric part of
k0/2 (ln J)^2, and K = v (grad N . c . grad N + grad N . sigma grad N I).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import box_mesh, mjed_split
from diagnosis_stubs import cell_gradients

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.spectral_tangent import shear_term_findings, stress_term_findings
from conformance.diagnosis.split_parts import split_part_findings
from conformance.judge.compare import DOUBLE


def _dyad(a, b):
    return np.einsum("mij,mkl->mijkl", a, b)


def _ogden_stiffness(
    points, cells, x, model, shear=1.0, mean=1.0, sigma=1.0, turn=None, shear_mean=1.0
):
    """K (3n, 3n) of the spectral Ogden engine whose a != b tangent terms are ``shear`` times
    the divided difference, the mean term mu sum t / 9 of d tau_a / d ln lambda_b ``mean``
    times its value, the term -2 tau_a n_a^4 ``sigma`` times its and the shear coefficients'
    deviatoric-mean term ``shear_mean`` times its (1: right); turn: a
    generator that turns the engine's eigenvectors of the repeated pair (sorted: the first two) by a
    random angle per cell, as another eigen-solver's round-off would.
    """
    mu, alpha, k0 = model.mu, model.alpha, model.k0
    V0, D, F, J = cell_gradients(points, cells, x)
    e, n = np.linalg.eigh(F @ F.swapaxes(1, 2))
    if turn is not None:
        phi = turn.uniform(0.0, np.pi, len(J))
        c, s_ = np.cos(phi)[:, None], np.sin(phi)[:, None]
        n1, n2 = n[:, :, 0].copy(), n[:, :, 1].copy()
        n[:, :, 0], n[:, :, 1] = c * n1 + s_ * n2, c * n2 - s_ * n1
    xb = J[:, None] ** (-2.0 / 3.0) * e
    L = xb ** (alpha / 2.0)
    S = L.sum(axis=1)
    mm = mu / alpha
    beta = mm * (L - S[:, None] / 3.0)
    N = np.einsum("mia,mjb->mabij", n, n)
    Naa = np.einsum("maaij->maij", N)
    eye3 = np.eye(3)
    dbeta = mm * alpha * (L[:, :, None] * eye3 - (L[:, :, None] + L[:, None, :]) / 3.0)
    dbeta = dbeta + mean * mm * alpha * S[:, None, None] / 9.0
    dbeta = dbeta - sigma * 2.0 * beta[:, :, None] * eye3
    Jc = np.einsum("mab,maij,mbkl->mijkl", dbeta, Naa, Naa)
    for a, b in ((0, 1), (1, 0), (0, 2), (2, 0), (1, 2), (2, 1)):
        xa, xc = xb[:, a], xb[:, b]
        same = np.isclose(xa, xc, rtol=1e-12, atol=0.0)
        # (beta_a xb_b - beta_b xb_a) / (xb_a - xb_b) and its limit for equal stretches
        lim = mm * (alpha / 2.0 - 1.0) * L[:, a] + mm * S / 3.0
        dd = (beta[:, a] * xc - beta[:, b] * xa) / np.where(same, 1.0, xa - xc)
        # shear_mean: the sign (or factor) of the deviatoric mean's term mu S / (3 alpha) in it
        gam = shear * np.where(same, lim, dd) + (shear_mean - 1.0) * mm * S / 3.0
        Nab, Nba = N[:, a, b], N[:, b, a]
        Jc = Jc + gam[:, None, None, None, None] * (_dyad(Nab, Nab) + _dyad(Nab, Nba))
    tau = np.einsum("ma,maij->mij", beta, Naa)
    lnJ = np.log(J)
    p, pt = k0 * lnJ, k0 * lnJ + k0 * (1.0 - lnJ)  # J U', J U' + J^2 U''
    one = np.broadcast_to(eye3, F.shape)
    II = 0.5 * (np.einsum("mik,mjl->mijkl", one, one) + np.einsum("mil,mjk->mijkl", one, one))
    Jc = (
        Jc + pt[:, None, None, None, None] * _dyad(one, one) - 2 * p[:, None, None, None, None] * II
    )
    tau = tau + p[:, None, None] * eye3
    c, sig = Jc / J[:, None, None, None, None], tau / J[:, None, None]
    g = D @ np.linalg.inv(F)
    Ke = np.einsum("maj,mijkl,mbl->maibk", g, c, g) + np.einsum(
        "mab,ik->maibk", np.einsum("maj,mjl,mbl->mab", g, sig, g), eye3
    )
    Ke = ((J * V0)[:, None, None, None, None] * Ke).reshape(-1, 12, 12)
    return assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke)[1]


@pytest.mark.parametrize("uniaxial", [False, True])
def test_ogden_shear_terms_with_the_wrong_sign_are_named_and_a_scaled_shear_is_not(uniaxial):
    points, cells = box_mesh(2, jitter=0.0 if uniaxial else 0.2, seed=2)
    x = points @ np.diag([1.15, 0.93, 0.93]).T
    if not uniaxial:
        x = x + 0.04 * np.random.default_rng(2).standard_normal(points.shape)
    model = default_material("Ogden")
    split, f_o, K_o, s = mjed_split(model, points, cells, x)

    def found(shear):
        K = _ogden_stiffness(points, cells, x, model, shear)
        return shear_term_findings(model, split, K, K_o, DOUBLE.stiffness)

    right = _ogden_stiffness(points, cells, x, model, 1.0)
    assert abs(right - K_o).max() <= 1e-9 * abs(K_o).max()  # the engine itself is right
    named = found(-1.0)
    assert [f.code for f in named] == ["tangent-shear-sign"], [f.title for f in named]
    assert "wrong sign" in named[0].title
    assert (named[0].figures["turned_cells"] > 0) == uniaxial
    assert found(-0.9) == [] and found(0.0) == []


def _state(uniaxial):
    points, cells = box_mesh(2, jitter=0.0 if uniaxial else 0.2, seed=2)
    x = points @ np.diag([1.15, 0.93, 0.93]).T
    if not uniaxial:
        x = x + 0.04 * np.random.default_rng(2).standard_normal(points.shape)
    return points, cells, x


@pytest.mark.parametrize("uniaxial", [False, True])
def test_the_minus_two_tau_term_left_out_is_named_and_a_scaled_one_is_not(uniaxial):
    points, cells, x = _state(uniaxial)
    model = default_material("Ogden")
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    turn = np.random.default_rng(7) if uniaxial else None

    def found(sigma):
        K = _ogden_stiffness(points, cells, x, model, sigma=sigma, turn=turn)
        return stress_term_findings(model, split, K, K_o, DOUBLE.stiffness)

    # the engine written right is right whatever basis its eigen-solver picks in the plane
    right = _ogden_stiffness(points, cells, x, model, turn=turn)
    assert abs(right - K_o).max() <= 1e-9 * abs(K_o).max()
    named = found(0.0)
    assert [f.code for f in named] == ["tangent-spectral-stress-term"], [f.title for f in named]
    assert "left out" in named[0].title and "-2 sigma_a" in named[0].title
    assert (named[0].figures["turned_cells"] > 0) == uniaxial
    assert "sign flipped" in found(-1.0)[0].title
    assert found(0.7) == [] and found(1.0) == []


@pytest.mark.parametrize("uniaxial", [False, True])
def test_the_mean_term_left_out_is_named_with_its_mjed_twin_and_a_scaled_one_is_not(uniaxial):
    points, cells, x = _state(uniaxial)

    def found(model, mean):
        split, f_o, K_o, s = mjed_split(model, points, cells, x)
        K = _ogden_stiffness(points, cells, x, model, mean=mean)
        return split_part_findings(model, points, cells, x, f_o, K, f_o, K_o, s, DOUBLE)

    model = default_material("Ogden")
    assert model.alpha == 3.0
    (named,) = found(model, 0.0)
    assert "mean term" in named.title and "left out" in named.title
    # alpha = 3: MJED's J-J block of J^(-1) sum lambda^(3/2), halved, gives the same numbers
    assert "equally" in named.evidence and "J-J block" in named.evidence
    assert found(model, 0.6) == []
    # another alpha: the same slip; MJED's J-J block halved no longer gives it (its f'' with
    # another coefficient still does, and is said beside it)
    (other,) = found(dataclasses.replace(model, alpha=5.0), 0.0)
    assert "mean term" in other.title and "halved" not in other.evidence


@pytest.mark.parametrize("uniaxial", [False, True])
def test_the_shear_coefficients_mean_term_with_its_sign_lost_is_named(uniaxial):
    points, cells, x = _state(uniaxial)
    model = default_material("Ogden")
    split, f_o, K_o, s = mjed_split(model, points, cells, x)

    def found(shear_mean):
        K = _ogden_stiffness(points, cells, x, model, shear_mean=shear_mean)
        return shear_term_findings(model, split, K, K_o, DOUBLE.stiffness)

    named = found(-1.0)
    assert [f.code for f in named] == ["tangent-shear-mean-sign"], [f.title for f in named]
    assert found(0.5) == []
