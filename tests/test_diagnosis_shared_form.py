"""The variants of an energy that differ only in numbers (one term, factors of the powers of J,
the deformed volume) share one compiled form (conformance.diagnosis.shared_form), and give what
each variant's own form gives.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from conftest import MATERIALS, deformed_cube

from reference_fem import dolfinx_available

pytestmark = pytest.mark.skipif(
    not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
)


@dataclass(frozen=True, eq=False)
class OwnForm:
    """A variant evaluated through :func:`energy_terms.build`, the numbers written into the UFL:
    what every variant compiled to before they shared a form.
    """

    model: Any
    spec: Any

    @property
    def frame(self):
        return getattr(self.model, "frame", None)


def _register_own_form():
    from conformance.diagnosis.energy_terms import build
    from reference_fem.energies import register_energy

    @register_energy(OwnForm, takes_frame=True)
    def _energy(p, F, frame):
        return build(p.material.model, F, frame, p.constant, p.material.spec)[0]


@pytest.fixture(scope="module")
def cube():
    _register_own_form()
    return deformed_cube()


def _oracle(mesh, material):
    from reference_fem import UFLOracle

    return UFLOracle(mesh.points, mesh.cells, material)


def _signature(mesh, material) -> str:
    # The residual form's signature is FFCx's cache key: equal signatures, one compiled form.
    return _oracle(mesh, material)._ufl_forms["R"].signature()


def _isochoric_exponents(model) -> list:
    from conformance.diagnosis.energy_terms import Spec, j_power_exponents, symbolic

    return j_power_exponents(symbolic(model, Spec(), lambda v: v)[0])


@pytest.mark.parametrize("name", ["MooneyRivlin", "Costa"])
def test_variants_that_differ_in_numbers_share_one_form(cube, name):
    from conformance.diagnosis.energy_terms import Spec, j_exponents
    from conformance.diagnosis.transformed import TransformedEnergy

    mesh, _ = cube
    model = MATERIALS[name]
    (key, _), *_ = j_exponents(model)
    numeric = [
        Spec(),
        Spec(term=0),
        Spec(term=2),
        Spec(j_power=0.5),
        Spec(j_power=0.0),
        Spec(j_exponents=((key, 0.9),)),
        Spec(deformed_volume=True),
    ]
    signatures = {_signature(mesh, TransformedEnergy(model, s)) for s in numeric}
    assert len(signatures) == 1
    # a variant that changes the kinematics has a form of its own
    other = _signature(mesh, TransformedEnergy(model, Spec(transpose=True)))
    assert other not in signatures


def _specs(model):
    from conformance.diagnosis.energy_terms import Spec, j_exponents, split_terms, symbolic

    W, _, F = symbolic(model, Spec())
    last = len(split_terms(W, F)) - 1
    fitted = tuple((key, 0.93 + 0.05 * i) for i, (key, _) in enumerate(j_exponents(model)))
    specs = [Spec(term=0), Spec(term=last), Spec(j_power=0.0), Spec(j_power=2.0)]
    specs += [Spec(j_exponents=fitted), Spec(deformed_volume=True)]
    exponents = _isochoric_exponents(model)
    if len(exponents) > 1:  # one power of J alone
        specs.append(Spec(j_power=0.5, j_power_of=exponents[1]))
    return specs


@pytest.mark.parametrize("name", ["MooneyRivlin", "Ogden"])
def test_the_shared_form_gives_what_the_variants_own_form_gives(cube, name):
    """Force, stiffness and energy to round-off, each term alone included (the rest constant
    belongs to the whole energy, not to a term), for a material with two powers of J and one
    whose power of J reads a parameter.
    """
    from conformance.diagnosis.transformed import TransformedEnergy

    mesh, x = cube
    model = MATERIALS[name]
    plain_K = _oracle(mesh, model).stiffness(x)
    for spec in _specs(model):
        shared = _oracle(mesh, TransformedEnergy(model, spec))
        own = _oracle(mesh, OwnForm(model, spec))
        f, K = shared.force_and_stiffness(x)
        f0, K0 = own.force_and_stiffness(x)
        scale_f, scale_K = np.abs(f0).max(), abs(K0).max()
        assert np.abs(f - f0).max() <= 1e-12 * scale_f, spec
        assert abs(K - K0).max() <= 1e-12 * scale_K, spec
        assert abs(K - plain_K).max() > 1e-6 * scale_K, f"{spec} is the energy itself"
        assert shared.energy(x) == pytest.approx(own.energy(x), rel=1e-12, abs=1e-15), spec


def test_a_term_beyond_the_split_is_refused(cube):
    from conformance.diagnosis.energy_terms import Spec
    from conformance.diagnosis.transformed import TransformedEnergy

    mesh, _ = cube
    with pytest.raises(ValueError, match="term 9 of 3"):
        _oracle(mesh, TransformedEnergy(MATERIALS["MooneyRivlin"], Spec(term=9)))
