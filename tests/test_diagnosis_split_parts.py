"""Holzapfel's isochoric/volumetric split read piece by piece (conformance.diagnosis.split_parts).

The mistaken engines are one small Holzapfel-style engine written here (its own einsums, the
isochoric law's derivatives from the material's declared classical Psi, not from the module's
hyper-dual numbers), with the coefficient of one piece changed or one piece written another
way; MJED stands in for the oracle. Each mistake comes with a nearby one that must not get its
cause: the same piece wrong by an unlisted factor, or wrong together with another error.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import box_mesh, checked_random, mjed_split

from common.cases import default_material
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.split_parts import split_part_findings, split_parts
from conformance.judge.compare import DOUBLE
from mjed.materials.declaration import declaration_of
from reference_fem import dolfinx_available

DECOUPLED = ("MooneyRivlin", "Yeoh", "ArrudaBoyce", "Gent", "VerondaWestmann", "Demiray")
NOT_SPLIT = ("NeoHookean", "StVenantKirchhoff", "Costa")

I3 = np.eye(3)
II = 0.5 * (np.einsum("ik,jl->ijkl", I3, I3) + np.einsum("il,jk->ijkl", I3, I3))

#: The engine's coefficients as Holzapfel writes them.
RIGHT = dict(
    coupling=-2.0 / 3.0,  # -2/3 (C^-1 (x) S_iso + S_iso (x) C^-1)
    trace=2.0 / 3.0,  # 2/3 Tr(J^(-2/3) S_bar) P~
    ptilde=-1.0 / 3.0,  # P~ = C^-1 (.) C^-1 - 1/3 C^-1 (x) C^-1
    dp=1.0,  # p~ = p + dp J dp/dJ
    sbar_c2=2.0,  # S_bar = 2 (psi1 + I1b psi2) I - sbar_c2 psi2 C_bar
    sbar_power=0.0,  # S_bar times J^sbar_power
    dev_tr=False,  # DEV(X) with tr(X) for X : C
    proj_t=False,  # P = II - 1/3 C (x) C^-1
    k0=1.0,  # U' and U'' times k0
    psi11=1.0,  # psi11 times psi11 in the fictitious tangent
    proj_double=1.0,  # P : CC~ : P^T written out, its 1/9 (C : CC~ : C) C^-1 (x) C^-1 times this
)


def _outer(A, B):
    return np.einsum("mij,mkl->mijkl", A, B)


def _odot(A, B):
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def holzapfel(model, points, cells, x, **mistake):
    """The force (n, 3) and stiffness of a Holzapfel-style total-Lagrangian P1 engine."""
    c = {**RIGHT, **mistake}
    Xe = points[cells]
    M = np.stack([Xe[:, 1] - Xe[:, 0], Xe[:, 2] - Xe[:, 0], Xe[:, 3] - Xe[:, 0]], axis=2)
    V = np.abs(np.linalg.det(M)) / 6.0
    Minv = np.linalg.inv(M)
    G = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)  # (m, 4, 3)
    F = np.einsum("mak,maI->mkI", x[cells], G)
    J = np.linalg.det(F)
    C = np.einsum("mkI,mkJ->mIJ", F, F)
    Ci = np.linalg.inv(C)
    m = len(J)
    Jm23 = J ** (-2.0 / 3.0)
    Cb = Jm23[:, None, None] * C
    I1b = np.trace(Cb, axis1=1, axis2=2)
    I2b = 0.5 * (I1b**2 - np.einsum("mij,mji->m", Cb, Cb))
    law = declaration_of(type(model)).classical(model)
    p = SimpleNamespace(**dict(law.parameters))
    _, psi1, psi2, psi11, psi12, psi22 = (
        np.broadcast_to(np.asarray(v, dtype=float), (m,)) for v in law.psi.function(p, I1b, I2b, np)
    )
    psi11 = c["psi11"] * psi11
    k0 = c["k0"] * law.k0
    dU, d2U = k0 * np.log(J) / J, k0 * (1.0 - np.log(J)) / J**2
    Id = np.broadcast_to(I3, (m, 3, 3))
    Sbar = 2.0 * (psi1 + I1b * psi2)[:, None, None] * Id - c["sbar_c2"] * psi2[:, None, None] * Cb
    Sbar = (J ** c["sbar_power"])[:, None, None] * Sbar
    d1 = psi11 + 2.0 * I1b * psi12 + psi2 + I1b**2 * psi22
    d2 = -(psi12 + I1b * psi22)
    w = lambda a: a[:, None, None, None, None]  # noqa: E731
    CCbar = 4.0 * (
        w(d1) * _outer(Id, Id)
        + w(d2) * (_outer(Id, Cb) + _outer(Cb, Id))
        + w(psi22) * _outer(Cb, Cb)
        - w(psi2) * II
    )
    trace = np.trace if c["dev_tr"] else None
    SC = np.trace(Sbar, axis1=1, axis2=2) if trace else np.einsum("mij,mij->m", Sbar, C)
    S_iso = Jm23[:, None, None] * (Sbar - (SC / 3.0)[:, None, None] * Ci)
    S_vol = (J * dU)[:, None, None] * Ci
    pt = dU + c["dp"] * J * d2U
    CC_vol = w(J * pt) * _outer(Ci, Ci) - w(2.0 * J * dU) * _odot(Ci, Ci)
    Proj = II - (_outer(C, Ci) if c["proj_t"] else _outer(Ci, C)) / 3.0
    Pt = _odot(Ci, Ci) + c["ptilde"] * _outer(Ci, Ci)
    trS = Jm23 * np.einsum("mij,mij->m", Sbar, C)
    CC_iso = np.einsum("mijab,mabcd,mklcd->mijkl", Proj, w(Jm23**2) * CCbar, Proj)
    CCt_C = np.einsum("mij,mijkl,mkl->m", C, w(Jm23**2) * CCbar, C)  # C : CC~ : C
    CC_iso = CC_iso + (c["proj_double"] - 1.0) * w(CCt_C / 9.0) * _outer(Ci, Ci)
    CC_iso = CC_iso + c["trace"] * w(trS) * Pt
    CC_iso = CC_iso + c["coupling"] * (_outer(Ci, S_iso) + _outer(S_iso, Ci))
    S, CC = S_vol + S_iso, CC_vol + CC_iso
    P = np.einsum("miK,mKJ->miJ", F, S)
    A = np.einsum("ik,mJL->miJkL", I3, S) + np.einsum("miI,mIJKL,mkK->miJkL", F, CC, F)
    fe = -V[:, None, None] * np.einsum("miJ,maJ->mai", P, G)
    Ke = V[:, None, None, None, None] * np.einsum("maJ,miJkL,mbL->maibk", G, A, G)
    return assemble(cells, len(points), fe, Ke.reshape(m, 12, 12))


def _case(name, seed=0, stretch=(1.1, 0.95, 0.92)):
    model = default_material(name)
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag(stretch).T + 0.03 * rng.standard_normal(points.shape)
    _, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, points, cells, x, f_o, K_o, s


def _find(case, **mistake):
    model, points, cells, x, f_o, K_o, s = case
    f, K = holzapfel(model, points, cells, x, **mistake)
    return split_part_findings(model, points, cells, x, f, K, f_o, K_o, s, DOUBLE)


@pytest.mark.parametrize("name", DECOUPLED)
def test_the_pieces_of_every_decoupled_material_add_up_to_the_oracle(name):
    model, points, cells, x, f_o, K_o, s = _case(name)
    parts = split_parts(model, points, cells, x, f_o, K_o)
    assert parts is not None
    f = np.sum([a for a, _ in parts.part.values()], axis=0)
    K = np.sum([b for _, b in parts.part.values()], axis=0)
    assert np.linalg.norm(f - f_o.ravel()) <= 1e-12 * max(
        np.linalg.norm(a) for a, _ in parts.part.values()
    )
    K_on = np.asarray(K_o[parts.pattern.rows, parts.pattern.cols]).ravel()
    assert np.linalg.norm(K - K_on) <= 1e-12 * np.linalg.norm(K_on)
    # the test engine written right is the oracle too, and nothing is read from it
    assert _find((model, points, cells, x, f_o, K_o, s)) == []
    # a wrong oracle is not split: the pieces must add up to it
    assert split_parts(model, points, cells, x, f_o, 1.001 * K_o) is None
    assert split_parts(model, points, cells, x, 1.001 * f_o, K_o) is None


@pytest.mark.parametrize("stretch", [(1.1, 0.95, 0.92), (1.1, 0.95, 0.95)])
@pytest.mark.parametrize("alpha", [3.0, -2.0, 5.0])
def test_ogden_power_sum_is_split_and_its_pieces_add_up_to_the_oracle(alpha, stretch):
    model = dataclasses.replace(default_material("Ogden"), alpha=alpha)
    points, cells = box_mesh(2, jitter=0.0, seed=0)
    x = points @ np.diag(stretch).T  # (1.1, 0.95, 0.95): two equal stretches in every cell
    _, f_o, K_o, s = mjed_split(model, points, cells, x)
    parts = split_parts(model, points, cells, x, f_o, K_o)
    assert parts is not None
    K = np.sum([b for _, b in parts.part.values()], axis=0)
    K_on = np.asarray(K_o[parts.pattern.rows, parts.pattern.cols]).ravel()
    assert np.linalg.norm(K - K_on) <= 1e-12 * np.linalg.norm(K_on)
    # the pieces that depend on the principal frame exist only where it is defined
    distinct = len(set(stretch)) == 3
    assert ("CCbar-principal" in parts.carried) == distinct
    assert ("spectral-diagonal" in parts.carried) == distinct
    assert "spectral-double" in parts.carried and "spectral-single" in parts.carried
    assert split_parts(model, points, cells, x, f_o, 1.001 * K_o) is None


@pytest.mark.parametrize("name", NOT_SPLIT)
def test_materials_not_written_in_isochoric_invariants_are_not_split(name):
    model, points, cells, x, f_o, K_o, s = _case(name)
    assert split_parts(model, points, cells, x, f_o, K_o) is None


def _only(found, code, *words):
    assert len(found) == 1, [f.title for f in found]
    assert found[0].code == code, found[0].title
    for w in words:
        assert w in found[0].title, found[0].title
    return found[0]


#: mistake (engine coefficients), material, words the finding must hold, a nearby mistake that
#: must not get the cause.
MISTAKES = [
    (
        dict(coupling=2.0 / 3.0),
        "MooneyRivlin",
        ("coupling term", "sign flipped"),
        dict(coupling=1.5 / 3.0),
    ),
    (
        dict(trace=1.0 / 3.0, coupling=-1.0 / 3.0),
        "Gent",
        ("trace term", "coupling term", "1/3 for 2/3"),
        dict(trace=1.0 / 3.0, coupling=-1.0 / 3.0, dp=0.9),
    ),
    (
        dict(ptilde=1.0 / 3.0),
        "ArrudaBoyce",
        ("modified projection P~", "+ 1/3 C^-1 (x) C^-1"),
        dict(ptilde=0.25),
    ),
    (dict(dp=0.0), "Yeoh", ("p~ written p, without J dp/dJ",), dict(dp=0.0, coupling=-0.6)),
    (
        dict(dev_tr=True),
        "VerondaWestmann",
        ("deviator", "tr(S_bar)"),
        dict(dev_tr=True, k0=1.01),
    ),
    (
        dict(proj_t=True),
        "Gent",
        ("projection tensor", "transposed"),
        dict(proj_t=True, ptilde=-0.3),
    ),
    (
        dict(sbar_c2=1.0),
        "MooneyRivlin",
        ("-2 psi2 C_bar", "fictitious stress", "halved"),
        dict(sbar_c2=1.2),
    ),
    (
        dict(psi11=-1.0),
        "Gent",
        ("psi11 part 4 psi11 I (x) I", "sign flipped"),
        dict(psi11=-0.8),
    ),
    (
        dict(sbar_power=-2.0 / 3.0),
        "Demiray",
        ("J^(-2/3) applied twice",),
        dict(sbar_power=-0.6),
    ),
    (
        dict(proj_double=0.0),
        "Demiray",
        ("double contraction 1/9 (C : CC~ : C)", "left out"),
        dict(proj_double=0.1),
    ),
]


@pytest.mark.parametrize("mistake, name, words, nearby", MISTAKES, ids=lambda v: str(v)[:40])
def test_a_mistaken_piece_is_named_and_a_nearby_mistake_is_not(mistake, name, words, nearby):
    case = _case(name)
    found = _find(case, **mistake)
    assert len(found) == 1, [f.title for f in found]
    for w in words:
        assert w in found[0].title, found[0].title
    assert found[0].figures["force_error"] <= DOUBLE.force
    assert found[0].figures["stiffness_error"] <= DOUBLE.stiffness
    assert _find(case, **nearby) == []


def test_a_volumetric_parameter_is_not_read_as_pieces():
    """k0 1 % off: the energy changed (force and stiffness consistently), not one piece."""
    model, points, cells, x, f_o, K_o, s = _case("MooneyRivlin")
    other = dataclasses.replace(model, k0=1.01 * model.k0)
    f, K = holzapfel(other, points, cells, x)
    assert split_part_findings(model, points, cells, x, f, K, f_o, K_o, s, DOUBLE) == []


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
@pytest.mark.parametrize(
    "name, mistake, words",
    [
        ("ArrudaBoyce", dict(ptilde=1.0 / 3.0), "modified projection P~"),
        ("MooneyRivlin", dict(sbar_c2=1.0), "-2 psi2 C_bar of the fictitious stress S_bar halved"),
    ],
)
def test_the_check_puts_the_split_reading_first(name, mistake, words):
    """Through the check (the UFL oracle, run.READINGS): P~'s sign lies along C^-1 (x) C^-1,
    which the diagnosis's per-cell volumetric fit also fits; the split goes first. A stress
    piece (the force wrong) is read before the hand-derived readings.
    """
    import mjed

    model = default_material(name)

    def engine(case):
        f, K = holzapfel(model, case.points, case.cells, case.positions, **mistake)
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), model)
        return f, K, field.energy(case.positions)

    diag = checked_random(engine, model)
    head = diag.findings[0]
    assert head.code == "split-part" and words in head.title, diag.text()
