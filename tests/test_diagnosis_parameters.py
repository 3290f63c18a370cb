"""Parameters exchanged or read with another value (issue 29): hypotheses the oracle evaluates
with the parameters themselves changed, for those entering the energy non-linearly (Costa's b_ij
inside exp(Q)), which no linear fit over the terms sees.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pytest
import scipy.sparse as sp

from conformance.diagnosis.parameters import (
    convention_words,
    declared_units,
    elastic_convention_words,
    exchanges,
)
from conformance.diagnosis.refit import Target, refit
from mjed.materials import Costa, MooneyRivlin, StVenantKirchhoff, VerondaWestmann
from reference_fem import dolfinx_available

COSTA = Costa(a=800.0, k0=3.0e4, b_ff=18.5, b_fs=2.8, b_ss=3.6, b_fn=2.0, b_sn=1.6, b_nn=3.6)


def test_units_are_read_from_the_declaration_and_only_like_units_are_exchanged():
    units = declared_units(COSTA)
    assert units["a"] == units["k0"] == "Pa" and units["b_ff"] == "dimensionless"
    pairs = {(x.p, x.q) for x in exchanges(COSTA)}
    assert ("b_ff", "b_ss") in pairs and ("a", "k0") in pairs
    assert ("a", "b_ff") not in pairs  # Pa and dimensionless
    assert ("b_ss", "b_nn") not in pairs  # equal values: the exchange changes nothing
    veronda = VerondaWestmann(c1=1000.0, c2=1.5, k0=3e4)
    assert {(x.p, x.q) for x in exchanges(veronda)} == {("c1", "k0")}  # c2 is dimensionless


def _nonlinear(values):
    """A stand-in for the oracle: f = exp(b x) per entry, K = diag(b exp(b x))."""
    b = values[0]
    x = np.linspace(0.1, 1.0, 12)
    return np.exp(b * x).reshape(4, 3), sp.diags(b * np.exp(b * x)).tocsr()


def test_refit_finds_a_value_inside_an_exponential_and_gives_up_on_noise():
    f, K = _nonlinear([2.2])
    fit = refit(_nonlinear, [1.5], Target(f, K, 10.0, 10.0, 1e-10, 1e-10))
    assert fit is not None and fit.agrees and fit.values[0] == pytest.approx(2.2, rel=1e-10)
    noise = np.random.default_rng(0).standard_normal(f.shape)
    assert refit(_nonlinear, [2.2], Target(f + noise, K, 10.0, 10.0, 1e-10, 1e-10)) is None


def _checked(material, changed):
    """The diagnosis of MJED on ``changed(case.model)`` checked as ``material`` (cube-small, one
    random state, no probes).
    """
    import mjed
    from conformance.protocol import check_implementation

    logging.disable(logging.INFO)

    def engine(case):
        field = mjed.HyperelasticForceField(
            mjed.TetMesh(case.points, case.cells), changed(case.model)
        )
        f, K = field.force_and_stiffness(case.positions)
        return f, K, field.energy(case.positions)

    run = check_implementation(
        engine, material=material, mesh="cube-small", states=("random",), probes=False
    )
    (outcome,) = run.outcomes
    assert outcome.status == "failed", outcome.diagnosis.text()
    return outcome.diagnosis


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_costa_with_two_b_exchanged_is_named_as_such():
    """MJED on Costa with b_ff and b_ss exchanged, checked on cube-small with the kit's helical
    per-cell frames: named "parameters b_ff and b_ss exchanged", and nothing else.
    """
    d = _checked(COSTA, lambda m: dataclasses.replace(m, b_ff=m.b_ss, b_ss=m.b_ff))
    (cause,) = d.causes
    assert cause.code == "parameters-exchanged", d.text()
    assert cause.title == "parameters b_ff and b_ss exchanged" and cause.figures["residual"] < 1e-10


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_two_parameters_with_other_values_are_refitted_together():
    """MJED on Costa with the transversely isotropic reading of its b's (b_sn given b_ss's value,
    b_fn b_fs's): no parameter refitted alone, no exchange and no order of the values explains
    it; all refitted together do, and each changed value is said with the parameter it is.
    """
    d = _checked(COSTA, lambda m: dataclasses.replace(m, b_sn=m.b_ss, b_fn=m.b_fs))
    assert d.causes, d.text()
    cause = d.causes[0]
    assert cause.code == "parameter-values", d.text()
    assert cause.figures["parameters"] == ["b_fn", "b_sn"]
    assert cause.figures["values"] == pytest.approx([COSTA.b_fs, COSTA.b_ss], rel=1e-8)
    assert "the value of b_ss: b_ss used for b_sn" in cause.title
    assert "the value of b_fs: b_fs used for b_fn" in cause.title


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_parameters_refitted_together_are_not_named_on_alike_cells_alone():
    """On a homogeneous stretch several parameters moved together fit many single slips (a
    second derivative by differences: W1 kept, W11 moved), so there the joint refit names
    nothing; the case takes the cause where the kit's general state names it.
    """
    import mjed
    from conformance.protocol import check_implementation

    logging.disable(logging.INFO)
    changed = dataclasses.replace(COSTA, b_sn=COSTA.b_ss, b_fn=COSTA.b_fs)

    def engine(case):
        model = dataclasses.replace(changed, frame=case.model.frame)
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), model)
        f, K = field.force_and_stiffness(case.positions)
        return f, K, field.energy(case.positions)

    run = check_implementation(
        engine, material=COSTA, mesh="cube-small", states=("uniaxial", "random"), probes=False
    )
    by_state = {o.state: o.diagnosis for o in run.outcomes}
    random, uniaxial = by_state["random"], by_state["uniaxial"]
    assert random.causes[0].code == "parameter-values", random.text()
    head = uniaxial.findings[0]
    assert head.code == "parameter-values" and head.figures.get("named_on"), uniaxial.text()


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_a_parameter_inside_an_exponential_with_another_value_is_refitted():
    """MJED on Veronda-Westmann with c2 (inside exp(c2 (I1b - 3)) and in the I2b term) 10 %
    larger: no term fit explains it; the refit of c2 alone does, and says the value.
    """
    m = VerondaWestmann(c1=1000.0, c2=1.5, k0=3e4)
    d = _checked(m, lambda model: dataclasses.replace(model, c2=1.65))
    assert d.causes, d.text()
    cause = d.causes[0]
    assert cause.code == "parameter-value" and cause.figures["parameter"] == "c2", d.text()
    assert cause.figures["value"] == pytest.approx(1.65, rel=1e-8)
    assert cause.title.startswith("parameter c2 = 1.65 in your engine where the case has 1.5")


def test_a_squared_parameter_is_said_as_another_convention():
    from conformance.diagnosis.parameters import convention_words
    from mjed.materials import ArrudaBoyce

    ab = ArrudaBoyce(mu=1.0, k0=10.0, N=8.0)
    assert "locking stretch" in convention_words(ab, "N", 64.0, 8.0)
    assert "another convention" in convention_words(COSTA, "b_ff", 18.5**2, 18.5)
    assert "square root" in convention_words(ab, "N", np.sqrt(8.0), 8.0)
    assert convention_words(ab, "N", 9.0, 8.0) == ""  # another value, not a convention
    assert convention_words(ab, "N", 1.0, 1.0) == ""
    from mjed.materials import Gent

    gent = Gent(mu=1.0, Jm=10.0, k0=10.0)
    assert "limiting value of I1b" in convention_words(gent, "Jm", 7.0, 10.0)
    assert convention_words(gent, "Jm", 8.0, 10.0) == ""
    assert convention_words(ab, "N", 5.0, 8.0) == ""  # a shift is Gent's Jm's alone


def test_a_bulk_modulus_given_as_abaqus_d1_or_as_an_inverse_is_a_convention():
    """k0 = 3e4 used as D1 = 2/K (corpus 6: the engine's bulk modulus was 2/k0): said so; the
    inverse of any modulus is a compliance; other small values are values.
    """
    from conformance.diagnosis.parameters import convention_words
    from mjed.materials import Yeoh

    yeoh = Yeoh(c10=1e3, c20=-200.0, c30=100.0, k0=3e4)
    assert "D1 = 2/K" in convention_words(yeoh, "k0", 2 / 3e4, 3e4)
    assert "inverse" in convention_words(yeoh, "k0", 1 / 3e4, 3e4)
    assert "inverse" in convention_words(yeoh, "c10", 1e-3, 1e3)
    assert convention_words(yeoh, "k0", 3 / 3e4, 3e4) == ""
    assert "D1" not in convention_words(yeoh, "c10", 2e-3, 1e3)  # D1 is a bulk modulus's


def _reading(code, coefficients=None):
    from conformance.diagnosis.findings import FULL, Finding
    from conformance.diagnosis.readings import Reading

    figs = {} if coefficients is None else {"coefficients": coefficients}
    return Reading(Finding(code, code, FULL, "", figs))


def test_a_parameter_refit_heads_a_term_fit_that_scales_terms_unequally():
    from conformance.diagnosis.readings import _parameters_first

    series = [_reading("term-coefficients", [1.0, 0.125, 0.015625]), _reading("parameter-value")]
    assert [r.finding.code for r in _parameters_first(series)] == [
        "parameter-value",
        "term-coefficients",
    ]
    # one term off, or several scaled alike (a parameter's terms): the term fit stays first
    for a in ([1.0, 2.0, 1.0], [1.0, 2.0, 2.0]):
        kept = [_reading("term-coefficients", a), _reading("parameter-value")]
        assert _parameters_first(kept) == kept
    # the parameter list read in another order heads such a term fit too (corpus 7's
    # ab_props_in_kit_order: N for k0 scales every term of the series unequally)
    reordered = [_reading("term-coefficients", [2.7e-4, 7.1e-8]), _reading("parameters-reordered")]
    assert [r.finding.code for r in _parameters_first(reordered)][0] == "parameters-reordered"


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_arruda_boyce_n_given_as_the_locking_stretch_is_named_as_n():
    """MJED on Arruda-Boyce with N squared (lambda_m given where N is expected, and squared):
    every series term from the second on is off; the cause is N's value, not a term scaled.
    """
    from mjed.materials import ArrudaBoyce

    d = _checked(ArrudaBoyce(mu=1.0, k0=10.0, N=8.0), lambda m: dataclasses.replace(m, N=64.0))
    cause = d.causes[0]
    assert cause.code == "parameter-value" and cause.figures["parameter"] == "N", d.text()
    assert "locking stretch" in cause.title and "scaled" not in cause.title, d.text()


def test_lame_and_bulk_modulus_confused_is_a_convention():
    svk = StVenantKirchhoff(mu=3448.2759, lam=31034.483)
    lam, mu = svk.lam, svk.mu
    words = elastic_convention_words(svk, "lam", lam - 2 * mu / 3, lam)
    assert "bulk modulus" in words and "2 mu/3" in words
    assert "entered where Lame" in convention_words(svk, "lam", lam + 2 * mu / 3, lam)
    # nearby: another value of lam, and mu itself, are no convention
    assert elastic_convention_words(svk, "lam", 0.9 * lam, lam) == ""
    assert elastic_convention_words(svk, "mu", mu - 2 * lam / 3, mu) == ""
    # a bulk modulus with the shear modulus written as 2 (c1 + c2)
    mr = MooneyRivlin(c1=1200.0, c2=400.0, k0=3e4)
    words = elastic_convention_words(mr, "k0", 3e4 + 2 * 3200.0 / 3, 3e4)
    assert "Lame's lambda" in words and "2 (c1 + c2)" in words


def test_parameters_given_each_others_values_are_read_as_another_order():
    """Costa's six b's taken by position in Guccione's order (corpus 6): the refitted values are
    the declared ones rearranged, three or more moved; two moved is an exchange (its own
    reading), and values that are not a rearrangement are values.
    """
    from conformance.diagnosis.parameters import permutation_words, unit_groups

    names = ["b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn"]
    declared = [18.5, 2.8, 3.6, 2.0, 1.6, 3.6]
    fitted = [18.5, 2.0, 2.8, 1.6, 3.6, 3.6]
    words = permutation_words(names, fitted, declared)
    assert "another order" in words and "b_fs = 2 (the case's b_fn)" in words
    assert "b_sn = 3.6 (the case's b_ss or b_nn)" in words
    assert permutation_words(names, [18.5, 2.0, 3.6, 2.8, 1.6, 3.6], declared) is None  # a pair
    assert permutation_words(names, [18.5, 2.0, 2.8, 1.6, 3.7, 3.6], declared) is None
    assert permutation_words(names, declared, declared) is None
    assert ["b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn"] in unit_groups(COSTA)


def test_moduli_converted_through_young_and_poisson_with_one_slip_are_named():
    """Corpus 7: a driver converting (lam, mu) to (E, nu) with nu = lam / (lam + mu) (its 2 lost)
    for a routine that converts back: both moduli change, and the round trip with that slip
    predicts both values; the plane-stress lambda changes lam alone. Nearby: other values, or
    one modulus of a two-modulus slip, are no conversion.
    """
    from conformance.diagnosis.elastic_conversions import matching_conversion
    from conformance.diagnosis.term_fit import TermFit, describe_fit

    values = {"mu": 3448.2758620689656, "lam": 31034.48275862069}
    lam, mu = values["lam"], values["mu"]
    e, nu = mu * (3 * lam + 2 * mu) / (lam + mu), lam / (lam + mu)
    fitted = {"lam": e * nu / ((1 + nu) * (1 - 2 * nu)), "mu": e / (2 * (1 + nu))}
    found = matching_conversion(values, fitted)
    assert len(found) == 1 and "its 2 lost" in found[0].words and "(E, nu)" in found[0].words
    assert matching_conversion(values, {"lam": 1.01 * fitted["lam"], "mu": fitted["mu"]}) == []
    assert matching_conversion(values, {"lam": fitted["lam"]}) == []  # mu changes too
    e, nu = mu * (3 * lam + 2 * mu) / (lam + mu), lam / (2 * (lam + mu))
    plane = matching_conversion(values, {"lam": e * nu / (1 - nu * nu)})
    assert len(plane) == 1 and "plane-stress" in plane[0].words
    # the term fit says the conversion instead of two odd factors
    a = np.array([fitted["lam"] / lam, fitted["mu"] / mu])
    fit = TermFit(a, True, (), ((0.0, 0.0),), True)
    _, readings = describe_fit(fit, [("lam",), ("mu",)], values)
    assert len(readings) == 1 and "nu = lam / (lam + mu)" in readings[0], readings
    fit = TermFit(np.array([1.3, 0.7]), True, (), ((0.0, 0.0),), True)
    _, readings = describe_fit(fit, [("lam",), ("mu",)], values)
    assert not any("(E, nu)" in r for r in readings), readings
    # mu doubled alone (an Ogden routine's 2 mu convention) is what the backward slip
    # mu = E / (1 + nu) gives too: the plain factor first, the conversion as the alternative
    bulk = {"k0": 3e4, "mu": 5e3}
    fit = TermFit(np.array([1.0, 2.0]), True, (), ((0.0, 0.0),), True)
    _, readings = describe_fit(fit, [("k0",), ("mu",)], bulk)
    assert len(readings) == 1 and readings[0].startswith("parameter mu: its terms doubled")
    assert "or k0 and mu converted to (E, nu) and back with mu = E / (1 + nu)" in readings[0]
    # a bulk modulus doubled (D1 = 1/K given to a routine reading K = 2/D1) is said so
    from mjed.materials import Yeoh

    yeoh = Yeoh(c10=1e3, c20=-200.0, c30=100.0, k0=3e4)
    assert "D1 = 1/K" in convention_words(yeoh, "k0", 6e4, 3e4)
    assert "D1 = 2/K" in convention_words(yeoh, "k0", 1.5e4, 3e4)
    assert "D1" not in convention_words(yeoh, "k0", 6.1e4, 3e4)


def test_every_order_of_a_short_parameter_list_but_the_exchanges_is_tried():
    """Gent (mu, Jm, k0): five other orders, less the exchange of mu and k0 (both Pa, the
    exchanges' reading); a model with more than four parameters is not reordered.
    """
    from conformance.diagnosis.parameters import reorderings
    from mjed.materials import Gent

    orders = {x.order for x in reorderings(Gent(mu=2500.0, Jm=10.0, k0=3e4))}
    assert orders == {(0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1)}
    assert reorderings(COSTA) == []


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_a_parameter_list_read_in_a_constructors_order_is_named():
    """An engine whose Gent constructor takes (mu, kappa, Jm), handed the kit's list (mu, Jm,
    k0) by position: Jm and k0 (of different units) exchanged, named as the list's order. Nearby:
    the same two values not exactly exchanged is no reordering.
    """
    from mjed.materials import Gent

    def positional(model):
        mu, kappa, jm = model.mu, model.Jm, model.k0  # the kit's list read by position
        return Gent(mu=mu, Jm=jm, k0=kappa)

    d = _checked("Gent", positional)
    (cause,) = d.causes
    assert cause.code == "parameters-reordered", d.text()
    assert "by position" in cause.title and "(mu, k0, Jm)" in cause.title, cause.title
    assert "Jm = 30000 (the case's k0)" in cause.title
    near = _checked("Gent", lambda m: Gent(mu=m.mu, Jm=m.k0 * 1.001, k0=m.Jm))
    assert all(c.code != "parameters-reordered" for c in near.causes), near.text()


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_parameters_held_in_float32_are_named_and_one_rounded_alone_is_not_said_so():
    """Every parameter rounded to single precision (a float32 parameter struct), the rest in
    double: named as such. Only mu rounded is one parameter with another value, not the
    float32 reading (which rounds them all).
    """
    rounded = lambda m, names: dataclasses.replace(  # noqa: E731
        m, **{n: float(np.float32(getattr(m, n))) for n in names}
    )
    d = _checked("NeoHookean", lambda m: rounded(m, ("mu", "lam")))
    (cause,) = d.causes
    assert cause.code == "parameters-float32", d.text()
    assert "single precision (float32)" in cause.title and "mu = " in cause.title
    d = _checked("NeoHookean", lambda m: rounded(m, ("mu",)))
    assert "parameters-float32" not in [c.code for c in d.causes], d.text()


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_a_parameter_is_not_named_where_its_term_is_not_told_from_others():
    """Yeoh's c30 stress and tangent scaled by 2/3 (its energy right) on the uniaxial state:
    every cell has one I1b, so c10, c20 and c30's terms have the same force and stiffness, and
    refitting c10 alone fits as well as c30: no parameter value is named there.
    """
    import mjed
    from conformance.protocol import check_implementation

    logging.disable(logging.INFO)

    def engine(case):
        model = case.model
        wrong = dataclasses.replace(model, c30=model.c30 * 2.0 / 3.0)
        mesh = mjed.TetMesh(case.points, case.cells)
        f, K = mjed.HyperelasticForceField(mesh, wrong).force_and_stiffness(case.positions)
        return f, K, mjed.HyperelasticForceField(mesh, model).energy(case.positions)

    run = check_implementation(
        engine, material="Yeoh", mesh="cube-small", states=("uniaxial",), probes=False
    )
    (outcome,) = run.outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed", d.text()
    assert not any(c.code == "parameter-value" for c in d.causes), d.text()
    assert any(f.title.startswith("(not told apart here) parameter") for f in d.findings), d.text()


def test_a_refitted_value_in_a_simple_ratio_to_the_case_is_said_so():
    from conformance.diagnosis.readings import _ratio_words

    assert _ratio_words("alpha", 0.5) == " (alpha halved: 1/2 times the case's value)"
    assert "doubled" in _ratio_words("mu", 2.0000000001)
    assert "3/4 times" in _ratio_words("k0", 0.75)
    assert _ratio_words("c2", 1.1) == "" and _ratio_words("c2", 1.0) == ""


def test_a_value_a_case_could_not_tell_apart_is_named_where_the_kit_tells_it():
    """Arruda-Boyce's N = 64 for 8 on a uniaxial stretch (its series terms alike there) is named
    where another case of the kit names the same value in full; another value, or none named
    elsewhere, leaves it an observation.
    """
    from types import SimpleNamespace

    from conformance.diagnosis.findings import FULL, OBSERVED, Finding
    from conformance.diagnosis.readings import _UNTOLD, _told_over_kit

    def value(v, strength, title="parameter N = 64"):
        return Finding("parameter-value", title, strength, "fit", {"parameter": "N", "value": v})

    untold = value(64.0, OBSERVED, _UNTOLD + "parameter N = 64")
    elsewhere = [SimpleNamespace(causes=[value(64.0 * (1 + 1e-12), FULL)])]
    told = _told_over_kit(untold, elsewhere)
    assert told is not None and told.strength == FULL and told.title == "parameter N = 64"
    assert "told apart over the kit" in told.evidence
    assert _told_over_kit(untold, [SimpleNamespace(causes=[value(63.0, FULL)])]) is None
    assert _told_over_kit(untold, [SimpleNamespace(causes=[])]) is None
    assert _told_over_kit(value(64.0, FULL), elsewhere) is None  # not an untold value
