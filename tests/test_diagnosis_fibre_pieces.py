"""A fibre-frame routine's results rotated back wrongly (conformance.diagnosis.fibre_pieces):
Costa's dQ/dC and d2Q/dCdC computed in the frame and rotated back with R^T (.) R, or not at
all, the strain taken into the frame rightly. The engine is Costa written out here by hand
(total-Lagrangian: f_a = -V0 F S D_a, K_ab = V0 (D_a F CC F D_b + D_a S D_b I)).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import assemble, cell_piola
from conformance.diagnosis.fibre_pieces import fibre_piece_findings
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.judge.compare import DOUBLE, errors
from mjed.materials import Costa

A, K0, BS = 0.9, 3.0, (1.0, 0.3, 0.8, 0.2, 0.1, 0.5)  # b_ff, b_fs, b_ss, b_fn, b_sn, b_nn
EYE = np.eye(3)


def _rotations(n, seed):
    R = np.linalg.qr(np.random.default_rng(seed).standard_normal((n, 3, 3)))[0]
    return R * np.sign(np.linalg.det(R))[:, None, None]


def _dyad(a, b):
    return np.einsum("mij,mkl->mijkl", a, b)


def _strain_form(split, R):
    """Costa's B (3, 3), and per cell F, J, C^-1, the frame strain Ef = R^T E R, Q = B : Ef^2
    and the frame tangent T_f (3, 3, 3, 3) of Q / 4.
    """
    bff, bfs, bss, bfn, bsn, bnn = BS
    B = np.array([[bff, bfs, bfn], [bfs, bss, bsn], [bfn, bsn, bnn]])
    F = split.F
    C = F.swapaxes(1, 2) @ F
    Ef = np.einsum("mai,mab,mbj->mij", R, 0.5 * (C - EYE), R)
    Tf = 0.25 * (
        np.einsum("ab,ac,bd->abcd", B, EYE, EYE) + np.einsum("ab,ad,bc->abcd", B, EYE, EYE)
    )
    Q = np.einsum("ij,mij->m", B, Ef * Ef)
    return B, F, np.linalg.det(F), np.linalg.inv(C), Ef, Q, Tf


def _assembled(split, S, CC):
    """f_a = -V0 F S D_a, K_ab = V0 (D_a F CC F D_b + D_a S D_b I), assembled."""
    V0, D, F = split.V0, split.D, split.F
    fe = -V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", F, S, D)
    mat = np.einsum("maI,mkJ,mJIML,mlM,mbL->makbl", D, F, CC, F, D)
    geo = np.einsum("maI,mIL,mbL,kl->makbl", D, S, D, EYE)
    Ke = (V0[:, None, None, None, None] * (mat + geo)).reshape(-1, 12, 12)
    return assemble(split.cells, split.n, fe, Ke)


def _costa_engine(split, R, back, push=None):
    """Force and stiffness of Costa with dQ/dC, d2Q/dCdC rotated back by ``back`` ("right":
    R X R^T; "transposed": R^T X R; "none": X); push: "covectors" (a spatial engine's frame
    a_i = F^-T r_i: pulled back, C^-1 R), "normalised" (a_i = F r_i / |F r_i|: R / |F r_i|).
    """
    B, F, J, Ci, Ef, Q, Tf = _strain_form(split, R)
    Tf = np.broadcast_to(Tf, (J.size, 3, 3, 3, 3))
    if push is not None:
        if push == "covectors":
            Rp = Ci @ R
        else:
            stretch = np.linalg.norm(F @ R, axis=1)  # |F r_i| per column
            Rp = R / stretch[:, None, :]
        H = Rp @ (B * Ef) @ Rp.swapaxes(1, 2)
        dH = np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", Rp, Rp, Rp, Rp, Tf)
    elif back == "right":
        H = R @ (B * Ef) @ R.swapaxes(1, 2)
        dH = np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", R, R, R, R, Tf)
    elif back == "transposed":
        H = R.swapaxes(1, 2) @ (B * Ef) @ R
        dH = np.einsum("mai,mbj,mck,mdl,mabcd->mijkl", R, R, R, R, Tf)
    else:
        H, dH = B * Ef, np.array(Tf)
    j43 = (J ** (-4.0 / 3.0))[:, None, None]
    e = np.exp(j43[:, 0, 0] * Q)[:, None, None]
    Qs = Q[:, None, None, None, None]
    G = j43 * (H - (2.0 / 3.0) * Q[:, None, None] * Ci)
    odot = 0.5 * (np.einsum("mik,mjl->mijkl", Ci, Ci) + np.einsum("mil,mjk->mijkl", Ci, Ci))
    d2 = -(2.0 / 3.0) * (_dyad(H, Ci) + _dyad(Ci, H)) + (4.0 / 9.0) * Qs * _dyad(Ci, Ci)
    d2 = j43[..., None, None] * (d2 + (2.0 / 3.0) * Qs * odot + dH)
    lnJ = np.log(J)[:, None, None]
    S = A * e * G + K0 * J[:, None, None] * lnJ * Ci
    CC = 2.0 * A * e[..., None, None] * (_dyad(G, G) + d2)
    Jv = J[:, None, None, None, None]
    CC = (
        CC
        + K0 * Jv * (lnJ[..., None, None] + 1.0) * _dyad(Ci, Ci)
        - 2.0 * K0 * Jv * lnJ[..., None, None] * odot
    )
    return _assembled(split, S, CC)


def _case(seed):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T + 0.05 * rng.standard_normal(points.shape)
    R = _rotations(cells.shape[0], seed + 10)
    model = Costa(A, K0, *BS, frame=R)
    return model, R, points, cells, x, *mjed_split(model, points, cells, x)


def _found(split, model, f, K, f_o, K_o, s):
    def matches(fp, Kp):
        if DOUBLE.within(errors(fp, Kp, None, f_o, K_o, 0.0, s), energy=False):
            return float("inf")
        e = errors(f, sp.csr_matrix(K), None, fp, Kp, 0.0, s)
        return max(e.force, e.stiffness) if DOUBLE.within(e, energy=False) else float("inf")

    t = cell_tensors(*cell_piola(split), split.F)
    return [x.code for x in fibre_piece_findings(split, t, model, matches)]


def test_results_rotated_back_with_the_transpose_or_not_at_all_are_told_apart():
    model, R, points, cells, x, split, f_o, K_o, s = _case(0)
    f, K = _costa_engine(split, R, "right")  # the hand engine is the oracle's
    assert DOUBLE.within(errors(f, K, None, f_o, K_o, 0.0, s), energy=False)
    assert _found(split, model, f, K, f_o, K_o, s) == []
    for back, code in (("transposed", "transposed"), ("none", "not-rotated")):
        f, K = _costa_engine(split, R, back)
        assert _found(split, model, f, K, f_o, K_o, s) == [f"fibre-rotated-back-{code}"]


def test_the_whole_frame_transposed_is_not_a_wrong_rotation_back():
    """R^T for R everywhere (the strain taken into the frame with it too): not this mistake."""
    import mjed

    model, R, points, cells, x, split, f_o, K_o, s = _case(1)
    wrong = Costa(A, K0, *BS, frame=np.ascontiguousarray(R.swapaxes(1, 2)))
    f, K = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), wrong).force_and_stiffness(x)
    assert _found(split, model, f, sp.csr_matrix(K), f_o, K_o, s) == []


def _cjet_mul(a, b):
    """Product of C-jets (value (m,), dW/dC (m, 3, 3), d2W/dCdC (m, 3, 3, 3, 3))."""
    v = a[0] * b[0]
    d = a[1] * b[0][:, None, None] + b[1] * a[0][:, None, None]
    cross = _dyad(a[1], b[1])
    v4, w4 = a[0][:, None, None, None, None], b[0][:, None, None, None, None]
    return v, d, a[2] * w4 + b[2] * v4 + cross + cross.transpose(0, 3, 4, 1, 2)


def _cjet_apply(f, f1, f2, a):
    """f(a) of a C-jet, given f and its derivatives f1, f2 at a's value."""
    d = f1[:, None, None] * a[1]
    return (
        f,
        d,
        f2[:, None, None, None, None] * _dyad(a[1], a[1]) + f1[:, None, None, None, None] * a[2],
    )


def _costa_jets(split, R, dJ_factor, stress_only=False):
    """Costa through C-jets (S = 2 dW/dC, CC = 4 d2W/dC2) with dJ/dC = J/2 C^-1 times
    dJ_factor (per cell) in J's jet, d2J/dC2 right; stress_only: the tangent from the right jet.
    """
    B, F, Jv, Ci, Ef, Qv, Tf = _strain_form(split, R)
    odot = 0.5 * (np.einsum("mik,mjl->mijkl", Ci, Ci) + np.einsum("mil,mjk->mijkl", Ci, Ci))
    J4 = Jv[:, None, None, None, None]
    dQ = R @ (B * Ef) @ R.swapaxes(1, 2)
    ddQ = np.einsum("mia,mjb,mkc,mld,abcd->mijkl", R, R, R, R, Tf)
    Q = (Qv, dQ, ddQ)

    def jets(factor):
        J = (
            Jv,
            factor[:, None, None] * 0.5 * Jv[:, None, None] * Ci,
            J4 * (0.25 * _dyad(Ci, Ci) - 0.5 * odot),
        )
        Jp = _cjet_apply(Jv ** (-4 / 3), -4 / 3 * Jv ** (-7 / 3), 28 / 9 * Jv ** (-10 / 3), J)
        u = _cjet_mul(Jp, Q)
        e = np.exp(u[0])
        iso = _cjet_apply(0.5 * A * (e - 1.0), 0.5 * A * e, 0.5 * A * e, u)
        lnJ = np.log(Jv)
        vol = _cjet_apply(K0 * (Jv * lnJ - Jv + 1.0), K0 * lnJ, K0 / Jv, J)
        return 2.0 * (iso[1] + vol[1]), 4.0 * (iso[2] + vol[2])

    S, CC = jets(dJ_factor)
    if stress_only:
        CC = jets(np.ones_like(Jv))[1]
    return _assembled(split, S, CC)


def test_dj_dc_without_its_j_in_the_c_jets_is_named_and_not_in_the_stress_alone():
    """dJ/dC written C^-1/2 in J's jet (the stress and the tangent's chain-rule products take
    it, d2J/dC2 right) is named; the nearby mistake, the stress alone so (the tangent right),
    is not.
    """
    model, R, points, cells, x, split, f_o, K_o, s = _case(2)
    J = np.linalg.det(split.F)
    f, K = _costa_jets(split, R, np.ones_like(J))  # the jet engine is the oracle's
    assert DOUBLE.within(errors(f, K, None, f_o, K_o, 0.0, s), energy=False)
    f, K = _costa_jets(split, R, 1.0 / J)
    assert _found(split, model, f, K, f_o, K_o, s) == ["derivative-dJ-without-J"]
    f, K = _costa_jets(split, R, 1.0 / J, stress_only=True)
    assert _found(split, model, f, K, f_o, K_o, s) == []


def test_a_spatial_engines_frame_pushed_forward_wrongly_is_named():
    """a_i = F^-T r_i (covectors) or F r_i normalised, in F M F^T and the tangent's dyads, Q
    itself from R^T E R: each named as such, and not as the other.
    """
    model, R, points, cells, x, split, f_o, K_o, s = _case(2)
    for push in ("covectors", "normalised"):
        f, K = _costa_engine(split, R, "right", push=push)
        assert _found(split, model, f, K, f_o, K_o, s) == [f"fibre-pushed-{push}"], push
