"""The operation-count model: structure, not timings. It is derived from the declared terms
(MJED) and the classical law, so declaring more terms must cost more, and each part must move
with the term that causes it.
"""

from __future__ import annotations

import pytest

from common.cases import DEFAULT_MATERIALS
from comparisons.timing.opcount import (
    EIGEN,
    TRANSCENDENTAL,
    classical_flops,
    mjed_flops,
    mjed_source_flops,
    model,
    source_flops,
)
from mjed import materials as M
from mjed.materials.base import Material
from mjed.terms import InvariantFunction, JPower, Term, TermGroup


@pytest.mark.parametrize("name", sorted(DEFAULT_MATERIALS))
def test_every_material_is_counted_and_totals_add_up(name):
    r = model(DEFAULT_MATERIALS[name])
    for method in ("mjed", "classical"):
        parts = r[method]["parts"]
        assert all(v >= 0 for v in parts.values()) and r[method]["total"] == sum(parts.values()) > 0
    # like with like: both counted from their generated sources; the hand model beside it
    assert r["predicted_ratio"] == pytest.approx(r["classical"]["total"] / r["mjed_source"])
    assert r["hand_model_ratio"] == pytest.approx(r["classical"]["total"] / r["mjed"]["total"])
    assert r["hand_model_ratio"] <= r["predicted_ratio"]


def test_mjed_count_follows_the_declared_terms():
    nh = mjed_flops(M.NeoHookean(mu=1.0, lam=2.0)).parts
    mr = mjed_flops(M.MooneyRivlin(c1=1.0, c2=0.5, k0=3.0)).parts
    vw = mjed_flops(M.VerondaWestmann(c1=1.0, c2=0.5, k0=3.0)).parts
    svk = mjed_flops(M.StVenantKirchhoff(mu=1.0, lam=2.0)).parts
    og = mjed_flops(M.Ogden(mu=1.0, alpha=3.0, k0=3.0)).parts
    # Mooney-Rivlin's I2 term brings a first- and a second-kind tangent pair: more edge-block work.
    assert mr["edge blocks"] > nh["edge blocks"] and mr["terms"] > nh["terms"]
    # Veronda-Westmann's exponential group adds a rank-one term per edge and an exp per cell.
    assert vw["terms"] - mr["terms"] >= TRANSCENDENTAL and vw["edge blocks"] > mr["edge blocks"]
    # Only Ogden needs the eigen-decomposition of C.
    assert og["kinematics"] - nh["kinematics"] == EIGEN
    assert all(p["kinematics"] == nh["kinematics"] for p in (mr, vw, svk))
    # St Venant-Kirchhoff has no J terms: no volumetric coupling, no d2J skew term.
    assert svk["terms"] < nh["terms"] + 200 and svk["edge blocks"] != nh["edge blocks"]
    # Assembly and the force do not depend on the material.
    assert (
        len({p["assembly"] for p in (nh, mr, vw, svk, og)}) == 1
        and len({p["force"] for p in (nh, mr, svk)}) == 1
    )


def test_an_added_term_costs_more():
    base = M.NeoHookean(mu=1.0, lam=2.0)

    class Extra(Material):
        def decomposition(self):
            (g,) = base.decomposition()
            return (TermGroup(g.terms + (Term(JPower(-2.0 / 3.0), g.terms[0].g),)),)

    assert mjed_flops(Extra()).total > mjed_flops(base).total


def test_classical_count_follows_the_law():
    c = {n: classical_flops(m).parts["law (S, CC)"] for n, m in DEFAULT_MATERIALS.items()}
    # the decoupled (isochoric projection) laws cost far more than the plain neo-Hookean
    for n in ("MooneyRivlin", "VerondaWestmann", "ArrudaBoyce"):
        assert c[n] > 2 * c["NeoHookean"]
    assert c["StVenantKirchhoff"] < c["NeoHookean"] < c["Ogden"]
    # the element matrix B^T CC B is dense for every law but St Venant-Kirchhoff, whose
    # constant CC has 12 structural zeros of 21 the generated kernel leaves out
    matrix = {n: classical_flops(m).parts["element matrix"] for n, m in DEFAULT_MATERIALS.items()}
    assert len({v for n, v in matrix.items() if n != "StVenantKirchhoff"}) == 1
    assert matrix["StVenantKirchhoff"] < matrix["NeoHookean"]
    assert classical_flops(M.Ogden(mu=1.0, alpha=3.0, k0=3.0)).parts["law (S, CC)"] > EIGEN


def test_source_count_rules():
    source = """
def kernel(x, flag):
    m = 1.0
    for e in range(3):
        a = x[e] * 2.0 + (1.0 / 3.0)
        b = a if a == 0.0 else math.exp(a)
        if flag:
            c = a * b - a
        else:
            c = a
        if regularize:
            d = a * a * a
        energy += a ** 1.5
"""
    # a: one multiply and one add (the literal quotient is folded); b: the generic (else) branch, a
    # libm call; c: the larger branch (2); d: skipped; energy: one add and a libm power
    counts = source_flops(source, {"a": "first"}, "rest", skip=("regularize",))
    assert counts == {"first": 2, "rest": TRANSCENDENTAL + 2 + 1 + TRANSCENDENTAL}


def test_mjed_hand_model_is_no_lower_than_its_source_count():
    for m in DEFAULT_MATERIALS.values():
        assert mjed_source_flops(m) <= mjed_flops(m).total


def test_unknown_term_type_is_refused():
    class Odd(InvariantFunction):
        def value(self, kin):
            return 1.0

    class OddMaterial(Material):
        def decomposition(self):
            return (TermGroup((Term(JPower(1.0), Odd()),)),)

    with pytest.raises(NotImplementedError, match="Odd"):
        mjed_flops(OddMaterial())
