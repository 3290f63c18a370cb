"""Rewritten formulas (issue 29): I2 with tr(C^2) written from part of C."""

from __future__ import annotations

import logging

import pytest
from conftest import checked_random

from mjed.materials import MooneyRivlin
from reference_fem import dolfinx_available


def test_i2_from_part_of_c_is_a_variant_of_every_formula_with_i2():
    from conformance.diagnosis.variants import variants

    codes = [v.rewrite.code for v in variants(MooneyRivlin(c1=1200.0, c2=400.0, k0=3e4))]
    assert "I2-diagonal" in codes and "I2-voigt" in codes


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_i2_from_the_diagonal_of_c_is_named_as_a_rewritten_formula():
    """An engine whose I2 takes tr(C^2) from the diagonal of C: the rewritten formula named."""
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle
    from reference_fem.user_energy import UserEnergy

    logging.disable(logging.INFO)

    oracles: dict = {}

    def engine(case):
        m = case.model
        if "o" not in oracles:
            mistaken = UserEnergy(
                "c1*(I1b - 3) + c2*(J**(-4/3)*(I1**2 - (C11**2 + C22**2 + C33**2))/2 - 3)"
                " + k0/2*ln(J)**2",
                {"c1": m.c1, "c2": m.c2, "k0": m.k0},
            )
            oracles["o"] = UFLOracle(case.points, case.cells, mistaken)
        f, K = oracles["o"].force_and_stiffness(case.positions)
        return f, K, oracles["o"].energy(case.positions)

    run = check_implementation(
        engine,
        material=MooneyRivlin(c1=1200.0, c2=400.0, k0=3e4),
        mesh="cube-small",
        states=("random",),
        probes=False,
    )
    (outcome,) = run.outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed" and d.causes, d.text()
    assert d.causes[0].code == "energy-variant", d.text()
    assert d.causes[0].figures["variant"] == "I2-diagonal", d.text()


def test_log10_for_ln_is_a_variant_of_every_formula_with_ln_j():
    from conformance.diagnosis.variants import variants
    from mjed.materials import NeoHookean
    from reference_fem.user_energy import UserEnergy

    (v,) = [v for v in variants(NeoHookean(mu=3448.0, lam=31034.0)) if v.rewrite.code == "log10"]
    assert v.expression.count("ln(J)/2.302585092994") == 2  # both J terms, none left natural
    no_log = UserEnergy("mu/2*(I1b - 3) + k/2*(J - 1)**2", {"mu": 1.0, "k": 10.0})
    assert "log10" not in [v.rewrite.code for v in variants(no_log)]


def _check_user_engine(expression, material):
    """check_implementation of an engine that is the oracle of ``expression`` (a UserEnergy with
    ``material``'s parameters), on the random state: the outcome's diagnosis.
    """
    import dataclasses

    from reference_fem import UFLOracle
    from reference_fem.user_energy import UserEnergy

    oracles: dict = {}
    params = {f.name: getattr(material, f.name) for f in dataclasses.fields(material)}

    def engine(case):
        if "o" not in oracles:
            oracles["o"] = UFLOracle(case.points, case.cells, UserEnergy(expression, params))
        f, K = oracles["o"].force_and_stiffness(case.positions)
        return f, K, oracles["o"].energy(case.positions)

    return checked_random(engine, material)


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_a_j_only_energy_named_per_cell_is_made_specific_by_the_rewritten_formula():
    """log10 J for ln J: the per-cell volumetric reading is true but unspecific; the rewritten
    formula says which U(J). Nearby: a bulk term scaled by 1.3 is J-only too, but no rewrite
    matches: the parameter's value (lam 1.3 times the case's) says it.
    """
    from mjed.materials import NeoHookean

    neo = NeoHookean(mu=3448.2759, lam=31034.483)
    c = 1.0 / 2.302585092994046
    d = _check_user_engine(f"mu/2*(I1 - 3) - mu*{c!r}*ln(J) + lam/2*({c!r}*ln(J))**2", neo)
    (head,) = d.causes
    assert head.code == "volumetric" and "your engine matches W' =" in head.title, d.text()
    assert head.figures["formula"]["variant"] == "log10", d.text()
    assert "log10" in head.evidence
    d = _check_user_engine("mu/2*(I1 - 3) - mu*ln(J) + 1.3*lam/2*ln(J)**2", neo)
    assert "formula" not in d.causes[0].figures, d.text()
    # ... but one parameter's value does: lam 1.3 times the case's
    assert d.causes[0].figures["parameter"]["parameter"] == "lam", d.text()
    assert "parameter lam = " in d.causes[0].title, d.text()


def test_every_declared_formula_is_written_as_the_declared_energy_computes():
    """The written formula of each declared material (the base of every rewrite) gives the
    declared energy's value at a deformed state: a divisor or a power written without its
    parentheses (a/2*b for a/(2 b)) would not.
    """
    import math
    from types import SimpleNamespace

    from conformance.diagnosis.variants import energy_expression
    from mjed.materials.declaration import declarations

    J, I1, I2 = 1.07, 3.4, 3.6  # a state with J != 1 and non-trivial invariants
    k = SimpleNamespace(
        I1=I1, I2=I2, J=J, lnJ=math.log(J), I1b=J ** (-2 / 3) * I1, I2b=J ** (-4 / 3) * I2
    )
    k.exp, k.ln = math.exp, math.log
    written = 0
    for d in declarations():
        found = energy_expression(d.default)
        if found is None or "E11" in found[0]:  # no scalar formula, or one written in E
            continue
        text, params = found
        value = eval(text, {"exp": math.exp, "ln": math.log}, {**vars(k), **params})  # noqa: S307
        declared = d.energy(lambda name, m=d.default: float(getattr(m, name)), k)
        assert value == pytest.approx(declared, rel=1e-12), (d.name, text)
        written += 1
    assert written >= 7


def test_an_exponential_with_its_argument_negated_is_a_variant_of_every_formula_with_exp():
    from common.cases import default_material
    from conformance.diagnosis.variants import variants

    def flipped(name):
        return [
            v.expression for v in variants(default_material(name)) if v.rewrite.code == "exp-sign"
        ]

    (demiray,) = flipped("Demiray")
    assert "(a/(2*b))*(1/exp(b*(I1b - 3)) - 1)" in demiray
    assert len(flipped("VerondaWestmann")) == 1 and flipped("NeoHookean") == []


def test_the_identity_typed_as_ones_in_the_green_strain_is_a_variant_of_st_venant_kirchhoff():
    import numpy as np

    from common.cases import default_material
    from conformance.diagnosis.variants import variants

    model = default_material("StVenantKirchhoff")
    (v,) = [v for v in variants(model) if v.rewrite.code == "identity-ones"]
    rng = np.random.default_rng(3)
    F = np.eye(3) + 0.1 * rng.standard_normal((6, 3, 3))
    E = 0.5 * (F.transpose(0, 2, 1) @ F - np.ones((3, 3)))  # the typo itself
    trE = np.trace(E, axis1=1, axis2=2)
    W = model.lam / 2 * trE**2 + model.mu * np.einsum("mij,mij->m", E, E)
    assert np.allclose(v.model.density(F), W, rtol=1e-13)
    assert all(v.rewrite.code != "identity-ones" for v in variants(default_material("Yeoh")))


def test_i2b_with_the_power_of_j_of_i1b_on_tr_c2_is_a_variant_of_formulas_with_i2b():
    """I2b = (I1b^2 - J^(-2/3) tr(C^2)) / 2, equal to the right I2b only where J = 1."""
    import numpy as np

    from common.cases import default_material
    from conformance.diagnosis.variants import variants

    (vw,) = [
        v.expression
        for v in variants(default_material("VerondaWestmann"))
        if v.rewrite.code == "power-trC2-in-I2b"
    ]
    assert "J**(-2/3)*(I1**2 - 2*I2)" in vw
    codes = [v.rewrite.code for v in variants(default_material("NeoHookean"))]
    assert "power-trC2-in-I2b" not in codes  # no I2b in its formula

    # the rewrite's value against the right I2b at a state with J != 1
    C = np.diag([1.3, 0.9, 1.1])
    J = np.sqrt(np.linalg.det(C))
    I1, I2 = np.trace(C), 0.5 * (np.trace(C) ** 2 - np.trace(C @ C))
    I1b, I2b = J ** (-2 / 3) * I1, J ** (-4 / 3) * I2
    wrong = (I1b**2 - J ** (-2 / 3) * (I1**2 - 2 * I2)) / 2
    assert (
        abs(wrong - I2b) > 1e-3
        and abs((I1b**2 - J ** (-4 / 3) * (I1**2 - 2 * I2)) / 2 - I2b) < 1e-12
    )


def test_i2_as_the_trace_of_c_inverse_is_a_variant_of_formulas_with_i2b():
    """I2 = tr C^-1: the cofactor form tr cof C = det C tr C^-1 with det C = J^2 dropped, so
    I2b / J^2 for I2b; equal to the right I2b only where J = 1.
    """
    import numpy as np

    from common.cases import default_material
    from conformance.diagnosis.variants import variants

    (mr,) = [
        v.expression
        for v in variants(default_material("MooneyRivlin"))
        if v.rewrite.code == "I2-inverse-trace"
    ]
    assert "(I2b/J**2)" in mr
    C = np.diag([1.3, 0.9, 1.1]) + 0.05
    J = np.sqrt(np.linalg.det(C))
    I2 = 0.5 * (np.trace(C) ** 2 - np.trace(C @ C))
    assert abs(J ** (-4 / 3) * I2 / J**2 - J ** (-4 / 3) * np.trace(np.linalg.inv(C))) < 1e-12
