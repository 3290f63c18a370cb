"""A tangent that is a known, published approximation is named as such: the case found by
checking SOFA's MJED plugin (its Ogden differentiates C^p coaxially), kept here without SOFA by
computing that same tangent with the project's MJED engine (Ogden(tangent="sofa")).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from reference_fem import dolfinx_available

pytestmark = [
    pytest.mark.oracle,
    pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx"),
]


def _coaxial_ogden(case):
    import mjed

    model = dataclasses.replace(case.model, tangent="sofa")
    field = mjed.make_force_field(mjed.TetMesh(case.points, case.cells), model)
    return field.force_and_stiffness(case.positions)


def test_coaxial_ogden_tangent_is_named():
    from conformance.protocol import check_implementation

    run = check_implementation(_coaxial_ogden, material="Ogden", states=("uniaxial", "random"))
    assert run.outcomes and all(o.status == "failed" for o in run.outcomes)
    for o in run.outcomes:
        first = o.diagnosis.findings[0]
        assert first.code == "tangent-approximation", o.diagnosis.text()
        assert "SOFA's MJED plugin" in first.title and first.figures["error"] < 1e-12


def test_exact_ogden_is_not_called_an_approximation():
    import meshes
    import mjed
    from common.cases import default_material
    from conformance.diagnosis.approximations import match_approximation

    points, cells, _ = meshes.resolve("single-tet")
    model = default_material("Ogden")
    x = points @ np.diag([1.3, 0.9, 0.8]).T
    K = mjed.make_force_field(mjed.TetMesh(points, cells), model).stiffness(x)
    assert match_approximation(model, points, cells, x, K, 1e-10) is None
    other = default_material("NeoHookean")  # no tangent options: nothing to try
    assert match_approximation(other, points, cells, x, K, 1e-10) is None
