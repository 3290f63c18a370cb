"""The engine's energy is a mistaken variant's at every state of the kit while its force and
stiffness are not that variant's (conformance.diagnosis.variant_energy): the energy routine
shares a helper with the mistake, the stress routine does not. The frame-twice and C_bar
strain engines are in test_diagnosis_frame_lookup.py and test_diagnosis_strain.py.
"""

from __future__ import annotations

import pytest

from reference_fem import dolfinx_available


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_an_energy_with_i2_typed_with_a_plus_is_named_from_the_energy():
    """Mooney-Rivlin's energy with I2 = (I1^2 + tr C^2)/2 (corpus 11's Veronda-Westmann slip in
    an invariants routine), its force and stiffness the kit's: the formula variant's energy.
    An energy off by a constant is not that.
    """
    import mjed
    from conformance.diagnosis.variants import variants
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle

    def run(energy):
        def engine(case):
            field = mjed.make_force_field(mjed.TetMesh(case.points, case.cells), case.model)
            f, K = field.force_and_stiffness(case.positions)
            return f, K, energy(case, field)

        (outcome,) = check_implementation(
            engine, material="MooneyRivlin", states=("random",)
        ).outcomes
        return outcome.diagnosis

    def i2_plus(case, field):
        (v,) = [v for v in variants(case.model) if v.rewrite.code == "I2-plus"]
        return UFLOracle(case.points, case.cells, v.model).energy(case.positions)

    d = run(i2_plus)
    assert d.findings[0].code == "variant-energy", d.text()
    assert d.findings[0].figures["variant"] == "formula-I2-plus", d.text()
    d = run(lambda case, field: field.energy(case.positions) + 1e-3)
    assert all(f.code != "variant-energy" for f in d.findings), d.text()
