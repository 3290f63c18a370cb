"""A UMAT driver's DDSDDE converted wrong (conformance.diagnosis.spatial_pieces, read through
hand_derived_reading): the engines are written here, vectorised, as such drivers are, for
St Venant-Kirchhoff in closed form: sigma = F S F^T / J, c = (lam b (x) b + 2 mu b (.) b) / J,
DDSDDE = c + the four Jaumann-rate terms, then a factor on DDSDDE and weights on the terms the
driver removes; MJED stands in for the oracle. Each mistake has a nearby one (a factor or a
weight that is no simple number) that must not get the cause.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh
from diagnosis_stubs import CaseStub, MjedCache, OutputStub

from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.findings import OBSERVED, Finding
from conformance.diagnosis.hand_derived import hand_derived_reading
from conformance.judge.compare import errors, scales
from conformance.judge.oracle import Reference

EYE = np.eye(3)
RIGHT = (-1.0, -1.0, -1.0, -1.0)


def _state(uniform=False):
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    x = points @ np.diag([1.1, 0.95, 0.97]).T
    if not uniform:
        x = points + 0.06 * np.random.default_rng(5).standard_normal(points.shape)
    return points, cells, x


def _packed(c):
    """C (m, 3, 3, 3, 3) through a Voigt DDSDDE: the entries of the slots (11, 22, 33, 12, 23,
    13) kept and spread to their minor-symmetric twins.
    """
    slots = [(0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2)]
    out = np.zeros_like(c)
    for i, j in slots:
        for k, ll in slots:
            for p, q in {(i, j), (j, i)}:
                for r, t in {(k, ll), (ll, k)}:
                    out[:, p, q, r, t] = c[:, i, j, k, ll]
    return out


def _engine(
    points, cells, x, scale=lambda J: 1.0, weights=RIGHT, dev=0.0, pressure=0.0, one_order=False
):
    """(f, K): c = scale(J) DDSDDE + sum_k weights_k T_k + dev T(s) + pressure p II, the T_k
    the four halved terms d_ik s_jl, s_ik d_jl, d_il s_jk, s_il d_jk, T(s) their sum for the
    deviatoric stress s, p = tr(sigma)/3 (the right: scale 1, weights -1, dev = pressure = 0);
    one_order: St Venant-Kirchhoff's b (.) b written b_ik b_jl and DDSDDE packed in Voigt form.
    """
    from mjed.mesh import shape_vectors

    model = default_material("StVenantKirchhoff")
    mu, lam = model.mu, model.lam
    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    J = np.linalg.det(F)
    b = F @ F.swapaxes(1, 2)
    E = 0.5 * (F.swapaxes(1, 2) @ F - EYE)
    trE = np.einsum("mii->m", E)
    S = lam * trE[:, None, None] * EYE + 2 * mu * E
    s = F @ S @ F.swapaxes(1, 2) / J[:, None, None]
    bb = 0.5 * (np.einsum("mik,mjl->mijkl", b, b) + np.einsum("mil,mjk->mijkl", b, b))
    if one_order:  # b_ik b_jl alone, packed into a Voigt DDSDDE
        bb = np.einsum("mik,mjl->mijkl", b, b)
    c = (lam * np.einsum("mij,mkl->mijkl", b, b) + 2 * mu * bb) / J[:, None, None, None, None]
    T = 0.5 * np.stack(
        [
            np.einsum("ik,mjl->mijkl", EYE, s),
            np.einsum("mik,jl->mijkl", s, EYE),
            np.einsum("il,mjk->mijkl", EYE, s),
            np.einsum("mil,jk->mijkl", s, EYE),
        ]
    )
    ddsdde = c + T.sum(axis=0)
    if one_order:
        ddsdde = _packed(ddsdde)
    c_e = np.asarray(scale(J))[..., None, None, None, None] * ddsdde
    c_e = c_e + np.einsum("q,qmijkl->mijkl", np.asarray(weights, dtype=float), T)
    p = np.einsum("mii->m", s) / 3.0
    sd = s - p[:, None, None] * EYE
    Td = 0.5 * (
        np.einsum("ik,mjl->mijkl", EYE, sd)
        + np.einsum("mik,jl->mijkl", sd, EYE)
        + np.einsum("il,mjk->mijkl", EYE, sd)
        + np.einsum("mil,jk->mijkl", sd, EYE)
    )
    II = 0.5 * (np.einsum("ik,jl->ijkl", EYE, EYE) + np.einsum("il,jk->ijkl", EYE, EYE))
    c_e = c_e + dev * Td + pressure * p[:, None, None, None, None] * II
    return _assemble(points, cells, D @ np.linalg.inv(F), J * np.abs(V0), s, c_e)


def _neo_engine(points, cells, x, weight=-1.0, two=2.0):
    """(f, K) of a Neo-Hookean engine written with c = lam/J I (x) I + two (mu + weight lam ln J)
    /J II (the right: weight -1, two 2).
    """
    from mjed.mesh import shape_vectors

    model = default_material("NeoHookean")
    mu, lam = model.mu, model.lam
    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    J = np.linalg.det(F)
    lnJ = np.log(J)[:, None, None]
    s = (mu * (F @ F.swapaxes(1, 2) - EYE) + lam * lnJ * EYE) / J[:, None, None]
    II = 0.5 * (np.einsum("ik,jl->ijkl", EYE, EYE) + np.einsum("il,jk->ijkl", EYE, EYE))
    k = (two * (mu + weight * lam * np.log(J)) / J)[:, None, None, None, None]
    c_e = (lam / J)[:, None, None, None, None] * np.einsum("ij,kl->ijkl", EYE, EYE) + k * II
    return _assemble(points, cells, D @ np.linalg.inv(F), J * np.abs(V0), s, c_e)


def _assemble(points, cells, g, v, s, c_e):
    """(f, K): f_a = -v s g_a, K_ab = v (g_a . c_e . g_b + (g_a . s g_b) I), summed."""
    fe = -np.einsum("m,mij,maj->mai", v, s, g)
    Ke = np.einsum("maj,mijkl,mbl->maibk", g, c_e, g)
    Ke = Ke + np.einsum("maj,mjl,mbl,ik->maibk", g, s, g, EYE)
    Ke = (v[:, None, None, None, None] * Ke).reshape(-1, 12, 12)
    n, m = points.shape[0], cells.shape[0]
    dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    f = np.zeros(3 * n)
    np.add.at(f, dof.ravel(), fe.reshape(-1))
    rows, cols = np.repeat(dof, 12, axis=1).ravel(), np.tile(dof, (1, 12)).ravel()
    K = sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(3 * n, 3 * n))
    return f.reshape(n, 3), K


def _causes(uniform=False, law="StVenantKirchhoff", **mistake):
    """The codes of the causes named for the engine of ``law`` with ``mistake``, and all the
    titles.
    """
    points, cells, x = _state(uniform)
    ci = CaseStub(points, cells, x, default_material(law))
    ref = MjedCache().reference(ci)
    engine = _engine if law == "StVenantKirchhoff" else _neo_engine
    f, K = engine(points, cells, x, **mistake)
    s = scales(0.5, 1.0, ref.force, ref.stiffness)
    e = errors(f, K, None, ref.force, ref.stiffness, 0.0, s)
    diag = Diagnosis("c", "failed", e, [Finding("unexplained", "unexplained", OBSERVED, "", {})])
    ref = Reference(0.0, ref.force, sp.csr_matrix(ref.stiffness))
    d = hand_derived_reading(diag, MjedCache(), ci, OutputStub(f, K), ref, s)
    return [c.code for c in d.causes], [c.title for c in d.findings]


@pytest.mark.parametrize("law", ["StVenantKirchhoff", "NeoHookean"])
def test_the_engine_written_right_is_the_oracle(law):
    points, cells, x = _state()
    ref = MjedCache().reference(CaseStub(points, cells, x, default_material(law)))
    f, K = (_engine if law == "StVenantKirchhoff" else _neo_engine)(points, cells, x)
    assert np.abs(f - ref.force).max() < 1e-9 * np.abs(ref.force).max()
    assert abs(K - ref.stiffness).max() < 1e-9 * abs(ref.stiffness).max()


def test_the_jaumann_terms_added_instead_of_removed_are_named_and_a_weight_off_is_not():
    codes, titles = _causes(weights=(1.0, 1.0, 1.0, 1.0))
    assert codes == ["spatial-tangent-pieces"], titles
    assert "added instead of removed" in titles[0] and "geometric stiffness" in titles[0]
    codes, titles = _causes(weights=(1.0, 1.0, 0.7, 1.0))  # no simple weight: nothing
    assert codes == [], titles


def test_two_of_the_four_terms_removed_are_named_as_such():
    codes, titles = _causes(weights=(-1.0, -1.0, 0.0, 0.0))
    assert codes == ["spatial-tangent-pieces"], titles
    assert "only d_ik s_jl/2, s_ik d_jl/2 removed" in titles[0], titles


def test_ddsdde_divided_by_j_again_or_left_in_mpa_is_named_and_a_plain_factor_is_not():
    codes, titles = _causes(scale=lambda J: 1.0 / J)
    assert codes == ["spatial-tangent-pieces"], titles
    assert "divided by J once more" in titles[0], titles
    codes, titles = _causes(scale=lambda J: 1e-6 + 0.0 * J)
    assert codes == ["spatial-tangent-pieces"] and "MPa" in titles[0], titles
    codes, titles = _causes(scale=lambda J: 0.9 + 0.0 * J)
    assert "spatial-tangent-pieces" not in codes, titles


def test_on_a_state_with_one_j_the_factor_is_said_as_both():
    codes, titles = _causes(uniform=True, scale=lambda J: 1.0 / J)
    assert codes == ["spatial-tangent-pieces"], titles
    assert "divided by J once more" in titles[0] and "equally the constant" in titles[0]


def test_one_isotropic_term_with_its_sign_flipped_is_named_and_another_weight_is_not():
    """Neo-Hookean's 2 (mu - lam ln J)/J II written with + lam ln J: the term -2 lam (ln J/J) II
    with its sign flipped; the weight -0.3 on lam ln J (no ratio of RATIOS) is not named; on a
    state with one J the functions of J coincide and nothing is named.
    """
    codes, titles = _causes(law="NeoHookean", weight=1.0)
    assert codes == ["spatial-isotropic-term"], titles
    assert "sign flipped" in titles[0] and "-2 lam (ln J / J) II" in titles[0], titles
    codes, titles = _causes(law="NeoHookean", weight=-0.3)
    assert "spatial-isotropic-term" not in codes, titles
    codes, titles = _causes(law="NeoHookean", weight=1.0, uniform=True)
    assert "spatial-isotropic-term" not in codes, titles


@pytest.mark.parametrize("uniform", [False, True])
def test_the_identity_term_with_its_factor_two_lost_is_named_on_any_state(uniform):
    """2 (mu - lam ln J)/J II written (mu - lam ln J)/J II: both of II's pieces halved, named as
    the II term halved where J varies and, the tensors still apart, where it does not.
    """
    codes, titles = _causes(law="NeoHookean", two=1.0, uniform=uniform)
    assert codes == ["spatial-isotropic-term"], titles
    assert "II term of the isotropic spatial tangent halved" in titles[0], titles
    codes, titles = _causes(law="NeoHookean", two=1.3, uniform=uniform)
    assert "spatial-isotropic-term" not in codes, titles


def test_the_deviatoric_or_the_pressure_rate_terms_taken_apart_are_named():
    """A UMAT that subtracts the deviatoric stress's Jaumann terms in DDSDDE (c - 2 T(s) after
    the conversion), or writes its volumetric DDSDDE in the Truesdell form (-2 p II twice); a
    weight off the simple numbers is not named.
    """
    codes, titles = _causes(dev=-2.0)
    assert codes == ["spatial-tangent-pieces"], titles
    assert "c - 2 T(s)" in titles[0] and "subtracted in DDSDDE" in titles[0], titles
    codes, titles = _causes(pressure=-2.0)
    assert codes == ["spatial-tangent-pieces"], titles
    assert "c - 2 p II" in titles[0] and "Truesdell form" in titles[0], titles
    codes, titles = _causes(dev=-0.7)
    assert codes == [], titles  # nor any other piece, a product among them


def test_ddsdde_times_j_is_said_times_j():
    codes, titles = _causes(scale=lambda J: J)
    assert codes == ["spatial-tangent-pieces"], titles
    assert "multiplied by J: times J where 1 belongs" in titles[0], titles


def test_a_product_written_with_one_index_order_and_packed_in_voigt_form_is_named():
    codes, titles = _causes(one_order=True)
    assert codes == ["spatial-unsymmetrised-product"], titles
    assert "b (.) b" in titles[0], titles
