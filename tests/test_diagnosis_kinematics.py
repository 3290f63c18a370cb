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


def test_the_j_power_out_of_the_exponential_is_tried_only_where_it_multiplies_the_argument():
    """Costa's exp(J^(-4/3) Q) has the power as a factor of the argument; Demiray's
    exp(b (I1b - 3)) and Neo-Hookean's energy have none: no such variant there.
    """
    codes = lambda name: [v.code for v in kinematic_variants(default_material(name))]  # noqa: E731
    assert codes("Costa").count("j-power-out-of-exp") == 1
    assert "j-power-out-of-exp" not in codes("Demiray")
    assert "j-power-out-of-exp" not in codes("NeoHookean")


def _costa_engine_j_power_outside(power_kept: bool):
    """Costa with its fibre term written a/2 J^(-4/3) (exp(Q) - 1) (power_kept False: the
    nearby mistake a/2 (exp(Q) - 1), the power dropped), by hyper-dual numbers.
    """
    from hyperdual_engine import density_engine

    def density(model, k, F, R):
        B = model.B
        Ef = R.T * k.E * R
        Q = sum(B[i][j] * Ef[i, j] ** 2 for i in range(3) for j in range(3))
        fibre = 0.5 * model.a * (k.exp(Q) - 1.0)
        if power_kept:
            fibre = k.J ** (-4.0 / 3.0) * fibre
        return fibre + model.k0 * (k.J * k.lnJ - k.J + 1.0)

    engine = density_engine(density, frame_of=lambda model: model.frame)
    return lambda case: engine(case)[:2]


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_costa_with_the_j_power_outside_the_exponential_is_named_and_without_it_is_not():
    from conformance.protocol import check_implementation

    for kept, code in ((True, "kinematic-j-power-out-of-exp"), (False, None)):
        run = check_implementation(
            _costa_engine_j_power_outside(kept),
            material="Costa",
            states=("random",),
            probes=False,
        )
        (outcome,) = run.outcomes
        codes = [f.code for f in outcome.diagnosis.causes]
        assert outcome.status == "failed", outcome.diagnosis.text()
        if code is None:
            assert "kinematic-j-power-out-of-exp" not in codes, outcome.diagnosis.text()
        else:
            assert codes == [code], outcome.diagnosis.text()


def test_the_inverse_map_and_the_ignored_rotation_are_tried_for_every_material():
    from mjed.materials.declaration import declarations

    for d in declarations():
        codes = [v.code for v in kinematic_variants(d.default)]
        assert "inverse-map" in codes and "rotation-ignored" in codes, d.name
    titles = [v.title for v in kinematic_variants(default_material("Yeoh"))]
    assert any("J with its sign flipped" in t for t in titles)  # I1b = J^(2/3) I1
    assert not any(
        "sign flipped" in v.title for v in kinematic_variants(default_material("NeoHookean"))
    )  # no non-integer power of J


def _inverse(F):
    """F^-1 of a hyper-dual Matrix: its cofactors transposed over its determinant."""
    from hyperdual_engine import Matrix

    def cof(i, j):
        a, b, c, d = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
        return F[a, c] * F[b, d] - F[a, d] * F[b, c]

    J = F[0, 0] * cof(0, 0) + F[0, 1] * cof(0, 1) + F[0, 2] * cof(0, 2)
    return Matrix([[cof(j, i) / J for j in range(3)] for i in range(3)])


def _formula_engine(material, kinematics):
    """The declared formula of ``material`` on kinematics(F) (a Namespace), by hyper-dual
    numbers (tests/hyperdual_engine.py): force and stiffness.
    """
    from hyperdual_engine import density_engine

    from mjed.materials.declaration import declaration_of

    formula = declaration_of(type(default_material(material))).energy

    def density(model, k, F, R):
        p = lambda name: float(getattr(model, name))  # noqa: E731
        return formula(p, kinematics(F))

    engine = density_engine(density)
    return lambda case: engine(case)[:2]


def _symmetric_part(F):
    """The namespace of (F + F^T)/2, with J = det F (a rotation leaves it alone)."""
    from hyperdual_engine import Matrix, Namespace, det, ln

    k = Namespace(Matrix([[0.5 * (F[i, j] + F[j, i]) for j in range(3)] for i in range(3)]))
    k.J = det(F)
    k.lnJ = ln(k.J)
    k.I1b, k.I2b = k.J ** (-2.0 / 3.0) * k.I1, k.J ** (-4.0 / 3.0) * k.I2
    return k


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_inverse_map_and_the_ignored_rotation_are_named():
    """Mooney-Rivlin on F^-1: I1b and I2b exchange (I1b(C^-1) = I2b(C)) and (ln J)^2 is even, so
    the engine is exactly c1 and c2 exchanged, and both are said, as one prediction. Neo-Hookean
    on (F + F^T)/2 with J = det F: the rotation ignored.
    """
    from hyperdual_engine import Namespace

    from conformance.protocol import check_implementation

    for material, kinematics, code, words in (
        ("MooneyRivlin", lambda F: Namespace(_inverse(F)), None, ("F^-1", "c1 and c2")),
        ("NeoHookean", _symmetric_part, "kinematic-rotation-ignored", ("(F + F^T)/2",)),
    ):
        run = check_implementation(
            _formula_engine(material, kinematics), material=material, states=("random",)
        )
        (outcome,) = run.outcomes
        named = outcome.diagnosis.causes
        assert outcome.status == "failed" and len(named) == 1, outcome.diagnosis.text()
        assert code is None or named[0].code == code, outcome.diagnosis.text()
        said = named[0].title + named[0].evidence
        assert all(w in said for w in words), outcome.diagnosis.text()


def test_i1_from_part_of_f_is_tried_wherever_the_formula_has_i1():
    titles = [v.title for v in kinematic_variants(default_material("NeoHookean"))]
    assert any("tr(F F)" in t for t in titles) and any("diagonal of F" in t for t in titles)
    titles = [v.title for v in kinematic_variants(default_material("StVenantKirchhoff"))]
    assert not any("diagonal of F" in t for t in titles)  # written in E: no I1 to take


def _i1_from_the_diagonal(F):
    """The namespace of F with I1 = F_11^2 + F_22^2 + F_33^2 (C's trace from F's diagonal)."""
    from hyperdual_engine import Namespace

    k = Namespace(F)
    k.I1 = F[0, 0] * F[0, 0] + F[1, 1] * F[1, 1] + F[2, 2] * F[2, 2]
    k.I1b = k.J ** (-2.0 / 3.0) * k.I1
    return k


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_i1_from_the_diagonal_of_f_is_named():
    from conformance.protocol import check_implementation

    run = check_implementation(
        _formula_engine("NeoHookean", _i1_from_the_diagonal),
        material="NeoHookean",
        states=("random",),
        probes=False,
    )
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and len(named) == 1, outcome.diagnosis.text()
    assert named[0].code == "kinematic-i1-from-part-of-F", outcome.diagnosis.text()
    assert "diagonal of F" in named[0].title


def _reversed(F):
    """The namespace of 2 I - F: an engine whose displacements are u = X - x."""
    from hyperdual_engine import Matrix, Namespace

    return Namespace(Matrix([[float(i == j) * 2.0 - F[i, j] for j in range(3)] for i in range(3)]))


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_displacements_taken_as_rest_minus_current_are_named():
    """Displacements u = X - x: the energy, stress and tangent of 2 I - F, the force -dW/du' at
    u' = -u (minus the variant's force); the same engine with the variant's own force is not it.
    """
    from conformance.protocol import check_implementation

    engine = _formula_engine("NeoHookean", _reversed)

    def rest_minus_current(case):
        f, K = engine(case)
        return -f, K

    run = check_implementation(rest_minus_current, material="NeoHookean", states=("random",))
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and named, outcome.diagnosis.text()
    assert named[0].code == "kinematic-displacement-reversed", outcome.diagnosis.text()
    assert "u = X - x" in named[0].title
    run = check_implementation(engine, material="NeoHookean", states=("random",))
    (outcome,) = run.outcomes
    codes = [c.code for c in outcome.diagnosis.causes]
    assert "kinematic-displacement-reversed" not in codes, outcome.diagnosis.text()


def _c_diagonal(F):
    """The namespace of sqrt(diag C): C's off-diagonal entries lost."""
    from hyperdual_engine import Matrix, Namespace

    d = [sum(F[k, i] * F[k, i] for k in range(3)) ** 0.5 for i in range(3)]
    return Namespace(Matrix([[d[i] if i == j else 0.0 * d[i] for j in range(3)] for i in range(3)]))


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_off_diagonal_entries_of_c_lost_are_named():
    """A spectral engine whose eigen-solver reads the empty triangle of C: the energy of diag C."""
    from conformance.protocol import check_implementation

    run = check_implementation(
        _formula_engine("NeoHookean", _c_diagonal), material="NeoHookean", states=("random",)
    )
    (outcome,) = run.outcomes
    named = outcome.diagnosis.causes
    assert outcome.status == "failed" and named, outcome.diagnosis.text()
    assert named[0].code == "kinematic-c-off-diagonal-lost", outcome.diagnosis.text()
