"""A material routine handed the wrong kinematics (conformance.diagnosis.routine_inputs): the
routine given F_bar = J^(-1/3) F, U, F^T or a frame corotated by the polar R of F, while the
driver's gradients and volume come from the true F; and the driver's gradients D F for D F^-1
(conformance.diagnosis.spatial_assembly). The engines are written here by hand: a Neo-Hookean
Cauchy stress and spatial tangent in closed form, or MJED on the case's own mesh with another
frame, assembled the updated-Lagrangian way.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import assemble
from conformance.diagnosis.routine_inputs import (
    polar,
    probe_force_findings,
    routine_input_findings,
)
from conformance.diagnosis.spatial_assembly import assembly_matches
from conformance.judge.compare import DOUBLE, errors
from mjed.materials import Costa, NeoHookean

MU, LAM = 3448.0, 31034.0
EYE = np.eye(3)


def _positions(seed=0, rotate=True):
    """(points, cells, x): a jittered cube stretched (and its nodes moved randomly: rotations)."""
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T
    if rotate:
        x = x + 0.05 * np.random.default_rng(seed).standard_normal(points.shape)
    return points, cells, x


def _case(seed=0, model=None, rotate=True):
    """(model, points, split, f_o, K_o, s) at :func:`_positions`."""
    points, cells, x = _positions(seed, rotate)
    model = NeoHookean(mu=MU, lam=LAM) if model is None else model
    return (model, points, *mjed_split(model, points, cells, x))


def _neo(F):
    """The Cauchy stress (m, 3, 3) and spatial tangent (m, 3, 3, 3, 3) of
    W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2.
    """
    J = np.linalg.det(F)
    b = F @ F.swapaxes(1, 2)
    lnJ = np.log(J)[:, None, None]
    sigma = (MU * (b - EYE) + LAM * lnJ * EYE) / J[:, None, None]
    II = 0.5 * (np.einsum("ik,jl->ijkl", EYE, EYE) + np.einsum("il,jk->ijkl", EYE, EYE))
    c = (
        LAM * np.einsum("ij,kl->ijkl", EYE, EYE)[None]
        + 2.0 * (MU - LAM * lnJ[..., None, None]) * II[None]
    ) / J[:, None, None, None, None]
    return sigma, c


def _ul_engine(split, sigma, c, g=None):
    """f_a = -v sigma g_a, K_ab = v (g_a . c . g_b + (g_a . sigma g_b) I), g = D F^-1 unless
    given, v = J V0 from the true F.
    """
    F = split.F
    g = split.D @ np.linalg.inv(F) if g is None else g
    v = np.linalg.det(F) * split.V0
    fe = -v[:, None, None] * np.einsum("mkp,map->mak", sigma, g)
    Ke = np.einsum("map,mkplq,mbq->makbl", g, c, g)
    Ke = Ke + np.einsum("map,mpq,mbq,kl->makbl", g, sigma, g, EYE)
    return assemble(
        split.cells, split.n, fe, (v[:, None, None, None, None] * Ke).reshape(-1, 12, 12)
    )


def _codes(found):
    return [x.code for x, _ in found]


def test_routine_handed_the_isochoric_F_is_named_not_f_bar_in_the_stress_alone():
    model, points, split, f_o, K_o, s = _case()
    # the closed form is the oracle's with the true F (the hand engine is sound)
    f1, K1 = _ul_engine(split, *_neo(split.F))
    assert DOUBLE.within(errors(f1, K1, None, f_o, K_o, 0.0, s), energy=False)
    Fbar = np.cbrt(np.linalg.det(split.F))[:, None, None] ** -1.0 * split.F
    f, K = _ul_engine(split, *_neo(Fbar))
    found = routine_input_findings(model, points, split, f, K, s, DOUBLE)
    assert _codes(found) == ["routine-input-isochoric-F"], found
    assert "J^(-1/3)" in found[0][0].title
    assert assembly_matches(split, f, K, s, DOUBLE) == []
    # nearby: F_bar in the stress, the true F in the tangent; and the oracle itself
    _, c = _neo(split.F)
    f2, K2 = _ul_engine(split, _neo(Fbar)[0], c)
    assert routine_input_findings(model, points, split, f2, K2, s, DOUBLE) == []
    assert routine_input_findings(model, points, split, f_o, K_o, s, DOUBLE) == []


def test_routine_handed_U_is_the_same_prediction_as_b_from_C_and_says_so():
    from conformance.diagnosis.routine_inputs import merge_same, spatial_parts
    from conformance.diagnosis.spatial_assembly import ASSEMBLY_VARIANTS, assemble_variant

    model, points, split, f_o, K_o, s = _case(1)
    _, U = polar(split.F)
    f, K = _ul_engine(split, *_neo(U))
    found = routine_input_findings(model, points, split, f, K, s, DOUBLE)
    assert set(_codes(found)) == {"routine-input-right-stretch", "routine-input-F-transposed"}
    (b_from_c,) = assembly_matches(split, f, K, s, DOUBLE)
    (v,) = [v for v in ASSEMBLY_VARIANTS if v.code == "b-from-C"]
    merged = merge_same([(b_from_c, assemble_variant(split, spatial_parts(split), v)), *found])
    assert [m.code for m in merged] == ["spatial-assembly-b-from-C"]
    assert "right stretch tensor U" in merged[0].title
    # nearby: U with the stress rotated back by R (the right engine) names nothing
    R, _ = polar(split.F)
    sig, c = _neo(U)
    sig = R @ sig @ R.swapaxes(1, 2)
    c = np.einsum("mia,mjb,mkc,mld,mabcd->mijkl", R, R, R, R, c)
    f2, K2 = _ul_engine(split, sig, c)
    assert routine_input_findings(model, points, split, f2, K2, s, DOUBLE) == []


def _costa(frame):
    return Costa(0.9, 3.0, 1.0, 0.3, 0.8, 0.2, 0.1, 0.5, frame=frame)


def _rotations(n, seed):
    R = np.linalg.qr(np.random.default_rng(seed).standard_normal((n, 3, 3)))[0]
    return R * np.sign(np.linalg.det(R))[:, None, None]


def _mjed(model, points, cells, x):
    import mjed

    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f, K = field.force_and_stiffness(x)
    return f, sp.csr_matrix(K)


def test_frame_corotated_by_the_polar_rotation_is_named_not_its_transpose():
    R0 = _rotations(48, 3)
    model, points, split, f_o, K_o, s = _case(2, _costa(R0))
    R, _ = polar(split.F)
    f, K = _mjed(_costa(R @ R0), *_positions(2))  # the frame R R0, held fixed
    found = routine_input_findings(model, points, split, f, K, s, DOUBLE)
    assert _codes(found) == ["routine-input-frame-corotated"], found
    # nearby: the frame rotated by R^T
    f2, K2 = _mjed(_costa(R.swapaxes(1, 2) @ R0), *_positions(2))
    assert routine_input_findings(model, points, split, f2, K2, s, DOUBLE) == []


def test_gradients_times_F_are_named_not_times_F_transposed():
    model, points, split, f_o, K_o, s = _case(3)
    sig, c = _neo(split.F)
    for code, g in (
        ("gradient-times-F", split.D @ split.F),
        ("gradient-times-F-transposed", split.D @ split.F.swapaxes(1, 2)),
    ):
        f, K = _ul_engine(split, sig, c, g)
        found = assembly_matches(split, f, K, s, DOUBLE)
        assert [x.code for x in found] == [f"spatial-assembly-{code}"], found


def test_probe_forces_name_the_routine_input_a_rotation_free_state_hides():
    """On a stretch without rotation the U engine is right; at a rotated probe near it, its
    force is R^T sigma R assembled: the probe reading names it (merged with b from C), and an
    engine right at the probe gets nothing.
    """
    model, points, split, f_o, K_o, s = _case(4, rotate=False)
    f, K = _ul_engine(split, *_neo(polar(split.F)[1]))
    assert DOUBLE.within(errors(f, K, None, f_o, K_o, 0.0, s), energy=False)  # right here
    rng = np.random.default_rng(5)
    probe = _positions(4, rotate=False)[2] + 0.02 * rng.standard_normal(points.shape)
    psplit, pf_o, pK_o, _ = mjed_split(model, points, split.cells, probe)
    pf, _ = _ul_engine(psplit, *_neo(polar(psplit.F)[1]))

    def matches(fv, K, engine=pf):
        scale = s.force
        if np.linalg.norm(fv - pf_o) / scale <= DOUBLE.force:
            return float("inf")
        e = np.linalg.norm(engine - fv) / scale
        return e if e <= DOUBLE.force else float("inf")

    found = probe_force_findings(model, points, psplit, matches)
    assert [x.code for x in found] == ["spatial-assembly-b-from-C"], found
    assert "routine-input-right-stretch" in found[0].figures["same_as"]
    assert probe_force_findings(model, points, psplit, lambda fv, K: matches(fv, K, pf_o)) == []
