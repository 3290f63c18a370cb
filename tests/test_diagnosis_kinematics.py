"""The fibre frame pushed forward and re-orthonormalised (conformance.diagnosis.kinematics): the
variant is offered for every model with a frame, and an engine that computes Costa so (written
here with its own Gram-Schmidt, independent of the module's) is named by the check.
"""

from __future__ import annotations

from dataclasses import dataclass

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


_ENGINE_TYPE: dict = {}


def _gram_schmidt_costa(model):
    """Costa's declared energy with R replaced by the orthonormalised push-forward of R, the
    sheet projected with (I - f f^T), as a registered type of its own.
    """
    import ufl

    from mjed.materials import Costa
    from mjed.materials.declaration import declaration_of
    from reference_fem.energies import declared_energy, register_energy

    cls = _ENGINE_TYPE.get("costa")
    if cls is None:
        cls = dataclass(frozen=True)(type("_CostaGramSchmidt", (Costa,), {}))
        costa = declared_energy(declaration_of(Costa).energy)

        def energy(p, F, frame):
            a = F * frame[:, 0]
            f = a / ufl.sqrt(ufl.inner(a, a))
            b = (ufl.Identity(3) - ufl.outer(f, f)) * (F * frame[:, 1])
            s = b / ufl.sqrt(ufl.inner(b, b))
            n = ufl.as_vector([f[1] * s[2] - f[2] * s[1], f[2] * s[0] - f[0] * s[2],
                               f[0] * s[1] - f[1] * s[0]])  # fmt: skip
            R = ufl.as_matrix([[f[i], s[i], n[i]] for i in range(3)])
            return costa(p, F, R)

        register_energy(cls, takes_frame=True)(energy)
        _ENGINE_TYPE["costa"] = cls
    return cls(**{f: getattr(model, f) for f in model.__dataclass_fields__})


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_an_engine_with_the_orthonormalised_deformed_frame_is_named():
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle

    def engine(case):
        o = UFLOracle(case.points, case.cells, _gram_schmidt_costa(case.model))
        f, K = o.force_and_stiffness(case.positions)
        return f, K

    run = check_implementation(engine, material="Costa", states=("random",), probes=False)
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and len(named) == 1, outcome.diagnosis.text()
    assert named[0].code == "kinematic-frame-deformed", outcome.diagnosis.text()
    assert "re-orthonormalised" in named[0].title
