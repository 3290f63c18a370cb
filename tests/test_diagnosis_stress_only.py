"""Readings of another energy said of the stress and tangent only (conformance.diagnosis.readings
.stress_only): where the engine's energy is the oracle's, a term fit names the terms whose
derivatives are off, not a parameter's value (which would change the energy too).
"""

from __future__ import annotations

from types import SimpleNamespace

from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.hypotheses import common_factor_name
from conformance.diagnosis.readings import stress_only


def _fit(title: str) -> Finding:
    return Finding(
        "term-coefficients",
        title,
        FULL,
        "the engine's force and stiffness are the oracle's per-term ones combined as ...",
        {
            "coefficients": [1.0, 2.0 + 1e-12],
            "terms": [["k0"], ["mu", "Jm"]],
            "term_names": [
                "the volumetric term k0/2 (ln J)^2",
                "the isochoric term - mu Jm/2 ln(1 - (I1b - 3)/Jm)",
            ],
        },
    )


def _diagnosis(energy_error, findings=()):
    return SimpleNamespace(
        errors=SimpleNamespace(energy=energy_error),
        tolerances=SimpleNamespace(energy=1e-10),
        findings=list(findings),
    )


def test_with_the_energy_right_a_parameter_story_becomes_the_terms_derivative():
    story = "k0 and mu converted to (E, nu) and back with mu = E / (1 + nu): mu = 5000"
    (said,) = stress_only([_fit(story)], _diagnosis(1e-15))
    assert said.title.startswith(
        "the stress and tangent of the isochoric term - mu Jm/2 ln(1 - (I1b - 3)/Jm) doubled"
    ), said.title
    assert "your energy right" in said.title and "(E, nu)" not in said.title
    assert "volumetric" not in said.title  # the term at 1 is not said
    assert story in said.evidence  # what force and stiffness alone allow, kept as evidence


def test_with_the_energy_wrong_or_absent_the_story_stands():
    story = "parameter mu = 5000 in your engine where the case has 2500"
    (said,) = stress_only([_fit(story)], _diagnosis(0.3))
    assert said.title == story
    (said,) = stress_only([_fit(story)], _diagnosis(None))
    assert said.title == story


def test_a_power_of_1000_is_said_as_units():
    assert "units" in common_factor_name(1e-3, 1.0, False)
    assert "units" in common_factor_name(1e6, 1.0, False)
    assert common_factor_name(7.0, 1.0, False) == "factor 7"
