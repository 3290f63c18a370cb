"""The fibre frame pushed forward and re-orthonormalised (conformance.diagnosis.kinematics): the
variant is offered for every model with a frame, and an engine that computes Costa so (written
here with its own Gram-Schmidt, independent of the module's) is named by the check.
"""

from __future__ import annotations

import pytest

from common.cases import default_material
from conformance.diagnosis.kinematics import OrthonormalisedFrameEnergy, kinematic_variants
from reference_fem import dolfinx_available


def test_the_orthonormalised_frame_is_tried_only_with_a_frame():
    costa = default_material("Costa")
    found = [v for v in kinematic_variants(costa) if v.orthonormalised]
    assert len(found) == 1 and found[0].code == "frame-deformed"
    assert "re-orthonormalised" in found[0].title and "deformed" in found[0].title
    assert isinstance(found[0].oracle_model(costa), OrthonormalisedFrameEnergy)
    others = [v for v in kinematic_variants(costa) if not v.orthonormalised]
    assert len({v.key() for v in others}) == len(others) and found[0].key() not in {
        v.key() for v in others
    }
    assert not any(v.orthonormalised for v in kinematic_variants(default_material("NeoHookean")))


def _gram_schmidt_costa_engine():
    """Costa's declared energy with R replaced by the orthonormalised push-forward of R, the
    sheet projected with (I - f f^T): written with its own Gram-Schmidt, and differentiated in
    NumPy by hyper-dual numbers (tests/hyperdual_engine.py), so that the engine costs no
    compiled form of its own (the UFL stiffness of this energy takes over a minute to compile).
    """
    from hyperdual_engine import Namespace, density_engine, gram_schmidt_frame

    from mjed.materials import Costa
    from mjed.materials.declaration import declaration_of

    formula = declaration_of(Costa).energy

    def density(model, k, F, R):
        p = lambda name: float(getattr(model, name))  # noqa: E731
        return formula(p, Namespace(F, gram_schmidt_frame(F, R)))

    engine = density_engine(density, frame_of=lambda model: model.frame)
    return lambda case: engine(case)[:2]  # force and stiffness; the energy is not given


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_an_engine_with_the_orthonormalised_deformed_frame_is_named():
    from conformance.protocol import check_implementation

    run = check_implementation(
        _gram_schmidt_costa_engine(), material="Costa", states=("random",), probes=False
    )
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and len(named) == 1, outcome.diagnosis.text()
    assert named[0].code == "kinematic-frame-deformed", outcome.diagnosis.text()
    assert "re-orthonormalised" in named[0].title
