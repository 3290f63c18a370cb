"""The energy's terms named by their formula as the material declares it (issue 29): the term fit
says which term is off in the declaration's own words, with its kind.
"""

from __future__ import annotations

import numpy as np
import pytest

from conformance.diagnosis.energy_terms import formula_terms

ufl = pytest.importorskip("ufl")


def test_a_written_formula_splits_at_its_top_level_signs():
    assert formula_terms("c1 (exp(c2 (I1b - 3)) - 1) - c1 c2 / 2 (I2b - 3) + k0/2 (ln J)^2") == [
        ("+", "c1 (exp(c2 (I1b - 3)) - 1)"),
        ("-", "c1 c2 / 2 (I2b - 3)"),
        ("+", "k0/2 (ln J)^2"),
    ]
    # a leading sign, a sign after an operator and a number's exponent do not split
    assert formula_terms("-mu*J**-2 + 1e-3*x") == [("-", "mu*J**-2"), ("+", "1e-3*x")]


@pytest.mark.parametrize(
    "model, expected",
    [
        (
            "VerondaWestmann",
            {
                ("c1", "c2"): [
                    "the isochoric term c1 (exp(c2 (I1b - 3)) - 1)",
                    "the isochoric term - c1 c2 / 2 (I2b - 3)",
                ],
                ("k0",): ["the volumetric term k0/2 (ln J)^2"],
            },
        ),
        (
            "StVenantKirchhoff",
            {("lam",): ["the term lam/2 (tr E)^2"], ("mu",): ["the term mu tr(E^2)"]},
        ),
        (
            "MooneyRivlin",
            {
                ("c1",): ["the isochoric term c1 (I1b - 3)"],
                ("c2",): ["the isochoric term c2 (I2b - 3)"],
                ("k0",): ["the volumetric term k0/2 (ln J)^2"],
            },
        ),
    ],
)
def test_each_split_term_gets_its_written_formula_and_kind(model, expected):
    """The split's order is UFL's, not the text's: the names follow the terms (the two Veronda
    terms reading c1 and c2 are told apart by the exponential).
    """
    from conformance.diagnosis.energy_terms import Spec, split_terms, symbolic, term_names
    from conformance.diagnosis.term_fit import term_labels
    from mjed.materials.declaration import declarations

    (m,) = [d.default for d in declarations() if type(d.default).__name__ == model]
    labels, names = term_labels(m), term_names(m)
    got: dict = {}
    for lab, name in zip(labels, names):
        got.setdefault(lab, []).append(name)
    assert {k: sorted(v) for k, v in got.items()} == {k: sorted(v) for k, v in expected.items()}
    if model == "VerondaWestmann":  # the exponential term is the one named with exp
        W, _, F = symbolic(m, Spec(), "symbol")
        for term, name in zip(split_terms(W, F), names):
            assert ("exp" in str(term)) == ("exp" in name), (str(term), name)


def test_the_costa_and_ogden_terms_are_anisotropic_and_isochoric():
    from conformance.diagnosis.energy_terms import term_names
    from mjed.materials.declaration import declarations

    by = {type(d.default).__name__: term_names(d.default) for d in declarations()}
    assert "the anisotropic term a/2 (exp(J^(-4/3) Q) - 1)" in by["Costa"]
    assert sum("k0 (J ln J - J + 1) (part" in n for n in by["Costa"]) == 2
    assert by["Ogden"][0].startswith("the isochoric term mu / alpha^2 (J^(-alpha/3)")


def test_the_fit_reading_names_the_term_by_its_formula():
    """A doubled Veronda I2b term, and a halved SVK mu: the reading says the term as declared."""
    from conformance.diagnosis.term_fit import TermFit, describe_fit

    def fit(a):
        return TermFit(np.asarray(a, float), True, (), ((0.0, 0.0),), True)

    labels = [("c1", "c2"), ("c1", "c2"), ("k0",)]
    names = [
        "the isochoric term c1 (exp(c2 (I1b - 3)) - 1)",
        "the isochoric term - c1 c2 / 2 (I2b - 3)",
        "the volumetric term k0/2 (ln J)^2",
    ]
    params = {"c1": 1000.0, "c2": 1.5, "k0": 3e4}
    _, (reading,) = describe_fit(fit([1, 2, 1]), labels, params, names=names)
    assert reading.startswith("the isochoric term - c1 c2 / 2 (I2b - 3) doubled"), reading
    _, (reading,) = describe_fit(fit([1, -1, 1]), labels, params, names=names)
    assert "(I2b - 3) with the wrong sign" in reading
    _, (reading,) = describe_fit(fit([1, -1, 1]), labels, params)  # without names, as before
    assert reading.startswith("the c1 c2 term (2 of 2) with the wrong sign")
    _, (reading,) = describe_fit(
        fit([1, 0.5]),
        [("lam",), ("mu",)],
        {"mu": 1.0, "lam": 4.0},
        names=["the term lam/2 (tr E)^2", "the term mu tr(E^2)"],
    )
    assert reading.startswith("parameter mu: its terms halved") and "mu tr(E^2)" in reading


def test_a_series_part_is_named_by_its_index():
    """Arruda-Boyce's written series sum_{i=1..5}: each of its five parts is labelled with its
    own series term (the split keeps the series' order: its coefficients mu c_i N^(1-i) fall
    with i, which the last assertion checks on the split itself).
    """
    from conftest import MATERIALS

    from conformance.diagnosis.energy_terms import Spec, split_terms, symbolic, term_names

    model = MATERIALS["ArrudaBoyce"]
    names = term_names(model)
    series = [n for n in names if "sum_{i=1..5}" in n]
    assert len(series) == 5
    for i, name in enumerate(series, start=1):
        assert f"(part {i} of 5: the series term i = {i}, mu c_{i} N^(1-{i}) " in name, name
        assert f"(I1b^{i} - 3^{i}))" in name, name
    assert not any("series term" in n for n in names if "sum_{" not in n)
    W, _, F = symbolic(model, Spec())
    leading = [float(str(t).split(" * ")[0]) for t in split_terms(W, F)[:5]]
    assert leading == sorted(leading, reverse=True)
