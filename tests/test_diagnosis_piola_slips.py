"""The first Piola stress or its derivative A = dP/dF with an index or operand slip
(conformance.diagnosis.piola_slips), and differences of P with a step relative to each entry of
F (conformance.diagnosis.entry_steps). Each mistaken engine is a small St Venant-Kirchhoff engine
of this module's own in the graphics style (F = Ds Dm^-1, P = F S and A = delta S + F CC F in
closed form, or through numpy's SVD, or by central differences of P; f_a = -V P G_a,
K_ab = V G_a A G_b), checked against MJED as the oracle.
"""

from __future__ import annotations

import numpy as np
from conftest import mjed_split, stretched_state

from conformance.diagnosis.elements import assemble
from conformance.diagnosis.entry_steps import entry_step_findings
from conformance.diagnosis.piola_slips import slip_findings
from conformance.judge.compare import DOUBLE
from mjed.materials import StVenantKirchhoff

MU, LAM = 3448.0, 31034.0
EYE = np.eye(3)
MODEL = StVenantKirchhoff(mu=MU, lam=LAM)


def _edges(points, cells, x):
    """(Ds, Bm = Dm^-1, V0, G (m, 4, 3)) with edges from each cell's first node."""
    X, xx = points[cells], x[cells]
    Dm = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)
    Ds = np.swapaxes(xx[:, 1:] - xx[:, :1], 1, 2)
    Bm = np.linalg.inv(Dm)
    G = np.concatenate([-Bm.sum(axis=1, keepdims=True), Bm], axis=1)
    return Ds, Bm, np.abs(np.linalg.det(Dm)) / 6.0, G


def _piola(F):
    E = 0.5 * (np.swapaxes(F, 1, 2) @ F - EYE)
    S = LAM * np.trace(E, axis1=1, axis2=2)[:, None, None] * EYE + 2.0 * MU * E
    return F @ S


def _tangent(F):
    E = 0.5 * (np.swapaxes(F, 1, 2) @ F - EYE)
    S = LAM * np.trace(E, axis1=1, axis2=2)[:, None, None] * EYE + 2.0 * MU * E
    CC = LAM * np.einsum("IJ,KL->IJKL", EYE, EYE) + MU * (
        np.einsum("IK,JL->IJKL", EYE, EYE) + np.einsum("IL,JK->IJKL", EYE, EYE)
    )
    return np.einsum("ik,mJL->miJkL", EYE, S) + np.einsum("miI,IJKL,mkK->miJkL", F, CC, F)


def _differences(P_of, Z, h=1e-6, over=2.0, relative=False):
    """The derivative of P_of by Z (m, 3, 3, 3, 3): central differences divided by over h; with
    ``relative`` the step h max(|Z_kL|, eps) of each entry.
    """
    A = np.zeros(Z.shape + (3, 3))
    for k in range(3):
        for L in range(3):
            step = h * np.maximum(np.abs(Z[:, k, L]), np.finfo(float).eps) if relative else h
            step = np.broadcast_to(step, Z.shape[:1])
            Zp, Zm = Z.copy(), Z.copy()
            Zp[:, k, L] += step
            Zm[:, k, L] -= step
            A[:, :, :, k, L] = (P_of(Zp) - P_of(Zm)) / (over * step[:, None, None])
    return A


def _svd(F, vh_as_v=False):
    """The rotation-variant SVD (U, sigma, V; det U = det V = 1), numpy's Vh taken as V when
    ``vh_as_v``.
    """
    U, s, Vh = np.linalg.svd(F)
    V = Vh.copy() if vh_as_v else np.swapaxes(Vh, 1, 2).copy()
    U = U.copy()
    flip = np.linalg.det(U) < 0
    U[flip, :, 2] *= -1.0
    flip = np.linalg.det(V) < 0
    V[flip, :, 2] *= -1.0
    return U, V


def _engine(seed=0, uniaxial=False, P=None, A=None, F_of=None, svd=None):
    """(split, f, K, s): the oracle's split and an SVK engine's force and stiffness, with P(F),
    A(F, Ds, Bm) or F(Ds, Bm) replaced; svd: (vh_in_P, vh_in_A, rotation names) to go through
    the SVD basis.
    """
    points, cells, x = stretched_state(seed, uniaxial)
    split, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    Ds, Bm, V0, G = _edges(points, cells, x)
    F = (F_of or (lambda Ds, Bm: Ds @ Bm))(Ds, Bm)
    Pc = (P or _piola)(F)
    Ac = A(F, Ds, Bm) if A else _tangent(F)
    if svd is not None:
        vh_P, vh_A, names = svd
        U, V = _svd(F)
        Ph = np.swapaxes(U, 1, 2) @ Pc @ V
        Ah = np.einsum("mia,mJb,mkc,mLd,miJkL->mabcd", U, V, U, V, Ac)
        Ue, Ve = _svd(F, vh_as_v=True)
        if vh_P:
            Pc = Ue @ Ph @ np.swapaxes(Ve, 1, 2)
        R = {"U": Ue if vh_A else U, "V": Ve if vh_A else V}
        Ac = np.einsum("mia,mJb,mkc,mLd,mabcd->miJkL", *(R[n] for n in names), Ah)
    fe = -V0[:, None, None] * np.einsum("miJ,maJ->mai", Pc, G)
    Ke = V0[:, None, None, None, None] * np.einsum("maJ,miJkL,mbL->maibk", G, Ac, G)
    f, K = assemble(cells, len(points), fe, Ke.reshape(-1, 12, 12))
    return (points, split, f, K, s), (f_o, K_o)


def _found(case):
    points, split, f, K, s = case
    return slip_findings(MODEL, points)(split, f, K, s, DOUBLE)


def _codes(found):
    return [x.code for x in found]


def test_the_right_engine_and_a_plain_factor_name_nothing():
    case, (f_o, K_o) = _engine()
    points, split, f, K, s = case
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max()
    assert abs(K - K_o).max() <= 1e-9 * abs(K_o).max()
    assert _found(case) == []
    # the right tangent through the SVD basis is the right tangent
    assert _found(_engine(svd=(False, False, "UVUV"))[0]) == []


def test_numpy_vh_taken_as_v_is_named_and_in_the_stress_alone_is_its_own_slip():
    found = _found(_engine(svd=(True, True, "UVUV"))[0])
    assert _codes(found) == ["piola-slip-svd-vh"], found
    assert "Vh (= V^T) used as V" in found[0].title and found[0].strength == "explains"
    # nearby: only the stress built with Vh (the tangent rotated back right)
    assert _codes(_found(_engine(svd=(True, False, "UVUV"))[0])) == ["piola-slip-svd-vh-stress"]


def test_u_on_the_last_index_of_the_rotation_back_is_named_and_v_on_the_first_is_not_it():
    found = _found(_engine(svd=(False, False, "UVUU"))[0])
    assert _codes(found) == ["piola-slip-svd-rotation-L"], found
    assert "U_Ld" in found[0].title
    assert _codes(_found(_engine(svd=(False, False, "VVUV"))[0])) == ["piola-slip-svd-rotation-i"]


def test_column_major_flattening_is_named_and_one_index_pair_is_not_it():
    found = _found(_engine(A=lambda F, Ds, Bm: _tangent(F).transpose(0, 2, 1, 4, 3))[0])
    assert _codes(found) == ["piola-slip-vec-column-major"], found
    assert "column-major" in found[0].title
    found = _found(_engine(A=lambda F, Ds, Bm: _tangent(F).transpose(0, 1, 2, 4, 3))[0])
    assert _codes(found) == ["piola-slip-vec-column-major-columns"], found


def test_uniaxial_state_the_flattening_predicts_the_oracle_and_nothing_is_claimed():
    case, (f_o, K_o) = _engine(
        uniaxial=True, A=lambda F, Ds, Bm: _tangent(F).transpose(0, 2, 1, 4, 3)
    )
    assert abs(case[3] - K_o).max() <= 1e-9 * abs(K_o).max()
    assert _found(case) == []


def test_differences_in_ds_are_named_and_the_chain_factor_on_the_wrong_index_is_not_it():
    def in_Ds(F, Ds, Bm):
        return _differences(lambda Z: _piola(Z @ Bm), Ds)

    found = _found(_engine(A=in_Ds)[0])
    assert _codes(found) == ["piola-slip-derivative-in-Ds"], found
    assert "dP/dDs = dP/dF Dm^-T" in found[0].title
    # the same slip made analytically (nothing left): named in full
    found = _found(_engine(A=lambda F, Ds, Bm: np.einsum("miJkL,mlL->miJkl", _tangent(F), Bm))[0])
    assert _codes(found) == ["piola-slip-derivative-in-Ds"] and found[0].strength == "explains"
    # the analytic chain factor on the wrong index is another slip, named in full
    found = _found(_engine(A=lambda F, Ds, Bm: np.einsum("miJkL,mLl->miJkl", _tangent(F), Bm))[0])
    assert (
        _codes(found) == ["piola-slip-derivative-in-Ds-index"] and found[0].strength == "explains"
    )


def test_central_differences_over_h_are_named_by_their_noise_and_an_exact_factor_is_not():
    found = _found(_engine(A=lambda F, Ds, Bm: _differences(_piola, F, over=1.0))[0])
    assert _codes(found) == ["piola-slip-difference-over-h"], found
    assert found[0].strength == "partly explains" and "divided by h instead of 2h" in found[0].title
    assert found[0].figures["asymmetry"] >= 0.25
    # nearby: the analytic tangent doubled (symmetric, exact): not differences; the global
    # factor says it
    assert _found(_engine(A=lambda F, Ds, Bm: 2.0 * _tangent(F))[0]) == []
    # nearby: right differences (over 2h) predict the oracle: nothing
    assert _found(_engine(A=lambda F, Ds, Bm: _differences(_piola, F))[0]) == []


def test_f_formed_as_dm_inverse_ds_is_named_and_f_transposed_is_not_it():
    found = _found(_engine(F_of=lambda Ds, Bm: Bm @ Ds)[0])
    assert _codes(found) == ["piola-slip-F-product-reversed"], found
    assert "Dm^-1 Ds" in found[0].title and "x_a - x_0" in found[0].title
    # nearby: edges from the last node give another F'
    T = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -1.0, -1.0]])
    found = _found(_engine(F_of=lambda Ds, Bm: np.linalg.solve(T, Bm) @ Ds @ T)[0])
    assert _codes(found) == ["piola-slip-F-product-reversed-last"], found
    # nearby: F^T for F (a stress measure's family, P^T for an isotropic material): none here
    assert _found(_engine(F_of=lambda Ds, Bm: np.swapaxes(Ds @ Bm, 1, 2))[0]) == []


def _piola_svd(F):
    """P through the SVD, P = U diag(sigma_i S_i) V^T (S_i the principal SVK stresses): its
    entries sums of products that cancel, each with the round-off of |P|.
    """
    U, sig, Vh = np.linalg.svd(F)
    E = 0.5 * (sig**2 - 1.0)
    S = LAM * E.sum(axis=1, keepdims=True) + 2.0 * MU * E
    return np.einsum("mia,ma,maJ->miJ", U, sig * S, Vh)


def _entry_found(case):
    points, split, f, K, s = case
    return entry_step_findings(points)(split, f, K, s, DOUBLE)


def test_a_step_relative_to_each_entry_of_f_is_named_on_a_stretch_and_nothing_else_is():
    def relative(F, Ds, Bm):
        return _differences(_piola_svd, F, relative=True)

    found = _entry_found(_engine(uniaxial=True, A=relative)[0])
    assert _codes(found) == ["finite-difference-entry-steps"], found
    assert "relative to each entry of F" in found[0].title and "F_12" in found[0].title
    assert found[0].strength == "partly explains"
    # the random state's F has no zero entry: nothing read (and the slips name nothing either)
    case = _engine(A=relative)[0]
    assert _entry_found(case) == [] and _found(case) == []
    # nearby: a step of round-off size for every entry: the stretches' columns are noise too
    assert (
        _entry_found(
            _engine(uniaxial=True, A=lambda F, Ds, Bm: _differences(_piola_svd, F, 1e-13))[0]
        )
        == []
    )

    # nearby: the shear columns wrong by a formula, the same in every cell: not noise
    def shear_columns(F, Ds, Bm):
        A = _tangent(F)
        off = ~np.eye(3, dtype=bool)
        A[:, :, :, off] *= 1.5
        return A

    assert _entry_found(_engine(uniaxial=True, A=shear_columns)[0]) == []


def _tangent_geometric_paired_wrongly(F, Ds, Bm):
    E = 0.5 * (np.swapaxes(F, 1, 2) @ F - EYE)
    S = LAM * np.trace(E, axis1=1, axis2=2)[:, None, None] * EYE + 2.0 * MU * E
    return _tangent(F) - np.einsum("ik,mJL->miJkL", EYE, S) + np.einsum("iJ,mkL->miJkL", EYE, S)


def _tangent_minor_symmetrised(F, Ds, Bm):
    A = _tangent(F)
    half = 0.5 * (A + A.transpose(0, 2, 1, 3, 4))
    return 0.5 * (half + half.transpose(0, 1, 2, 4, 3))


def test_the_geometric_part_paired_wrongly_and_a_minor_symmetrised_tangent_are_named():
    found = _found(_engine(seed=2, A=_tangent_geometric_paired_wrongly)[0])
    assert _codes(found) == ["piola-slip-geometric-index-pairing"], [x.title for x in found]
    found = _found(_engine(seed=3, A=_tangent_minor_symmetrised)[0])
    assert _codes(found) == ["piola-slip-minor-symmetrised"], [x.title for x in found]
