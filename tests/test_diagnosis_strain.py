"""The strain measure as a kinematic variant (conformance.diagnosis.kinematics): an engine whose
E is the linearised strain (F + F^T)/2 - I, Green's strain without its 1/2 (C - I), or the
isochoric C_bar's strain (J^(-2/3) C - I)/2, is named
by the check. The engines are written here in UFL, independently of the diagnosis's rewrite.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from common.cases import default_material
from conformance.diagnosis.kinematics import kinematic_variants
from reference_fem import dolfinx_available

_TYPES: dict = {}


def test_strain_variants_are_offered_only_for_formulas_in_e():
    svk = {v.code for v in kinematic_variants(default_material("StVenantKirchhoff"))}
    assert {"strain-no-half", "strain-small", "strain-isochoric"} <= svk
    neo = {v.code for v in kinematic_variants(default_material("NeoHookean"))}
    assert not neo & {"strain-no-half", "strain-small"}  # no E in it: the same energy


def _svk_small_strain(model):
    """St Venant-Kirchhoff with eps = (F + F^T)/2 - I for E."""
    import ufl

    from mjed.materials import StVenantKirchhoff
    from reference_fem.energies import register_energy

    cls = _TYPES.get("svk")
    if cls is None:
        cls = dataclass(frozen=True)(type("_SVKSmall", (StVenantKirchhoff,), {}))

        @register_energy(cls)
        def energy(p, F, frame=None):
            eps = 0.5 * (F + F.T) - ufl.Identity(3)
            return 0.5 * p("lam") * ufl.tr(eps) ** 2 + p("mu") * ufl.tr(eps * eps)

        _TYPES["svk"] = cls
    return cls(**{f: getattr(model, f) for f in model.__dataclass_fields__})


def _costa_no_half(model):
    """Costa with E = C - I (exponential: not a coefficient of its terms)."""
    return _costa_with_strain(model, "no-half")


def _costa_isochoric(model):
    """Costa with E = (J^(-2/3) C - I)/2, the isochoric C_bar's strain (corpus 12)."""
    return _costa_with_strain(model, "isochoric")


def _costa_with_strain(model, which):
    import ufl

    from mjed.materials import Costa
    from reference_fem.energies import register_energy

    cls = _TYPES.get(which)
    if cls is None:
        cls = dataclass(frozen=True)(type(f"_Costa_{which}", (Costa,), {}))

        @register_energy(cls, takes_frame=True)
        def energy(p, F, R):
            J = ufl.det(F)
            C = F.T * F
            if which == "no-half":
                E = C - ufl.Identity(3)
            else:
                E = 0.5 * (J ** (-2.0 / 3.0) * C - ufl.Identity(3))
            Ef = R.T * E * R
            b = {n: p(n) for n in ("b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")}
            B = [
                [b["b_ff"], b["b_fs"], b["b_fn"]],
                [b["b_fs"], b["b_ss"], b["b_sn"]],
                [b["b_fn"], b["b_sn"], b["b_nn"]],
            ]
            Q = sum(B[i][j] * Ef[i, j] ** 2 for i in range(3) for j in range(3))
            return 0.5 * p("a") * (ufl.exp(J ** (-4.0 / 3.0) * Q) - 1.0) + p("k0") * (
                J * ufl.ln(J) - J + 1.0
            )

        _TYPES[which] = cls
    return cls(**{f: getattr(model, f) for f in model.__dataclass_fields__})


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
@pytest.mark.parametrize(
    "material, make, code",
    [
        ("StVenantKirchhoff", _svk_small_strain, "kinematic-strain-small"),
        ("Costa", _costa_no_half, "kinematic-strain-no-half"),
        ("Costa", _costa_isochoric, "kinematic-strain-isochoric"),
    ],
)
def test_an_engine_with_another_strain_measure_is_named(material, make, code):
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle

    def engine(case):
        return UFLOracle(case.points, case.cells, make(case.model)).force_and_stiffness(
            case.positions
        )

    run = check_implementation(engine, material=material, states=("random",), probes=False)
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and named, outcome.diagnosis.text()
    assert named[0].code == code, outcome.diagnosis.text()


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_an_energy_with_the_isochoric_strain_and_a_right_stress_is_named_from_the_energy():
    """The energy routine alone with C_bar's strain (force and stiffness the kit's): its energy
    is the kinematic variant's at the case and every probe (conformance.diagnosis.variant_energy).
    """
    import mjed
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle

    def engine(case):
        field = mjed.make_force_field(mjed.TetMesh(case.points, case.cells), case.model)
        f, K = field.force_and_stiffness(case.positions)
        W = UFLOracle(case.points, case.cells, _costa_isochoric(case.model)).energy(case.positions)
        return f, K, W

    run = check_implementation(engine, material="Costa", states=("random",))
    (outcome,) = run.outcomes
    named = outcome.diagnosis.findings[0]
    assert named.code == "variant-energy", outcome.diagnosis.text()
    assert named.figures["variant"] == "kinematic-strain-isochoric", outcome.diagnosis.text()
