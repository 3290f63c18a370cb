"""Rewritten formulas (issue 29): I2 with tr(C^2) written from part of C."""

from __future__ import annotations

import logging

import pytest

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
