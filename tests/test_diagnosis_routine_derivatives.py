"""A user routine's packed second derivatives taken wrongly by its driver (conformance.diagnosis.
routine_derivatives): the compressible Neo-Hookean law written as a UHYPER routine in
(I1b, J), W = mu/2 (J^(2/3) I1b - 3) - mu ln J + lam/2 (ln J)^2, whose second derivatives are
written out here by hand; the engine is MJED's stiffness plus the change a driver's slip makes,
4 V0 D A D with A = F dCC F formed here from the fourth-order tensor dCC. Against them: an entry
off by a factor not in the list, and a stiffness error that is no tangent slip.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import assemble
from conformance.diagnosis.routine_derivatives import (
    SLOTS,
    gradient_slip_findings,
    routine_derivative_findings,
    routine_hessians,
)
from conformance.judge.compare import DOUBLE
from mjed import materials as M

MU, LAM = 800.0, 4000.0


class _Out:
    def __init__(self, force, stiffness):
        self.force, self.stiffness = force, stiffness


@pytest.fixture(scope="module")
def case():
    points, cells = box_mesh(3, jitter=0.2, seed=3)
    rng = np.random.default_rng(3)
    x = points @ np.diag([1.15, 0.9, 0.97]).T + 0.02 * rng.standard_normal(points.shape)
    model = M.NeoHookean(mu=MU, lam=LAM)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, split, f_o, K_o, s


def _by_hand(F):
    """(U (3, 3, m) in (I1b, I2b, J), G (3, m, 3, 3) = dI/dC) of the Neo-Hookean routine."""
    C = F.swapaxes(1, 2) @ F
    J = np.linalg.det(F)
    I1 = np.trace(C, axis1=1, axis2=2)
    I1b = J ** (-2 / 3) * I1
    U = np.zeros((3, 3, J.size))
    U[0, 2] = U[2, 0] = MU / 3 * J ** (-1 / 3)
    U[2, 2] = -MU / 9 * J ** (-4 / 3) * I1b + MU / J**2 + LAM * (1 - np.log(J)) / J**2
    Ci = np.linalg.inv(C)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    eye = np.eye(3)
    c = lambda a: a[:, None, None]  # noqa: E731
    G = np.stack(
        [
            c(J ** (-2 / 3)) * (eye - c(I1 / 3) * Ci),
            c(J ** (-4 / 3)) * (c(I1) * eye - C - c(2 / 3 * I2) * Ci),
            c(J / 2) * Ci,
        ]
    )
    return U, G


def _engine(case, dU):
    """MJED's force and stiffness plus the tangent change 4 sum_ab dU_ab G_a (x) G_b."""
    _, split, f_o, K_o, _ = case
    _, G = _by_hand(split.F)
    dCC = 4 * np.einsum("abm,amij,bmkl->mijkl", dU, G, G)
    A = np.einsum("miI,mIJKL,mkK->miJkL", split.F, dCC, split.F)
    Ke = split.V0[:, None, None, None, None] * np.einsum(
        "maJ,miJkL,mbL->maibk", split.D, A, split.D
    )
    m = split.cells.shape[0]
    _, dK = assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))
    return _Out(f_o, sp.csr_matrix(K_o) + dK)


def _read(case, out):
    model, split, f_o, K_o, s = case
    return routine_derivative_findings(split, model, out, f_o, K_o, s, DOUBLE)


def test_the_declared_second_derivatives_are_the_routines(case):
    U, _ = _by_hand(case[1].F)
    got = routine_hessians(case[0], case[1].F)
    for t, (a, b) in enumerate(SLOTS):
        assert np.allclose(got[t], U[a, b], rtol=1e-10, atol=1e-9 * np.abs(U).max())


def test_the_mixed_slots_exchanged_are_named(case):
    U, _ = _by_hand(case[1].F)
    dU = np.zeros_like(U)
    dU[0, 2] = dU[2, 0] = -U[0, 2]  # d2U/dI1b dJ read into d2U/dI2b dJ's slot
    dU[1, 2] = dU[2, 1] = U[0, 2]
    (f,) = _read(case, _engine(case, dU))
    assert f.code == "routine-second-derivative"
    assert "d2U/dI1b dJ used as d2U/dI2b dJ" in f.title


def test_a_doubled_entry_and_a_mixed_term_counted_once_are_named(case):
    U, _ = _by_hand(case[1].F)
    dU = np.zeros_like(U)
    dU[0, 2] = dU[2, 0] = U[0, 2]
    (f,) = _read(case, _engine(case, dU))
    assert "d2U/dI1b dJ doubled" in f.title
    once = np.zeros_like(U)
    once[2, 0] = -U[2, 0]  # dI1b/dC (x) dJ/dC only
    (f,) = _read(case, _engine(case, once))
    assert "counted once" in f.title and "major symmetry" in f.title


def test_other_factors_and_other_errors_are_not_named(case):
    U, _ = _by_hand(case[1].F)
    dU = np.zeros_like(U)
    dU[2, 2] = 0.3 * U[2, 2]  # d2U/dJ2 x 1.3: no slip of the list
    assert _read(case, _engine(case, dU)) == []
    _, split, f_o, K_o, _ = case
    noise = sp.random(K_o.shape[0], K_o.shape[1], density=0.01, random_state=1)
    out = _Out(f_o, sp.csr_matrix(K_o) + 1e-3 * abs(K_o).max() * (noise + noise.T))
    assert _read(case, out) == []


def _engine_cc(case, dCC):
    """MJED's force and stiffness plus the material tangent change dCC (m, 3, 3, 3, 3)."""
    _, split, f_o, K_o, _ = case
    A = np.einsum("miI,mIJKL,mkK->miJkL", split.F, dCC, split.F)
    Ke = split.V0[:, None, None, None, None] * np.einsum(
        "maJ,miJkL,mbL->maibk", split.D, A, split.D
    )
    m = split.cells.shape[0]
    _, dK = assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))
    return _Out(f_o, sp.csr_matrix(K_o) + dK)


def test_a_term_of_an_invariants_second_derivative_written_wrongly_is_named(case):
    """The Neo-Hookean routine's U_1 = mu/2 J^(2/3) and U_J by hand: d2I1b/dC2 without its
    term -1/3 J^(-2/3) C^-1 (x) I (the transpose of I (x) C^-1), and d2J/dC2 with
    + J/2 C^-1 (.) C^-1; an unlisted factor on that term is not named.
    """
    F = case[1].F
    C = F.swapaxes(1, 2) @ F
    Ci = np.linalg.inv(C)
    J = np.linalg.det(F)
    I1b = J ** (-2 / 3) * np.trace(C, axis1=1, axis2=2)
    U1 = MU / 2 * J ** (2 / 3)
    UJ = MU / 3 * J ** (-1 / 3) * I1b - MU / J + LAM * np.log(J) / J
    w = lambda x: x[:, None, None, None, None]  # noqa: E731
    dropped = -4 * w(U1) * (-1 / 3) * w(J ** (-2 / 3)) * np.einsum("mij,kl->mijkl", Ci, np.eye(3))
    (f,) = _read(case, _engine_cc(case, dropped))
    assert "C^-1 (x) I of d2I1b/dC2 left out" in f.title and "major symmetry" in f.title
    odot = 0.5 * (np.einsum("mik,mjl->mijkl", Ci, Ci) + np.einsum("mil,mjk->mijkl", Ci, Ci))
    flipped = 4 * w(UJ) * 2 * w(J / 2) * odot  # -J/2 C^-1 (.) C^-1 written +J/2
    (f,) = _read(case, _engine_cc(case, flipped))
    assert "-J/2 C^-1 (.) C^-1 of d2J/dC2 with its sign flipped" in f.title
    assert _read(case, _engine_cc(case, 0.4 * dropped)) == []


def test_a_term_of_an_invariants_gradient_written_wrongly_is_named_in_stress_and_tangent(case):
    """dI1b/dC's projection term -J^(-2/3) I1/3 C^-1 written with I1b for I1 (J^(-2/3) twice):
    S = 2 U_1 dI1b/dC and the tangent's products U_1J (dI1b (x) dJ + dJ (x) dI1b) change alike,
    the force wrong; the same term off in the stress only is not this slip.
    """
    _, split, f_o, K_o, _ = case
    F = split.F
    U, G = _by_hand(F)
    C = F.swapaxes(1, 2) @ F
    J = np.linalg.det(F)
    I1 = np.trace(C, axis1=1, axis2=2)
    U1 = MU / 2 * J ** (2 / 3)
    dG = (J ** (-2 / 3) - 1)[:, None, None] * (
        -(J ** (-2 / 3) * I1 / 3)[:, None, None] * np.linalg.inv(C)
    )
    dS = 2 * U1[:, None, None] * dG
    dCC = (
        4
        * U[0, 2][:, None, None, None, None]
        * (np.einsum("mij,mkl->mijkl", dG, G[2]) + np.einsum("mij,mkl->mijkl", G[2], dG))
    )

    def engine(with_tangent):
        A = np.einsum("miI,mIJKL,mkK->miJkL", F, dCC if with_tangent else 0 * dCC, F)
        A = A + np.einsum("ik,mJL->miJkL", np.eye(3), dS)
        Ke = np.einsum("maJ,miJkL,mbL->maibk", split.D, A, split.D)
        Ke = split.V0[:, None, None, None, None] * Ke
        fe = -split.V0[:, None, None] * np.einsum("mkI,maI->mak", F @ dS, split.D)
        m = split.cells.shape[0]
        df, dK = assemble(split.cells, split.n, fe, Ke.reshape(m, 12, 12))
        return _Out(f_o + df, sp.csr_matrix(K_o) + dK)

    model, split_, f_o_, K_o_, s = case
    found = gradient_slip_findings(split_, model, engine(True), f_o_, K_o_, s, DOUBLE)
    assert [f.code for f in found] == ["routine-gradient-term"], found
    assert "I1b put for I1" in found[0].title and "dI1b/dC" in found[0].title
    assert gradient_slip_findings(split_, model, engine(False), f_o_, K_o_, s, DOUBLE) == []


def test_st_venant_kirchhoff_is_read_through_its_invariant_form():
    """Declared in E's components, St Venant-Kirchhoff is read as lam/8 (I1 - 3)^2 +
    mu/4 (I1^2 - 2 I2 - 2 I1 + 3): its U_a give S = lam tr E I + 2 mu E back.
    """
    from conformance.diagnosis.routine_derivatives import routine_slopes

    model = M.StVenantKirchhoff(mu=500.0, lam=2000.0)
    F = np.eye(3) + 0.1 * np.random.default_rng(0).standard_normal((5, 3, 3))
    U = routine_slopes(model, F)
    C = F.swapaxes(1, 2) @ F
    E = 0.5 * (C - np.eye(3))
    S = 2000.0 * np.trace(E, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 1000.0 * E
    Ci = np.linalg.inv(C)
    J = np.linalg.det(F)[:, None, None]
    I1 = np.trace(C, axis1=1, axis2=2)[:, None, None]
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C)[:, None, None])
    G = (
        J ** (-2 / 3) * (np.eye(3) - I1 / 3 * Ci),
        J ** (-4 / 3) * (I1 * np.eye(3) - C - 2 / 3 * I2 * Ci),
        J / 2 * Ci,
    )
    got = 2 * sum(U[a][:, None, None] * G[a] for a in range(3))
    assert np.allclose(got, S, rtol=0, atol=1e-10 * np.abs(S).max())
