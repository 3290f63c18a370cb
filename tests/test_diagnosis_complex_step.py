"""A Voigt material tangent by the complex step or central differences of S with too large a
step, and a relative step's divisor slip (conformance.diagnosis.complex_step). Each engine is a
small Neo-Hookean engine of this module's own (S(C) in closed form, complex-safe; its Voigt
tangent numerical), checked against MJED as the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import mjed_split, stretched_state

from conformance.diagnosis.complex_step import (
    divisor_findings,
    fit_second_order_steps,
    strain_curvatures,
)
from conformance.diagnosis.elements import assemble, cell_kinematics
from conformance.judge.compare import DOUBLE
from mjed.materials import NeoHookean

MU, LAM = 3448.0, 31034.0
EYE = np.eye(3)
PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))


def _stress(C):
    """S (m, 3, 3) of W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 as a function of C (complex
    entries allowed).
    """
    Ci = np.linalg.inv(C)
    lnJ = 0.5 * np.log(np.linalg.det(C))
    return MU * (EYE - Ci) + LAM * lnJ[:, None, None] * Ci


def _unit(B):
    e = np.zeros((3, 3))
    i, j = PAIRS[B]
    e[i, j] = e[j, i] = 1.0
    return e


def _voigt_tangent(C, scheme, h, where):
    """(m, 6, 6) D = dS/dE (engineering shears) column by column: ``scheme`` "complex" or
    "central", step h in each component of C ("C": a shear's C_IJ and C_JI together) or of E
    ("E": engineering; C moves by 2 h for a normal, h for a shear's pair).
    """
    D = np.empty((C.shape[0], 6, 6))
    for B in range(6):
        i, j = PAIRS[B]
        dC = _unit(B) * (1.0 if where == "C" or i != j else 2.0)  # C per unit of the step
        # dS/dE_B = dS/dC . dC/dE_B: a unit C step of a normal component is half a unit of E,
        # of a shear pair one unit of gamma
        per_e = 2.0 if (where == "C" and i == j) else 1.0
        if scheme == "complex":
            col = np.imag(_stress(C + 1j * h * dC)) / h
        else:
            col = (_stress(C + h * dC) - _stress(C - h * dC)) / (2.0 * h)
        D[:, :, B] = per_e * np.stack([col[:, p, q] for p, q in PAIRS], axis=1)
    return D


def _engine(points, cells, x, D_of):
    """Force and stiffness with the Voigt tangent D_of(C) (m, 6, 6)."""
    V, G, F = cell_kinematics(points, cells, x)
    C = np.swapaxes(F, 1, 2) @ F
    S = _stress(C)
    Dv = D_of(C)
    CC = np.zeros((len(cells), 3, 3, 3, 3))
    for A, (i, j) in enumerate(PAIRS):
        for B, (k, ll) in enumerate(PAIRS):
            for p, q in {(i, j), (j, i)}:
                for r, s in {(k, ll), (ll, k)}:
                    CC[:, p, q, r, s] = Dv[:, A, B]
    Amat = np.einsum("ik,mJL->miJkL", EYE, S) + np.einsum("miI,mIJKL,mkK->miJkL", F, CC, F)
    fe = -V[:, None, None] * np.einsum("miJ,maJ->mai", F @ S, G)
    Ke = V[:, None, None, None, None] * np.einsum("maJ,miJkL,mbL->maibk", G, Amat, G)
    return assemble(cells, len(points), fe, Ke.reshape(-1, 12, 12))


def _case(D_of, uniaxial=False):
    points, cells, x = stretched_state(0, uniaxial)
    model = NeoHookean(mu=MU, lam=LAM)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    f, K = _engine(points, cells, x, D_of)
    return model, points, split, f, K, f_o, K_o, s


@pytest.mark.parametrize(
    "scheme, where, h, named",
    [("complex", "C", 1e-2, "complex step"), ("central", "E", 5e-3, "central")],
)
def test_a_large_step_is_fitted_with_its_scheme_convention_and_size(scheme, where, h, named):
    model, points, split, f, K, f_o, K_o, s = _case(lambda C: _voigt_tangent(C, scheme, h, where))
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max()
    assert abs(K - K_o).max() > 1e-7 * abs(K_o).max()  # the step shows
    curvature = strain_curvatures(model, split, points)
    fits = fit_second_order_steps(split, curvature, (K - K_o).tocsr(), K_o)
    best = fits[0]
    assert best.scheme == named and best.convention == where, fits
    assert best.explained > 0.99 and abs(best.step / h - 1.0) < 0.02, fits


def test_the_complex_step_at_a_tiny_step_is_exact_and_no_truncation_is_fitted():
    model, points, split, f, K, f_o, K_o, s = _case(
        lambda C: _voigt_tangent(C, "complex", 1e-30, "C")
    )
    assert abs(K - K_o).max() <= 1e-10 * abs(K_o).max()
    curvature = strain_curvatures(model, split, points)
    fits = fit_second_order_steps(split, curvature, (K - K_o).tocsr(), K_o)
    assert all(fit.explained < 0.99 for fit in fits), fits


def test_a_relative_step_divided_by_the_absolute_one_is_named_and_the_exact_tangent_is_not():
    exact = lambda C: _voigt_tangent(C, "complex", 1e-30, "C")  # noqa: E731

    def scaled(C):
        comp = np.abs(np.stack([C[:, i, j] for i, j in PAIRS], axis=1))
        return exact(C) * np.maximum(comp, 1.0)[:, None, :]

    model, points, split, f, K, f_o, K_o, s = _case(scaled)
    found = divisor_findings(split, f, K, f_o, K_o, s, DOUBLE)
    assert [x.code for x in found] == ["tangent-step-scaled-not-divided"], found
    model, points, split, f, K, f_o, K_o, s = _case(exact)
    assert divisor_findings(split, f, K, f_o, K_o, s, DOUBLE) == []
