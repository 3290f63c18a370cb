"""Hand-derived stress and tangent pieces (conformance.diagnosis.hand_derived and the modules it
reads: invariant_pieces, voigt_stress, spatial_tangent). The mistaken engines are built here
from MJED's element forces and matrices plus the closed-form change the mistake makes for
Mooney-Rivlin (W = c1 (I1b - 3) + c2 (I2b - 3) + U(J)), written out per cell.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh
from diagnosis_stubs import CaseStub as _Case
from diagnosis_stubs import MjedCache as _Cache
from diagnosis_stubs import OutputStub as _Out
from diagnosis_stubs import mjed_cell_stress

from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.hand_derived import hand_derived_reading
from conformance.diagnosis.spatial_tangent import spatial_factor_words
from conformance.judge.compare import DOUBLE, errors, scales
from conformance.judge.oracle import Reference

EYE = np.eye(3)


def _state(uniaxial: bool):
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    if uniaxial:
        return points, cells, points @ np.diag([1.25, 0.9, 0.9]).T
    return points, cells, points + 0.06 * np.random.default_rng(5).standard_normal(points.shape)


def _kin(points, cells, x):
    from mjed.mesh import shape_vectors

    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    return np.abs(V0), D, F


def _material(points, cells, x, dCC):
    """The assembled V0 sym(F^T grad v) : dCC : sym(F^T grad w) of per-cell dCC."""
    V0, D, F = _kin(points, cells, x)
    Ke = np.einsum("maI,mkJ,mJIML,mlM,mbL->makbl", D, F, dCC, F, D)
    Ke = (V0[:, None, None, None, None] * Ke).reshape(-1, 12, 12)
    return assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke)[1]


def _read(points, cells, x, f, K, f_o, K_o, model):
    ci = _Case(points, cells, x, model)
    s = scales(0.5, 1.0, f_o, K_o)
    e = errors(f, K, None, f_o, K_o, 0.0, s)
    diag = Diagnosis("c", "failed", e, [Finding("unexplained", "unexplained", OBSERVED, "", {})])
    ref = Reference(0.0, f_o, sp.csr_matrix(K_o))
    return hand_derived_reading(diag, _Cache(), ci, _Out(f, sp.csr_matrix(K)), ref, s)


def _oracle(points, cells, x, model):
    r = _Cache().reference(_Case(points, cells, x, model))
    return r.force, r.stiffness


def _mooney():
    return default_material("MooneyRivlin")


def _psi2(F, c2):
    """dW/dI2 of the c2 (I2b - 3) term: c2 J^(-4/3), per cell."""
    return c2 * np.linalg.det(F) ** (-4.0 / 3.0)


II = 0.5 * (np.einsum("ik,jl->ijkl", EYE, EYE) + np.einsum("il,jk->ijkl", EYE, EYE))


def _no_identity(points, cells, x, model, whole=False):
    """Mooney-Rivlin's tangent with d2I2/dC2 written I (x) I (whole: the term left out)."""
    f_o, K_o = _oracle(points, cells, x, model)
    F = _kin(points, cells, x)[2]
    psi2 = _psi2(F, model.c2)[:, None, None, None, None]
    h2 = np.einsum("ij,kl->ijkl", EYE, EYE) - II
    dCC = -4.0 * psi2 * h2 if whole else 4.0 * psi2 * II
    return f_o, (K_o + _material(points, cells, x, dCC)).tocsr(), f_o, K_o


def test_the_identity_term_of_d2i2_missing_is_named_in_random_and_uniaxial_states():
    model = _mooney()
    for uniaxial in (False, True):
        points, cells, x = _state(uniaxial)
        d = _read(points, cells, x, *_no_identity(points, cells, x, model), model)
        assert [f.code for f in d.causes] == ["derivative-d2I2-no-identity"], [
            f.title for f in d.findings
        ]
        assert "-II term of d2I2/dC2" in d.causes[0].title


def test_the_whole_d2i2_term_missing_is_not_named_as_its_identity_term():
    model = _mooney()
    points, cells, x = _state(False)
    d = _read(points, cells, x, *_no_identity(points, cells, x, model, whole=True), model)
    assert [f.code for f in d.causes] == ["derivative-d2I2-missing"], [f.title for f in d.findings]


def test_the_sign_of_d2i2s_identity_term_flipped_is_named_and_not_as_it_missing():
    """The tangent with b (x) b + b (.) b for b (x) b - b (.) b: twice the change of the -II
    term missing (whose own test above is the nearby mistake that must not get this cause).
    """
    model = _mooney()
    points, cells, x = _state(False)
    f_o, K_o = _oracle(points, cells, x, model)
    psi2 = _psi2(_kin(points, cells, x)[2], model.c2)[:, None, None, None, None]
    K = (K_o + _material(points, cells, x, 8.0 * psi2 * II)).tocsr()
    d = _read(points, cells, x, f_o, K, f_o, K_o, model)
    assert [f.code for f in d.causes] == ["derivative-d2I2-identity-sign"], [
        f.title for f in d.findings
    ]


def test_a_tangent_scaled_is_no_piece():
    model = _mooney()
    points, cells, x = _state(False)
    f_o, K_o = _oracle(points, cells, x, model)
    d = _read(points, cells, x, f_o, (1.01 * K_o).tocsr(), f_o, K_o, model)
    assert d.causes == [] and d.findings[0].code == "unexplained"


def test_voigt_shear_stresses_doubled_in_the_force_are_named_and_normal_ones_are_not():
    model = _mooney()
    points, cells, x = _state(False)
    f_o, K_o = _oracle(points, cells, x, model)
    V0, D, F = _kin(points, cells, x)
    S = mjed_cell_stress(points, cells, x, model)
    diag = np.einsum("mii->mi", S)[:, :, None] * EYE
    for extra, named in ((S - diag, True), (diag, False)):
        fe = -V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", F, extra, D)
        f = f_o + assemble(cells, points.shape[0], fe, None)[0]
        d = _read(points, cells, x, f, K_o, f_o, K_o, model)
        codes = [c.code for c in d.causes]
        assert codes == (["voigt-stress-shear"] if named else []), [c.title for c in d.findings]


def test_a_spatial_tangent_without_its_one_over_j_is_named_cell_by_cell():
    """K = geometric + J_c x material per cell is named; a factor that is not each cell's J
    (their mean) is not.
    """
    import mjed

    model = _mooney()
    points, cells, x = _state(False)
    f_o, K_o = _oracle(points, cells, x, model)
    V0, D, F = _kin(points, cells, x)
    J = np.linalg.det(F)
    S = mjed_cell_stress(points, cells, x, model)
    field = mjed.make_force_field(mjed.TetMesh(points, cells), model)
    Ke = np.asarray(field.element_stiffness(x))
    geo = np.einsum("maI,mIL,mbL,kl->makbl", D, S, D, EYE)
    geo = (V0[:, None, None, None, None] * geo).reshape(-1, 12, 12)
    zero = np.zeros((len(cells), 4, 3))
    for factor, named in ((J, True), (np.full_like(J, J.mean()), False)):
        Kf = assemble(cells, points.shape[0], zero, geo + factor[:, None, None] * (Ke - geo))[1]
        d = _read(points, cells, x, f_o, Kf, f_o, K_o, model)
        codes = [c.code for c in d.causes]
        assert codes == (["spatial-tangent-j"] if named else []), [c.title for c in d.findings]


def test_the_j_factor_of_a_single_j_state_is_said_only_when_it_is_j():
    J = np.full(5, 1.3)
    assert "1/J missing" in spatial_factor_words(1.3, J)
    assert "1/J applied twice" in spatial_factor_words(1 / 1.3, J)
    assert spatial_factor_words(1.31, J) is None
    assert spatial_factor_words(1.3, np.array([1.3, 1.2])) is None
    assert spatial_factor_words(1.0, np.full(3, 1.0)) is None


def test_uniaxial_kirchhoff_material_stiffness_is_not_said_scaled():
    """Through diagnose: a material stiffness J times the oracle's on a state with one J is
    said as the missing 1/J, not as a scaled part.
    """
    from conformance.diagnosis.diagnose import diagnose
    from conformance.judge.parts import PartsOracle

    model = _mooney()
    points, cells, x = _state(True)
    f_o, K_o = _oracle(points, cells, x, model)
    J = float(np.linalg.det(_kin(points, cells, x)[2])[0])
    parts = PartsOracle(points, cells, model).parts(x)
    G = parts["geometric"]
    K = (G + J * (K_o - G)).tocsr()
    s = scales(0.5, 1.0, f_o, K_o)
    d = diagnose(
        "c",
        f=f_o,
        K=K,
        W=None,
        f_o=f_o,
        K_o=K_o,
        W_o=0.0,
        s=s,
        points=points,
        cells=cells,
        x=x,
        parts=lambda: parts,
        tol=DOUBLE,
    )
    assert d.causes and "1/J missing in the spatial (Kirchhoff) tangent" in d.causes[0].title


def _probe_engine(points, cells, x, model, extra_of_S):
    """The engine's force at x: MJED's plus the force of extra_of_S(S) per cell."""
    f_o, _ = _oracle(points, cells, x, model)
    V0, D, F = _kin(points, cells, x)
    extra = extra_of_S(mjed_cell_stress(points, cells, x, model))
    fe = -V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", F, extra, D)
    return f_o + assemble(cells, points.shape[0], fe, None)[0]


def test_shear_stresses_doubled_are_named_at_the_probes_when_the_case_is_uniaxial():
    from conformance.diagnosis.hand_derived import nearby_force_reading

    model = _mooney()
    points, cells, x = _state(True)
    f_o, K_o = _oracle(points, cells, x, model)
    rng = np.random.default_rng(9)
    probes = [x + 1e-5 * rng.standard_normal(x.shape) for _ in range(2)]
    s = scales(0.5, 1.0, f_o, K_o)
    nearby = Finding(
        "force-wrong-nearby", "the force is wrong away from this state", OBSERVED, "", {}
    )
    diag = Diagnosis("c", "failed", errors(f_o, K_o, None, f_o, K_o, 0.0, s), [nearby])

    def shear(S):
        return S - np.einsum("mii->mi", S)[:, :, None] * EYE

    def normal(S):
        return np.einsum("mii->mi", S)[:, :, None] * EYE

    for extra, code in ((shear, "voigt-stress-shear"), (normal, "voigt-map")):
        results = [(p, _probe_engine(points, cells, p, model, extra), None) for p in probes]
        d = nearby_force_reading(diag, _Cache(), _Case(points, cells, x, model), results, s)
        codes = [c.code for c in d.causes]
        assert codes == [code], [c.title for c in d.findings]
        assert "probes near this state" in d.causes[0].evidence
    # the normal stresses doubled are not the shear family: named as the map they are, the
    # force alone compared at the probes
    assert np.array_equal(d.causes[0].figures["map"], np.diag([2, 2, 2, 1, 1, 1.0]))
    assert "force alone compared" in d.causes[0].evidence


def _neo_dj_without_j(points, cells, x, model, tangent: bool):
    """The compressible Neo-Hookean (W_J = (lam ln J - mu)/J, W_JJ = (mu + lam - lam ln J)/J^2,
    no cross derivatives) with dJ/dC = C^-1/2 for J/2 C^-1 in the stress (f and the geometric
    stiffness) and, with ``tangent``, in CC's W_JJ dJ (x) dJ; d2J/dC2 right.
    """
    f_o, K_o = _oracle(points, cells, x, model)
    V0, D, F = _kin(points, cells, x)
    J = np.linalg.det(F)
    Ci = np.linalg.inv(F.swapaxes(1, 2) @ F)
    WJ = (model.lam * np.log(J) - model.mu) / J
    WJJ = (model.mu + model.lam - model.lam * np.log(J)) / J**2
    g, gw = 0.5 * J[:, None, None] * Ci, 0.5 * Ci
    dS = 2.0 * WJ[:, None, None] * (gw - g)
    outer = lambda a: np.einsum("mij,mkl->mijkl", a, a)  # noqa: E731
    dCC = 4.0 * WJJ[:, None, None, None, None] * (outer(gw) - outer(g)) * tangent
    fe = -V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", F, dS, D)
    geo = np.einsum("maI,mIL,mbL,kl->makbl", D, dS, D, EYE)
    Ke = (V0[:, None, None, None, None] * geo).reshape(-1, 12, 12)
    df, dK = assemble(cells, points.shape[0], fe, Ke)
    K = K_o + dK + _material(points, cells, x, dCC)
    return f_o + df, sp.csr_matrix(K), f_o, K_o


def test_dj_dc_without_its_j_is_named_and_not_in_the_stress_alone():
    model = default_material("NeoHookean")
    for uniaxial in (False, True):
        points, cells, x = _state(uniaxial)
        d = _read(points, cells, x, *_neo_dj_without_j(points, cells, x, model, True), model)
        assert [f.code for f in d.causes] == ["derivative-dJ-without-J"], [
            f.title for f in d.findings
        ]
    d = _read(points, cells, x, *_neo_dj_without_j(points, cells, x, model, False), model)
    assert "derivative-dJ-without-J" not in [f.code for f in d.findings]


def _mooney_isochoric_derivatives(F, model):
    """Mooney-Rivlin's isochoric part c1 J^(-2/3) I1 + c2 J^(-4/3) I2 (the -3s are constants)
    as a function of (I1, I2, J): its gradient (m, 3) and Hessian (m, 3, 3), per cell, with
    C^-1 and the gradients g_a = dI_a/dC (m, 3, 3, 3).
    """
    C = F.swapaxes(1, 2) @ F
    J = np.linalg.det(F)
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    a, b = model.c1 * J ** (-2.0 / 3.0), model.c2 * J ** (-4.0 / 3.0)
    dW = np.stack([a, b, -2.0 / 3.0 * a * I1 / J - 4.0 / 3.0 * b * I2 / J], axis=1)
    d2W = np.zeros((J.size, 3, 3))
    d2W[:, 0, 2] = d2W[:, 2, 0] = -2.0 / 3.0 * a / J
    d2W[:, 1, 2] = d2W[:, 2, 1] = -4.0 / 3.0 * b / J
    d2W[:, 2, 2] = 10.0 / 9.0 * a * I1 / J**2 + 28.0 / 9.0 * b * I2 / J**2
    Ci = np.linalg.inv(C)
    eye = np.broadcast_to(EYE, C.shape)
    g = np.stack([eye, I1[:, None, None] * eye - C, 0.5 * J[:, None, None] * Ci], axis=1)
    return dW, d2W, g, J


def _stress_change(points, cells, x, dS):
    """The assembled force and geometric stiffness of a per-cell stress change dS (m, 3, 3)."""
    V0, D, F = _kin(points, cells, x)
    fe = -V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", F, dS, D)
    geo = np.einsum("maI,mIL,mbL,kl->makbl", D, dS, D, EYE)
    return assemble(
        cells, points.shape[0], fe, (V0[:, None, None, None, None] * geo).reshape(-1, 12, 12)
    )


def _mooney_hessian_scaled(points, cells, x, model, volumetric: bool):
    """Mooney-Rivlin's tangent with the Hessian part 4 W_ab g_a (x) g_b of its isochoric energy
    (with ``volumetric``: of the whole W, U'' g_J (x) g_J too) halved, as an engine whose
    jets over (I1, I2, J) are contracted with 2 where 4 belongs.
    """
    f_o, K_o = _oracle(points, cells, x, model)
    _, d2W, g, J = _mooney_isochoric_derivatives(_kin(points, cells, x)[2], model)
    if volumetric:
        d2W[:, 2, 2] += model.k0 * (1.0 - np.log(J)) / J**2
    hessian = 4.0 * np.einsum("mab,maij,mbkl->mijkl", d2W, g, g)
    return f_o, (K_o + _material(points, cells, x, -0.5 * hessian)).tocsr(), f_o, K_o


def test_a_hessian_part_halved_is_named_with_the_part_it_sits_in():
    model = _mooney()
    for uniaxial in (False, True):
        points, cells, x = _state(uniaxial)
        for volumetric, scope in ((False, "iso"), (True, "all")):
            case = _mooney_hessian_scaled(points, cells, x, model, volumetric)
            d = _read(points, cells, x, *case, model)
            assert [f.code for f in d.causes] == ["derivative-scaled-hessian"], [
                f.title for f in d.findings
            ]
            cause = d.causes[0]
            assert cause.figures["factor"] == 0.5 and cause.figures["scope"] == scope
            assert "Hessian part" in cause.title and "halved" in cause.title


def test_dj_dc_doubled_in_the_isochoric_chain_is_named_in_the_stress_and_the_tangent():
    """dJ/dC = J C^-1 (the 1/2 lost) where the isochoric energy's derivatives are contracted,
    the volumetric p J C^-1 right: the stress changes by 2 W_J g_J and the tangent's products
    with g_J double (the g_J (x) g_J one fourfold); d2J/dC2 right.
    """
    model = _mooney()
    for uniaxial in (False, True):
        points, cells, x = _state(uniaxial)
        f_o, K_o = _oracle(points, cells, x, model)
        dW, d2W, g, _ = _mooney_isochoric_derivatives(_kin(points, cells, x)[2], model)
        gw = g.copy()
        gw[:, 2] *= 2.0
        dS = 2.0 * dW[:, 2, None, None] * g[:, 2]
        hess = lambda G: 4.0 * np.einsum("mab,maij,mbkl->mijkl", d2W, G, G)  # noqa: E731
        df, dK = _stress_change(points, cells, x, dS)
        K = K_o + dK + _material(points, cells, x, hess(gw) - hess(g))
        d = _read(points, cells, x, f_o + df, sp.csr_matrix(K), f_o, K_o, model)
        assert [f.code for f in d.causes] == ["derivative-scaled-dI2"], [
            f.title for f in d.findings
        ]
        assert "J/2 C^-1" in d.causes[0].title and d.causes[0].figures["scope"] == "iso"
