"""MJED's chain-rule parts of the declared terms (conformance.diagnosis.mjed_parts).

The mistaken engines are written here, per cell, from mjed's declared f(J), g(C) and S of one
term and this file's own dJ_a = J F^-T D_a, F S D_a and einsums (not with the module's
functions); MJED stands in for the oracle. Each mistake comes with a nearby one that must not
get its cause: an energy with another parameter (force and stiffness changed consistently), the
part with another factor, the stiffness merely scaled.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.findings import PARTIAL
from conformance.diagnosis.mjed_parts import mjed_part_findings, mjed_parts
from conformance.judge.compare import DOUBLE
from mjed.kinematics import Kinematics
from mjed.materials.base import Material

MATERIALS = (
    "NeoHookean",
    "MooneyRivlin",
    "Yeoh",
    "ArrudaBoyce",
    "Gent",
    "VerondaWestmann",
    "Demiray",
    "Ogden",
    "StVenantKirchhoff",
    "Costa",
)


def _case(name, seed=0, stretch=(1.1, 0.95, 0.92), model=None):
    model = default_material(name) if model is None else model
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag(stretch).T + 0.03 * rng.standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, points, cells, x, split, f_o, K_o, s


def _term(split, model, g_index, t_index):
    """Per cell: J, dJ (m, 4, 3), F S D (m, 4, 3), f, f', f'', g and the group's factor
    c phi'(u) of term t of group g, from mjed's declared pieces.
    """
    F, D = split.F, split.D
    kin = Kinematics(F)
    J = np.linalg.det(F)
    dJ = J[:, None, None] * np.einsum("mji,maj->mai", np.linalg.inv(F), D)
    group = model.decomposition()[g_index]
    term = group.terms[t_index]
    m = len(J)
    f, f1, f2 = (np.broadcast_to(v, (m,)) for v in term.f(J))
    S = term.g.stress(kin)
    S = np.zeros((m, 3, 3)) if S is None else np.broadcast_to(S, (m, 3, 3))
    FSD = np.einsum("mij,mjk,mak->mai", F, S, D)
    g = np.broadcast_to(term.g.value(kin), (m,))
    w = np.full(m, group.coefficient)
    if not group.plain:
        u = sum(np.broadcast_to(t.f(J)[0] * t.g.value(kin), (m,)) for t in group.terms)
        w = group.coefficient * group.function(u)[1]
    return dict(J=J, dJ=dJ, FSD=FSD, f=f, f1=f1, f2=f2, g=g, w=w)


def _assembled(split, fe=None, Ke=None):
    """Per-cell force (m, 4, 3) and blocks (m, 4, 3, 4, 3), times V0, assembled."""
    m = split.cells.shape[0]
    fe = np.zeros((m, 4, 3)) if fe is None else fe
    Ke = np.zeros((m, 4, 3, 4, 3)) if Ke is None else Ke
    f, K = assemble(
        split.cells,
        split.n,
        split.V0[:, None, None] * fe,
        (split.V0[:, None, None, None, None] * Ke).reshape(m, 12, 12),
    )
    return f, K


def _find(model, points, cells, x, f, K, f_o, K_o, s, force_alone=False):
    return mjed_part_findings(model, points, cells, x, f, K, f_o, K_o, s, DOUBLE, force_alone)


@pytest.mark.parametrize("name", MATERIALS)
def test_the_parts_of_every_material_add_up_to_the_oracle(name):
    model, points, cells, x, _, f_o, K_o, _ = _case(name)
    parts = mjed_parts(model, points, cells, x, f_o, K_o)
    assert parts is not None and len(parts.terms) >= 1
    # a wrong oracle is not split: the parts must add up to it
    assert mjed_parts(model, points, cells, x, f_o, 1.001 * K_o) is None
    assert mjed_parts(model, points, cells, x, 1.001 * f_o, K_o) is None


def test_neo_hookean_force_j_part_sign_is_named_and_a_parameter_is_not():
    """The volumetric term's f'(J) dJ_a subtracted in the force (stiffness right): its sign."""
    model, points, cells, x, split, f_o, K_o, s = _case("NeoHookean")
    J = np.linalg.det(split.F)
    dJ = J[:, None, None] * np.einsum("mji,maj->mai", np.linalg.inv(split.F), split.D)
    psi = (model.lam * np.log(J) - model.mu) / J  # f' of -mu ln J + lam/2 (ln J)^2
    f_part, _ = _assembled(split, fe=psi[:, None, None] * dJ)
    f = f_o + 2.0 * f_part  # the oracle's force is -dW/dx: the J part added, not subtracted
    found = _find(model, points, cells, x, f, K_o, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "mjed-part" and found[0].figures["part"] == "force-J"
    assert "sign flipped" in found[0].title and "volumetric" in found[0].title
    # nearby: lam 1 % off in the energy (force and stiffness change consistently), and the J
    # part with 1.9 its value
    other = dataclasses.replace(model, lam=1.01 * model.lam)
    _, _, _, _, _, f_l, K_l, _ = _case("NeoHookean", model=other)
    assert _find(model, points, cells, x, f_l, K_l, f_o, K_o, s) == []
    assert _find(model, points, cells, x, f_o + 1.9 * f_part, K_o, f_o, K_o, s) == []


def test_demiray_cross_block_once_is_named_and_its_transpose_told_apart():
    """(F S D_a) dJ_b^T left out of the exponential term's cross blocks: K not symmetric."""
    model, points, cells, x, split, f_o, K_o, s = _case("Demiray", seed=1)
    t = _term(split, model, 0, 0)
    c = (t["w"] * t["f1"])[:, None, None, None, None]
    _, Kb = _assembled(split, Ke=c * np.einsum("mai,mbj->maibj", t["FSD"], t["dJ"]))
    _, Ka = _assembled(split, Ke=c * np.einsum("mai,mbj->maibj", t["dJ"], t["FSD"]))
    found = _find(model, points, cells, x, f_o, K_o - Kb, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert "cross block f'(J) (F S D_i) dJ_j^T" in found[0].title and "left out" in found[0].title
    # the other half written twice instead: the transposed-half reading, not "left out"
    found = _find(model, points, cells, x, f_o, K_o - Kb + Ka, f_o, K_o, s)
    assert len(found) == 1 and "written twice" in found[0].title, [x.title for x in found]
    # nearby: the half left out at 0.9, and parameter a 1 % off
    assert _find(model, points, cells, x, f_o, K_o - 0.9 * Kb, f_o, K_o, s) == []
    other = dataclasses.replace(model, a=1.01 * model.a)
    _, _, _, _, _, f_a, K_a, _ = _case("Demiray", seed=1, model=other)
    assert _find(model, points, cells, x, f_a, K_a, f_o, K_o, s) == []


def test_svk_material_block_half_left_out_is_named_and_mu_off_is_not():
    """SVK's gamma (F B D_b)(F B D_a)^T of mu H (B = Id) left out of SVK's material block."""
    model, points, cells, x, split, f_o, K_o, s = _case("StVenantKirchhoff", seed=2)
    FD = np.einsum("mij,maj->mai", split.F, split.D)
    _, Kh = _assembled(split, Ke=model.mu * np.einsum("mbi,maj->maibj", FD, FD))
    found = _find(model, points, cells, x, f_o, K_o - Kh, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert "material block's half" in found[0].title and "left out" in found[0].title
    other = dataclasses.replace(model, mu=1.01 * model.mu)
    _, _, _, _, _, f_m, K_m, _ = _case("StVenantKirchhoff", seed=2, model=other)
    assert _find(model, points, cells, x, f_m, K_m, f_o, K_o, s) == []
    assert _find(model, points, cells, x, f_o, 1.01 * K_o, f_o, K_o, s) == []


def _wrong_dfdj(split, model, factor):
    """VerondaWestmann's I2b term with f'(J) ``factor(J)`` times the right one (per cell):
    the engine-minus-right force and stiffness.
    """
    t = _term(split, model, 1, 0)
    d = factor(t["J"]) - 1.0  # engine minus right, per cell, in units of f'
    dJ, FSD, g, J = t["dJ"], t["FSD"], t["g"], t["J"]
    w = (t["w"] * t["f1"] * d)[:, None, None, None, None]
    anti = np.einsum("mai,mbj->maibj", dJ, dJ) - np.einsum("mbi,maj->maibj", dJ, dJ)
    Ke = w * (
        np.einsum("mai,mbj->maibj", dJ, FSD)
        + np.einsum("mai,mbj->maibj", FSD, dJ)
        + (g / J)[:, None, None, None, None] * anti
    )
    # the oracle's force is -dW/dx
    return _assembled(split, fe=-w[..., 0, 0] * g[:, None, None] * dJ, Ke=Ke)


def test_veronda_i2b_dfdj_copied_gets_its_power_of_j():
    """f'(J) of the I2b term written -2/3 J^(-5/3), copied from I1b: 1/2 J^(2/3) times the
    right -4/3 J^(-7/3), in the force and in every f'-block.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("VerondaWestmann", seed=3)
    df, dK = _wrong_dfdj(split, model, lambda J: 0.5 * J ** (2.0 / 3.0))
    found = _find(model, points, cells, x, f_o + df, K_o + dK, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "mjed-dfdj" and "I2b" in found[0].title
    assert "-2/3 J^(-5/3)" in found[0].title and "-4/3 J^(-7/3)" in found[0].title
    # nearby: the wrong f' in the force only (stiffness right), a per-cell factor that follows
    # no power of J, and c2 1 % off in the energy
    assert _find(model, points, cells, x, f_o + df, K_o, f_o, K_o, s) == []
    df2, dK2 = _wrong_dfdj(split, model, lambda J: 1.0 + 5.0 * (J - 1.0) ** 2)
    assert _find(model, points, cells, x, f_o + df2, K_o + dK2, f_o, K_o, s) == []
    other = dataclasses.replace(model, c2=1.01 * model.c2)
    _, _, _, _, _, f_c, K_c, _ = _case("VerondaWestmann", seed=3, model=other)
    assert _find(model, points, cells, x, f_c, K_c, f_o, K_o, s) == []


def test_veronda_regularised_jj_block_in_compressed_cells_is_named():
    """Every term's f'' g dJ_a dJ_b^T replaced by (1 - b) dJ_a dJ_b^T + b (dJ_a . dJ_b) Id."""
    model, points, cells, x, split, f_o, K_o, s = _case(
        "VerondaWestmann", seed=4, stretch=(0.9, 0.95, 0.97)
    )
    Ke = 0.0
    for gi, group in enumerate(model.decomposition()):
        for ti in range(len(group.terms)):
            t = _term(split, model, gi, ti)
            b = np.clip(1.0 - t["J"], 0.0, 1.0)
            dJ = t["dJ"]
            dd = np.einsum("mak,mbk,ij->maibj", dJ, dJ, np.eye(3))
            JJ = np.einsum("mai,mbj->maibj", dJ, dJ)
            Ke = Ke + (t["w"] * t["f2"] * t["g"] * b)[:, None, None, None, None] * (dd - JJ)
    _, dK = _assembled(split, Ke=Ke)
    found = _find(model, points, cells, x, f_o, K_o + dK, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert "regularised" in found[0].title and "every term" in found[0].title
    assert _find(model, points, cells, x, f_o, K_o + 0.5 * dK, f_o, K_o, s) == []


def test_silent_on_an_ogden_stiffness_with_noise_and_a_material_mjed_cannot_split():
    """No part explains noise on Ogden's stiffness; a model without terms is not read (None)."""
    model, points, cells, x, split, f_o, K_o, s = _case("Ogden", seed=5)
    rng = np.random.default_rng(0)
    noise = K_o.copy()
    noise.data = noise.data * (1.0 + 1e-3 * rng.standard_normal(noise.nnz))
    assert _find(model, points, cells, x, f_o, noise, f_o, K_o, s) == []

    class NoTerms:
        def decomposition(self):
            raise NotImplementedError

    assert _find(NoTerms(), points, cells, x, f_o, noise, f_o, K_o, s) is None


def test_demiray_gradient_j_part_sign_reaches_the_groups_rank_one_block():
    """Every term's f'(J) g dJ_a subtracted where the term's gradient is formed: the force, and
    the exponential group's c phi''(u) du_a du_b^T built from that gradient.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("Demiray", seed=6)
    t = _term(split, model, 0, 0)  # the term in a exp(b (I1b - 3))
    v = _term(split, model, 1, 0)  # the volumetric term
    a = (t["f1"] * t["g"])[:, None, None] * t["dJ"]  # the J part of the term's gradient
    du = a + t["f"][:, None, None] * t["FSD"]
    w2 = t["w"]  # phi'' = phi' for exp
    wrong = du - 2.0 * a
    outer = lambda p, q: np.einsum("mai,mbj->maibj", p, q)  # noqa: E731
    dK_e = w2[:, None, None, None, None] * (outer(wrong, wrong) - outer(du, du))
    fJ = t["w"][:, None, None] * a + (v["w"] * v["f1"] * v["g"])[:, None, None] * v["dJ"]
    df, dK = _assembled(split, fe=2.0 * fJ, Ke=dK_e)  # the oracle's force is -dW/dx
    found = _find(model, points, cells, x, f_o + df, K_o + dK, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert "every term with its sign flipped in the term's gradient" in found[0].title
    # the force alone (the group's block from a right gradient): the force-only reading
    found = _find(model, points, cells, x, f_o + df, K_o, f_o, K_o, s)
    assert len(found) == 1 and "gradient" not in found[0].title, [x.title for x in found]
    assert found[0].figures["part"] == "force-J" and found[0].figures["factor"] == -2.0
    # nearby: the block changed with half the wrong gradient: nothing predicts both; asked for
    # the force alone (the last reading), the force's part, partly
    assert _find(model, points, cells, x, f_o + df, K_o + 0.5 * dK, f_o, K_o, s) == []
    found = _find(model, points, cells, x, f_o + df, K_o + 0.5 * dK, f_o, K_o, s, True)
    assert len(found) == 1 and found[0].strength == PARTIAL, [x.title for x in found]
    assert "your stiffness is not this force's" in found[0].title


def test_dj_with_the_inverse_not_transposed_is_named_and_a_symmetric_f_leaves_it_silent():
    """dJ_a = J F^-1 D_a everywhere (NeoHookean, written out here): named on a general state;
    where F is symmetric (a stretch along the axes) F^-1 = F^-T and the engine is right.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("NeoHookean", seed=7)
    F, D = split.F, split.D
    J = np.linalg.det(F)
    Finv = np.linalg.inv(F)
    psi1 = (model.lam * np.log(J) - model.mu) / J  # f' of the volumetric term
    psi2 = (model.lam * (1.0 - np.log(J)) + model.mu) / J**2  # its f''

    def engine(dJ):
        c = (slice(None), None, None, None, None)
        JJ = np.einsum("mai,mbj->maibj", dJ, dJ)
        anti = JJ - np.einsum("mbi,maj->maibj", dJ, dJ)
        Ke = psi2[c] * JJ + (psi1 / J)[c] * anti
        return _assembled(split, fe=-psi1[:, None, None] * dJ, Ke=Ke)

    right = engine(J[:, None, None] * np.einsum("mji,maj->mai", Finv, D))
    wrong = engine(J[:, None, None] * np.einsum("mij,maj->mai", Finv, D))
    df, dK = wrong[0] - right[0], wrong[1] - right[1]
    found = _find(model, points, cells, x, f_o + df, K_o + dK, f_o, K_o, s)
    assert len(found) == 1 and found[0].code == "mjed-dj", [x.title for x in found]
    assert "J F^-1 D_i" in found[0].title
    # nearby: only the force built with it (the stiffness right): nothing predicts both; the
    # force's slip, partly, when the force alone is asked for
    assert _find(model, points, cells, x, f_o + df, K_o, f_o, K_o, s) == []
    found = _find(model, points, cells, x, f_o + df, K_o, f_o, K_o, s, True)
    assert len(found) == 1 and found[0].strength == PARTIAL, [x.title for x in found]
    assert "J F^-1 D_i" in found[0].title and "your stiffness is right" in found[0].title


class _Terms(Material):
    """A material given by its term groups (mjed computes it: the mistaken engine)."""

    def __init__(self, groups):
        self.groups = groups

    def decomposition(self):
        return self.groups


def _with_power(model, power):
    """MooneyRivlin with its I2b term given f = J^power."""
    from mjed.terms import JPower

    groups = list(model.decomposition())
    for i, g in enumerate(groups):
        terms = tuple(
            dataclasses.replace(t, f=JPower(power))
            if isinstance(t.f, JPower) and abs(t.f.p + 4.0 / 3.0) < 1e-12
            else t
            for t in g.terms
        )
        groups[i] = dataclasses.replace(g, terms=terms)
    return _Terms(tuple(groups))


def test_mooney_i2b_given_the_i1b_power_of_j_is_named_and_another_power_is_not():
    """The I2b term's f(J) written J^(-2/3), copied from the I1b term: the energy's formula
    changed (force and stiffness consistently), named as that copy, not as a block.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("MooneyRivlin", seed=8)
    _, _, _, _, _, f_w, K_w, _ = _case("MooneyRivlin", seed=8, model=_with_power(model, -2 / 3))
    found = _find(model, points, cells, x, f_w, K_w, f_o, K_o, s)
    assert len(found) == 1 and found[0].code == "mjed-f-power", [x.title for x in found]
    assert "I2b" in found[0].title and "J^(-2/3)" in found[0].title
    # nearby: J^(-1), the power of no term of the material
    _, _, _, _, _, f_n, K_n, _ = _case("MooneyRivlin", seed=8, model=_with_power(model, -1.0))
    assert _find(model, points, cells, x, f_n, K_n, f_o, K_o, s) == []


def test_a_term_integrated_over_the_deformed_volume_is_named_and_a_constant_factor_is_not():
    """Yeoh's volumetric term with its force and stiffness times J cell by cell (the pressure
    integrated over J V, corpus 6), the isochoric term right. Nearby: the same term times a
    constant (a parameter's value, another reading's) is not a volume.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("Yeoh")
    twice = dataclasses.replace(model, k0=2.0 * model.k0)
    _, _, _, _, split2, _, _, _ = _case("Yeoh", model=twice)
    J = np.linalg.det(split.F)
    fe, Ke = split2.fe - split.fe, split2.Ke - split.Ke  # the volumetric term, per cell

    def engine(w):
        df, dK = assemble(cells, points.shape[0], w[:, None, None] * fe, w[:, None, None] * Ke)
        return f_o + df, K_o + dK

    found = _find(model, points, cells, x, *engine(J - 1.0), f_o, K_o, s)
    assert [c.code for c in found] == ["mjed-term-volume"], [c.title for c in found]
    assert "deformed volume" in found[0].title and "(volumetric)" in found[0].title
    found = _find(model, points, cells, x, *engine(np.full(J.size, 0.3)), f_o, K_o, s)
    assert "mjed-term-volume" not in [c.code for c in found]


def test_f_prime_times_j_is_said_as_a_kirchhoff_pressure():
    """f'(J) of a volumetric term times J (corpus 7: k0 ln J, the Kirchhoff pressure, used as the
    Cauchy pressure): the words say so; a constant factor or another power does not.
    """
    from conformance.diagnosis.mjed_parts import _df_words

    assert "Kirchhoff pressure" in _df_words("k0/2 (ln J)^2", 1.0, 1.0, None)
    assert "divided by J once more" in _df_words("k0/2 (ln J)^2", 1.0, -1.0, None)
    assert "Kirchhoff" not in _df_words("k0/2 (ln J)^2", 2.0, 1.0, None)
    assert "Kirchhoff" not in _df_words("k0/2 (ln J)^2", 1.3, 0.0, None)
    assert "Kirchhoff" not in _df_words("k0/2 (ln J)^2", 1.0, 2.0 / 3.0, None)


def test_a_closed_form_tangent_with_the_inverse_paired_the_other_way_is_the_j_hessian():
    """A Neo-Hookean dP/dF written in closed form, A = mu I (x) I + lam F^-T (x) F^-T +
    (lam ln J - mu) d(F^-T)/dF, with d(F^-T)_iJ/dF_kL typed -F^-1_Ji F^-1_Lk (the pairing of the
    lam term copied) where -F^-1_Jk F^-1_Li belongs: the J-Hessian block left out, said both
    ways.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("NeoHookean", seed=3)
    F, D = split.F, split.D
    Fi = np.linalg.inv(F)
    c = model.lam * np.log(np.linalg.det(F)) - model.mu
    eye = np.eye(3)

    def stiffness(pairing):
        A = model.mu * np.einsum("ik,JL->iJkL", eye, eye)[None]
        A = A + model.lam * np.einsum("mJi,mLk->miJkL", Fi, Fi)
        A = A - c[:, None, None, None, None] * np.einsum(pairing, Fi, Fi)
        return _assembled(split, Ke=np.einsum("maJ,miJkL,mbL->maibk", D, A, D))[1]

    right = stiffness("mJk,mLi->miJkL")
    assert abs(right - K_o).max() < 1e-9 * abs(K_o).max()
    found = _find(model, points, cells, x, f_o, stiffness("mJi,mLk->miJkL"), f_o, K_o, s)
    assert [f.code for f in found] == ["j-hessian-block"], [f.title for f in found]
    assert "left out" in found[0].title and "-F^-1_Ji F^-1_Lk" in found[0].title


def test_a_force_part_halved_with_the_stiffness_its_derivative_is_named():
    """A Neo-Hookean P written mu/2 F + (lam ln J - mu) F^-T (the I1 term's stress halved),
    the element stiffness the complex step of that element force: the C part halved in the
    force and in the blocks derived from it.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("NeoHookean", seed=5)
    D, V0 = split.D, split.V0

    def element_forces(xe):
        F = np.einsum("mak,maI->mkI", xe, D)
        J = np.linalg.det(F)
        FiT = np.swapaxes(np.linalg.inv(F), 1, 2)
        P = model.mu / 2 * F + (model.lam * np.log(J) - model.mu)[:, None, None] * FiT
        return -V0[:, None, None] * np.einsum("mkI,maI->mak", P, D)

    xe = x[cells].astype(complex)
    m, h = len(cells), 1e-30
    Ke = np.zeros((m, 12, 12))
    for j in range(12):
        xp = xe.reshape(m, 12).copy()
        xp[:, j] += 1j * h
        Ke[:, :, j] = -(element_forces(xp.reshape(m, 4, 3)).imag / h).reshape(m, 12)
    f, K = assemble(cells, len(points), element_forces(xe).real, Ke)
    found = _find(model, points, cells, x, f, K, f_o, K_o, s)
    assert [x.code for x in found] == ["mjed-part-derived"], [x.title for x in found]
    assert found[0].figures["part"] == "force-C" and found[0].figures["factor"] == -0.5


def _with_j_part(split, f_o, tensor_of, monomial):
    """The oracle's force with the volumetric monomial ``monomial`` (a2, a1) of Neo-Hookean's
    ln J polynomial put in S as J U'(J) X instead of J U'(J) C^-1 (X = tensor_of(F, C)).
    """
    F, D = split.F, split.D
    C = np.einsum("mki,mkj->mij", F, F)
    J = np.linalg.det(F)
    a2, a1 = monomial
    p = (2.0 * a2 * np.log(J) + a1) / J  # U'(J) of that monomial
    dS = (J * p)[:, None, None] * (tensor_of(F, C) - np.linalg.inv(C))
    fe = -split.V0[:, None, None] * np.einsum("mik,mkl,mal->mai", F, dS, D)
    return f_o + assemble(split.cells, split.n, fe, None)[0]


def _half(F, C):
    c, N = np.linalg.eigh(C)
    return np.einsum("mia,ma,mja->mij", N, c**-0.5, N)


def _identity(F, C):
    return np.broadcast_to(np.eye(3), C.shape)


def test_the_j_part_with_another_tensor_is_named():
    """The engine's lam ln J C^(-1/2) for lam ln J C^-1 (a principal stress over lambda_a
    where lambda_a^2 belongs) in Neo-Hookean's stress, the tangent right: named, the monomial
    and the tensor; the identity for C^-1 in the same monomial is another reading.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("NeoHookean", seed=3)
    (vol,) = [t for g in model.decomposition() for t in g.terms if hasattr(t.f, "a2")]
    a2, a1 = vol.f.a2, vol.f.a1
    assert a2 and a1  # lam/2 (ln J)^2 - mu ln J: two monomials
    for tensor_of, said in ((_half, "C^(-1/2)"), (_identity, "I")):
        f = _with_j_part(split, f_o, tensor_of, (a2, 0.0))
        found = mjed_part_findings(model, points, cells, x, f, K_o, f_o, K_o, s, DOUBLE)
        assert [x.figures.get("tensor") for x in found] == [said], [x.title for x in found]
        assert "(ln J)^2 alone" in found[0].title and found[0].strength != PARTIAL
    # a force error of another form is not this reading
    f = f_o + 0.1 * (_with_j_part(split, f_o, _half, (a2, a1)) - f_o) + 1e-3 * np.abs(f_o).max()
    found = mjed_part_findings(model, points, cells, x, f, K_o, f_o, K_o, s, DOUBLE)
    assert not any(x.code == "mjed-j-tensor" for x in found)


def test_an_isochoric_f2_power_rule_slip_is_named_with_its_numbers():
    """Mooney-Rivlin's I1 term f = J^(-2/3): f'' written q (q + 1) J^(q - 2) = -2/9 J^(-8/3)
    for q (q - 1) J^(q - 2) = 10/9 J^(-8/3), the J-J block alone; on one J (a homogeneous
    stretch) the same slip is not said (every J-J block has one shape there).
    """
    model = default_material("MooneyRivlin")
    groups = model.decomposition()
    g_i, t_i = next(
        (i, j)
        for i, g in enumerate(groups)
        for j, t in enumerate(g.terms)
        if getattr(t.f, "p", 0) == -2.0 / 3.0
    )
    for jitter, said in ((0.03, True), (0.0, False)):
        points, cells = box_mesh(2, jitter=0.2, seed=4)
        rng = np.random.default_rng(4)
        x = points @ np.diag([1.1, 0.95, 0.92]).T + jitter * rng.standard_normal(points.shape)
        split, f_o, K_o, s = mjed_split(model, points, cells, x)
        p = _term(split, model, g_i, t_i)
        q = -2.0 / 3.0
        wrong = (q * (q + 1.0) - q * (q - 1.0)) * p["J"] ** (q - 2.0)  # engine minus declared
        Ke = (p["w"] * wrong * p["g"])[:, None, None, None, None] * np.einsum(
            "mai,mbj->maibj", p["dJ"], p["dJ"]
        )
        K = K_o + _assembled(split, Ke=Ke)[1]
        found = _find(model, points, cells, x, f_o, K, f_o, K_o, s)
        codes = [x.code for x in found]
        if said:
            assert codes == ["mjed-d2f"], [x.title for x in found]
            assert "-2/9 J^(-8/3) where the declared f = J^(-2/3) has 10/9" in found[0].title
        else:
            assert "mjed-d2f" not in codes


def test_f1_typed_again_in_the_stiffness_is_named():
    """Yeoh's I1 term (f = J^(-2/3)): f' written 2/3 J^(-5/3) (its sign lost) in the cross and
    antisymmetric blocks, the force right: the stiffness blocks' f' said as -1 times.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("Yeoh", seed=5)
    groups = model.decomposition()
    g_i, t_i = next(
        (i, j)
        for i, g in enumerate(groups)
        for j, t in enumerate(g.terms)
        if getattr(t.f, "p", 0) != 0
    )
    p = _term(split, model, g_i, t_i)
    c = (p["w"] * -2.0 * p["f1"])[:, None, None, None, None]  # engine minus declared f'
    dJ, FSD, J = p["dJ"], p["FSD"], p["J"]
    outer = lambda u, v: np.einsum("mai,mbj->maibj", u, v)  # noqa: E731
    g = p["g"][:, None, None, None, None]
    Ke = c * (
        outer(dJ, FSD)
        + outer(FSD, dJ)
        + g * (outer(dJ, dJ) - np.einsum("mbi,maj->maibj", dJ, dJ)) / J[:, None, None, None, None]
    )
    K = K_o + _assembled(split, Ke=Ke)[1]
    found = _find(model, points, cells, x, f_o, K, f_o, K_o, s)
    assert [x.code for x in found] == ["mjed-typed-apart"], [x.title for x in found]
    assert "written -1 times" in found[0].title


def test_a_material_tangent_typed_with_another_factor_is_named_where_its_shape_is_its_own():
    """St Venant-Kirchhoff's material stiffness (the oracle's minus its geometric part, from
    mjed's stress per cell) written 3/2 times, the force right: named where J varies and on a
    homogeneous stretch (one J) too, where no other term has material blocks. Arruda-Boyce's
    I1^2 term likewise: named where J varies, not on one J, where its material blocks have the
    shape of the I1^3 term's (both along Id (x) Id there).
    """
    import scipy.sparse as sp

    import mjed

    model = default_material("StVenantKirchhoff")
    for jitter in (0.03, 0.0):
        points, cells = box_mesh(2, jitter=0.2, seed=6)
        rng = np.random.default_rng(6)
        x = points @ np.diag([1.1, 0.95, 0.92]).T + jitter * rng.standard_normal(points.shape)
        split, f_o, K_o, s = mjed_split(model, points, cells, x)
        S = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model).stress(x)
        DSD = np.einsum("maI,mIJ,mbJ->mab", split.D, S, split.D)
        geo = np.einsum("mab,kl->makbl", DSD, np.eye(3)).reshape(-1, 12, 12)
        K_geo = assemble(cells, split.n, 0 * split.fe, split.V0[:, None, None] * geo)[1]
        K = K_o + 0.5 * (K_o - K_geo)
        found = _find(model, points, cells, x, f_o, K, f_o, K_o, s)
        titles = [x.title for x in found if x.code == "mjed-typed-apart"]
        assert len(titles) == 1 and "3/2 times in its material blocks" in titles[0], titles

    model = default_material("ArrudaBoyce")
    material = ("first", "second-outer", "second-scaled", "spectral")
    for jitter, said in ((0.03, True), (0.0, False)):
        points, cells = box_mesh(2, jitter=0.2, seed=6)
        rng = np.random.default_rng(6)
        x = points @ np.diag([1.1, 0.95, 0.92]).T + jitter * rng.standard_normal(points.shape)
        split, f_o, K_o, s = mjed_split(model, points, cells, x)
        parts = mjed_parts(model, points, cells, x, f_o, K_o)
        term = next(t for t in parts.terms if "I1^2" in t)
        P = sum(p.stiffness for p in parts.parts if p.term == term and p.kind in material)
        N = 3 * split.n
        K = K_o + sp.csr_matrix((0.5 * P, (parts.rows, parts.cols)), shape=(N, N))
        found = _find(model, points, cells, x, f_o, K, f_o, K_o, s)
        titles = [x.title for x in found if x.code == "mjed-typed-apart"]
        if said:
            assert len(titles) == 1 and "3/2 times in its material blocks" in titles[0], titles
        else:
            assert not titles, titles


def _power_terms(model):
    """(group index, term index, q) of every term whose f is a power J^q, q != 0."""
    return [
        (i, j, t.f.p)
        for i, g in enumerate(model.decomposition())
        for j, t in enumerate(g.terms)
        if getattr(t.f, "p", 0) != 0
    ]


def _outer(u, v):
    return np.einsum("mai,mbj->maibj", u, v)


def test_an_f2_exponent_lowered_once_is_named_with_its_power():
    """Mooney-Rivlin's I1 term f = J^(-2/3): f'' written q (q - 1) J^(q - 1) = 10/9 J^(-5/3)
    where 10/9 J^(-8/3) belongs (a per-cell factor J, not a constant): the J-J block alone.
    A J-J change that follows no power of J is not said so.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("MooneyRivlin", seed=6)
    g_i, t_i, q = next(t for t in _power_terms(model) if t[2] == -2.0 / 3.0)
    p = _term(split, model, g_i, t_i)
    for factor, said in ((p["J"], True), (1.0 + 30.0 * (p["J"] - 1.0) ** 2, False)):
        wrong = q * (q - 1.0) * p["J"] ** (q - 2.0) * (factor - 1.0)
        Ke = (p["w"] * wrong * p["g"])[:, None, None, None, None] * _outer(p["dJ"], p["dJ"])
        found = _find(model, points, cells, x, f_o, K_o + _assembled(split, Ke=Ke)[1], f_o, K_o, s)
        if said:
            assert [x.code for x in found] == ["mjed-d2f"], [x.title for x in found]
            assert "10/9 J^(-5/3) where the declared f = J^(-2/3) has 10/9 J^(-8/3)" in (
                found[0].title
            )
        else:
            assert "mjed-d2f" not in [x.code for x in found], [x.title for x in found]


def test_every_power_terms_f1_exponent_not_lowered_is_named_together():
    """Yeoh's J^(-2/3), J^(-4/3) and J^(-2) terms all with f' = c q J^q (one helper's power rule
    without the lowered exponent): J times the right f' in each, force and f'-blocks.
    """
    model, points, cells, x, split, f_o, K_o, s = _case("Yeoh", seed=7)
    terms = _power_terms(model)
    assert len(terms) > 1
    m = split.cells.shape[0]
    fe, Ke = np.zeros((m, 4, 3)), np.zeros((m, 4, 3, 4, 3))
    for g_i, t_i, _ in terms:
        t = _term(split, model, g_i, t_i)
        dJ, FSD, g, J = t["dJ"], t["FSD"], t["g"], t["J"]
        w = t["w"] * t["f1"] * (J - 1.0)  # engine minus right
        anti = _outer(dJ, dJ) - np.einsum("mbi,maj->maibj", dJ, dJ)
        Ke += w[:, None, None, None, None] * (
            _outer(dJ, FSD) + _outer(FSD, dJ) + (g / J)[:, None, None, None, None] * anti
        )
        fe += -(w * g)[:, None, None] * dJ
    df, dK = _assembled(split, fe=fe, Ke=Ke)
    found = _find(model, points, cells, x, f_o + df, K_o + dK, f_o, K_o, s)
    assert [x.code for x in found] == ["mjed-dfdj"], [x.title for x in found]
    assert "every power term" in found[0].title and "exponent not lowered" in found[0].title


def test_the_cross_blocks_of_every_term_left_out_are_named():
    """Yeoh: f'(J) (dJ_i (F S D_j)^T + (F S D_i) dJ_j^T) left out of every term's blocks."""
    model, points, cells, x, split, f_o, K_o, s = _case("Yeoh", seed=8)
    m = split.cells.shape[0]
    Ke = np.zeros((m, 4, 3, 4, 3))
    for g_i, group in enumerate(model.decomposition()):
        for t_i in range(len(group.terms)):
            t = _term(split, model, g_i, t_i)
            w = -(t["w"] * t["f1"])[:, None, None, None, None]
            Ke += w * (_outer(t["dJ"], t["FSD"]) + _outer(t["FSD"], t["dJ"]))
    found = _find(model, points, cells, x, f_o, K_o + _assembled(split, Ke=Ke)[1], f_o, K_o, s)
    assert [x.code for x in found] == ["mjed-part"], [x.title for x in found]
    assert "both product-rule cross blocks" in found[0].title
    assert "of every term left out" in found[0].title


@dataclasses.dataclass(frozen=True)
class _ForwardPhi:
    """A group's phi with phi' by a forward difference of phi, step h."""

    inner: object
    h: float

    def __call__(self, u):
        v, _, d2 = self.inner(u)
        return v, (self.inner(u + self.h)[0] - v) / self.h, d2


def _forward_f(inner, h):
    """A term's f(J) with f' by a forward difference of f, step h."""
    from mjed.terms import JFunction

    @dataclasses.dataclass(frozen=True)
    class ForwardF(JFunction):
        def __call__(self, J):
            f, _, f2 = inner(J)
            return f, (inner(J + h)[0] - f) / h, f2

    return ForwardF()


def test_a_derivative_by_a_forward_difference_is_named_with_its_step():
    """Demiray's phi'(u) and Mooney-Rivlin's J^(-2/3) f'(J) each by a forward difference with
    step 1e-4 (errors of about 1e-5): named with the scheme and the step; the same size of
    error as a constant factor on the Mooney-Rivlin f' is not a difference quotient.
    """
    from mjed.terms import SmoothFunction

    SmoothFunction.register(_ForwardPhi)
    model = default_material("Demiray")
    groups = tuple(
        g
        if g.plain
        else dataclasses.replace(g, exponential=False, function=_ForwardPhi(g.function, 1e-4))
        for g in model.decomposition()
    )
    _, points, cells, x, _, f_o, K_o, s = _case("Demiray", seed=9)
    _, _, _, _, _, f_w, K_w, _ = _case("Demiray", seed=9, model=_Terms(groups))
    found = _find(model, points, cells, x, f_w, K_w, f_o, K_o, s)
    assert [x.code for x in found] == ["mjed-difference"], [x.title for x in found]
    assert "phi'(u)" in found[0].title and "forward difference" in found[0].title
    assert found[0].figures["step"] == pytest.approx(1e-4, rel=1e-2)

    model = default_material("MooneyRivlin")
    _, points, cells, x, _, f_o, K_o, s = _case("MooneyRivlin", seed=9)
    for wrong, said in ((lambda f: _forward_f(f, 1e-4), True), (None, False)):
        groups = []
        for g in model.decomposition():
            terms = tuple(
                dataclasses.replace(t, f=wrong(t.f))
                if wrong and getattr(t.f, "p", 0) == -2.0 / 3.0
                else t
                for t in g.terms
            )
            groups.append(dataclasses.replace(g, terms=terms))
        if wrong is None:  # f' of that term 1 + 3e-5 times the right one in every cell
            groups = [
                dataclasses.replace(
                    g,
                    terms=tuple(
                        dataclasses.replace(t, f=_scaled_f1(t.f, 1.0 + 3e-5))
                        if getattr(t.f, "p", 0) == -2.0 / 3.0
                        else t
                        for t in g.terms
                    ),
                )
                for g in groups
            ]
        _, _, _, _, _, f_w, K_w, _ = _case("MooneyRivlin", seed=9, model=_Terms(tuple(groups)))
        codes = [x.code for x in _find(model, points, cells, x, f_w, K_w, f_o, K_o, s)]
        assert ("mjed-difference" in codes) is said, codes


def _scaled_f1(inner, k):
    from mjed.terms import JFunction

    @dataclasses.dataclass(frozen=True)
    class Scaled(JFunction):
        def __call__(self, J):
            f, f1, f2 = inner(J)
            return f, k * f1, f2

    return Scaled()


def test_a_block_weighted_per_cell_by_another_factor_is_named():
    """Yeoh's J-Hessian blocks of every term with f(J) where f'(J) belongs, and Mooney-Rivlin's
    cross blocks of every term formed with F^-T D_i for dJ_i (the factor J lost there): each
    named with its block and factor; a factor 1 + 3 (J - 1)^2 in the cross blocks is not.
    """
    for name, kind, factor, said in (
        ("Yeoh", "anti", "f/f'", "with f(J) where f'(J) belongs"),
        ("MooneyRivlin", "cross", "1/J", "the factor J lost there"),
        ("MooneyRivlin", "cross", "other", None),
    ):
        model, points, cells, x, split, f_o, K_o, s = _case(name, seed=10)
        m = split.cells.shape[0]
        Ke = np.zeros((m, 4, 3, 4, 3))
        for g_i, group in enumerate(model.decomposition()):
            for t_i in range(len(group.terms)):
                t = _term(split, model, g_i, t_i)
                dJ, FSD, J = t["dJ"], t["FSD"], t["J"]
                if kind == "anti":
                    if not np.any(t["f1"]):
                        continue
                    w = t["w"] * (t["f"] - t["f1"]) * t["g"] / J
                    block = _outer(dJ, dJ) - np.einsum("mbi,maj->maibj", dJ, dJ)
                else:
                    ratio = 1.0 / J if factor == "1/J" else 1.0 + 3.0 * (J - 1.0) ** 2
                    w = t["w"] * t["f1"] * (ratio - 1.0)
                    block = _outer(dJ, FSD) + _outer(FSD, dJ)
                Ke += w[:, None, None, None, None] * block
        K = K_o + _assembled(split, Ke=Ke)[1]
        found = _find(model, points, cells, x, f_o, K, f_o, K_o, s)
        codes = [x.code for x in found]
        if said:
            assert codes == ["mjed-weighted-block"], [x.title for x in found]
            assert said in found[0].title and "of every term" in found[0].title
        else:
            assert "mjed-weighted-block" not in codes, [x.title for x in found]


def test_readings_with_the_same_prediction_here_are_said_in_the_evidence():
    """On a homogeneous stretch (one J) a forward-difference f' and f' times a constant are the
    same prediction: one is named, the other said as equal in its evidence.
    """
    model = default_material("MooneyRivlin")
    points, cells = box_mesh(2, jitter=0.2, seed=11)
    x = points @ np.diag([1.1, 0.95, 0.92]).T
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    groups = [
        dataclasses.replace(
            g,
            terms=tuple(
                dataclasses.replace(t, f=_forward_f(t.f, 1e-4))
                if getattr(t.f, "p", 0) == -2.0 / 3.0
                else t
                for t in g.terms
            ),
        )
        for g in model.decomposition()
    ]
    _, f_w, K_w, _ = mjed_split(_Terms(tuple(groups)), points, cells, x)
    found = _find(model, points, cells, x, f_w, K_w, f_o, K_o, s)
    assert len(found) == 1, [x.title for x in found]
    assert "equally (the same prediction here)" in found[0].evidence
    assert "forward difference" in found[0].title + found[0].evidence


def test_a_group_functions_rest_constant_lost_is_named():
    """Gent's ln(1 + 3/Jm - I1b/Jm) declared ln(1 - I1b/Jm): the constant 3/Jm lost."""
    from mjed.terms import Log

    model = default_material("Gent")
    groups = tuple(
        dataclasses.replace(g, function=Log(1.0)) if isinstance(g.function, Log) else g
        for g in model.decomposition()
    )
    _, points, cells, x, _, f_o, K_o, s = _case("Gent", seed=12)
    _, _, _, _, _, f_w, K_w, _ = _case("Gent", seed=12, model=_Terms(groups))
    found = _find(model, points, cells, x, f_w, K_w, f_o, K_o, s)
    assert [x.code for x in found] == ["mjed-group-shift"], [x.title for x in found]
    assert "3/Jm lost" in found[0].title


def test_on_one_j_an_antisymmetric_block_is_not_given_to_one_term():
    """Every term's J-Hessian block with f for f' on a homogeneous stretch (one J): all terms'
    J-Hessian blocks have one shape there, so no single term's f'-blocks are named for it
    (the volumetric term's, whose cross blocks are zero, once were, written 0.48 times).
    """
    model = default_material("Yeoh")
    points, cells = box_mesh(2, jitter=0.2, seed=13)
    x = points @ np.diag([1.1, 0.95, 0.92]).T
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    m = split.cells.shape[0]
    Ke = np.zeros((m, 4, 3, 4, 3))
    for g_i, group in enumerate(model.decomposition()):
        for t_i in range(len(group.terms)):
            t = _term(split, model, g_i, t_i)
            if not np.any(t["f1"]):
                continue
            dJ, J = t["dJ"], t["J"]
            w = t["w"] * (t["f"] - t["f1"]) * t["g"] / J
            block = _outer(dJ, dJ) - np.einsum("mbi,maj->maibj", dJ, dJ)
            Ke += w[:, None, None, None, None] * block
    found = _find(model, points, cells, x, f_o, K_o + _assembled(split, Ke=Ke)[1], f_o, K_o, s)
    assert "mjed-typed-apart" not in [x.code for x in found], [x.title for x in found]


def test_an_isochoric_factors_j_part_left_out_of_the_force_is_said_as_the_chain_rule_term():
    """Mooney-Rivlin's c1 term J^(-2/3) I1 with its J part left out of the force (stiffness
    right): the isochoric stress not deviatoric, said in MJED's words and in those of engines
    that do not split terms (the isochoric projection, the deviatoric stretches' chain).
    """
    model, points, cells, x, split, f_o, K_o, s = _case("MooneyRivlin")
    parts = mjed_parts(model, points, cells, x, f_o, K_o)
    (part,) = [p for p in parts.parts if p.kind == "force-J" and p.term.startswith("J^(-2/3) I1")]
    found = _find(model, points, cells, x, f_o - part.force.reshape(f_o.shape), K_o, f_o, K_o, s)
    assert found and found[0].figures["part"] == "force-J", [x.title for x in found]
    assert "left out" in found[0].title and "deviatoric" in found[0].title
    assert "isochoric projection" in found[0].title
