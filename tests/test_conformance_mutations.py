"""Every mistake of the mutation catalogue (tests/conformance_mutations.py) is detected and
named.
"""

from __future__ import annotations

import logging

import pytest

from mjed.materials import declarations
from reference_fem import dolfinx_available

pytestmark = [
    pytest.mark.oracle,
    pytest.mark.skipif(
        not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
    ),
]

logging.disable(logging.INFO)  # FFCx logs every compilation


@pytest.fixture(scope="module")
def oracles():
    """One cache of oracles for the module's checks: they share cube-small and most share the
    material, so the reference and the diagnosis' candidate energies are built once.
    """
    from conformance.judge.oracle import OracleCache

    return OracleCache()


@pytest.fixture(scope="module")
def runs(oracles):
    from conformance_mutations import MATERIAL, MUTATIONS, broken_engine

    from conformance.protocol import check_implementation

    return {
        name: check_implementation(
            broken_engine(name),
            material=MATERIAL,
            mesh="cube-small",
            states=("uniaxial", "random"),
            cache=oracles,
        )
        for name in MUTATIONS
    }


from conformance_mutations import EXPECTED  # noqa: E402


@pytest.mark.parametrize("mutation", list(EXPECTED))
def test_mutation_is_named(runs, mutation):
    run = runs[mutation]
    expected = EXPECTED[mutation]
    for outcome in run.outcomes:
        d = outcome.diagnosis
        if expected is None:
            assert outcome.status == "passed", d.text()
            continue
        assert outcome.status == "failed", d.text()
        codes = [f.code for f in d.causes]
        if expected == "finite-difference":  # no correction makes it exact: named first, with h
            import meshes
            from common.tolerances import mean_edge_length

            first = d.findings[0]
            assert first.code == expected and not codes, d.text()
            h = 1e-6 * mean_edge_length(*meshes.resolve("cube-small")[:2])
            assert first.figures["step"] == pytest.approx(h, rel=1e-2)
            assert first.figures["explained"] > 0.999
        else:
            assert codes and codes[0] == expected, d.text()
            assert d.causes[0].figures["residual"] <= 1e-10
        if mutation == "stiffness not the derivative of the force":
            assert "inconsistent-stiffness" in [f.code for f in d.findings], d.text()
            assert d.causes[0].figures["rest"], d.text()


def test_the_named_figures(runs):
    """The evidence carries the fitted numbers, not only the name."""

    def cause(name, state="random"):
        (o,) = [o for o in runs[name].outcomes if o.state == state]
        return o.diagnosis.causes[0]

    assert cause("factor 2").figures["ratio"] == pytest.approx(2.0, rel=1e-12)
    shear = cause("Voigt shear doubled").figures
    assert shear["parts"] == ["shear-shear block of the material tangent (Voigt)"]
    assert shear["coefficients"][0] == pytest.approx(1.0, abs=1e-9)
    geo = cause("geometric stiffness missing").figures
    assert geo["parts"] == ["geometric stiffness"] and geo["coefficients"][0] == pytest.approx(
        -1.0, abs=1e-9
    )
    vol = cause("volumetric tangent doubled").figures
    assert vol["parts"] == ["volumetric tangent (J-only terms)"]
    assert (
        "k/2 (J-1)^2 used for the bulk term instead of k/2 (ln J)^2, k = 30000"
        in cause("(J-1)^2 bulk term").evidence
    )
    assert (
        "single J" in cause("(J-1)^2 bulk term", "uniaxial").evidence
    )  # not identifiable from one J: said so
    cell = cause("one cell wrong")
    assert len(cell.figures["cells"]) == 1 and "scaled by 1.5" in cell.title
    (o,) = [o for o in runs["one cell wrong"].outcomes if o.state == "random"]
    (loc,) = [f.figures for f in o.diagnosis.findings if f.code == "localised"]
    assert len(loc["nodes"]) == 4 and loc["cells"] == cell.figures["cells"]
    assert "1-based" in cause("1-based node index").title
    assert "antisymmetric part" in cause("unsymmetric K").evidence


def test_an_unexplained_error_is_called_so(oracles):
    """Random noise on K: no hypothesis may claim it."""
    import numpy as np
    import scipy.sparse as sp
    from conformance_mutations import MATERIAL

    import mjed
    from conformance.protocol import check_implementation

    def noisy(case):
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
        f, K = field.force_and_stiffness(case.positions)
        C = sp.coo_matrix(K)
        noise = np.random.default_rng(0).standard_normal(C.nnz) * 1e-4 * abs(C.data).max()
        N = sp.csr_matrix((noise, (C.row, C.col)), shape=K.shape)
        return f, K + N + N.T

    run = check_implementation(
        noisy,
        material=MATERIAL,
        mesh="cube-small",
        states=("random",),
        probes=False,
        cache=oracles,
    )
    d = run.outcomes[0].diagnosis
    assert not d.causes and d.findings[0].code == "unexplained", d.text()


@pytest.mark.parametrize("material", [d.name for d in declarations()])
@pytest.mark.parametrize(
    "mutation, part, coefficient",
    [
        ("Voigt shear doubled", "shear-shear block of the material tangent (Voigt)", 1.0),
        ("geometric stiffness missing", "geometric stiffness", -1.0),
    ],
)
def test_tangent_parts_on_every_material(oracles, material, mutation, part, coefficient):
    from conformance_mutations import broken_engine

    from common.cases import DEFAULT_MATERIALS
    from conformance.protocol import check_implementation

    run = check_implementation(
        broken_engine(mutation),
        material=DEFAULT_MATERIALS[material],
        mesh="cube-small",
        states=("random",),
        probes=False,
        cache=oracles,
    )
    d = run.outcomes[0].diagnosis
    assert d.causes and d.causes[0].code == "tangent-part", d.text()
    assert d.causes[0].figures["parts"] == [part]
    assert d.causes[0].figures["coefficients"][0] == pytest.approx(coefficient, abs=1e-9)


# ---------------------------------------------------------------- issue 21: single precision
def float32_engine(engine):
    """The engine as a float32 code sees and writes things: coordinates rounded to float32 on the
    way in, force, stiffness and energy rounded to float32 on the way out (the check then holds
    it to single-precision tolerances).
    """
    import dataclasses

    import numpy as np
    import scipy.sparse as sp

    def run(case):
        rounded = dataclasses.replace(
            case,
            points=case.points.astype(np.float32).astype(np.float64),
            positions=case.positions.astype(np.float32).astype(np.float64),
        )
        f, K, W = engine(rounded)
        return np.asarray(f, dtype=np.float32), sp.csr_matrix(K).astype(np.float32), np.float32(W)

    return run


@pytest.fixture(scope="module")
def runs_single(oracles):
    """Verdicts only: what is tested here is the tolerance and the verdict at single precision
    (the causes are the double-precision runs' tests).
    """
    from conformance_mutations import MATERIAL, MUTATIONS, broken_engine

    from conformance.protocol import check_implementation

    return {
        name: check_implementation(
            float32_engine(broken_engine(name)),
            material=MATERIAL,
            mesh="cube-small",
            states=("random",),
            read_causes=False,
            cache=oracles,
        )
        for name in MUTATIONS
    }


@pytest.mark.parametrize("mutation", list(EXPECTED))
def test_mutation_in_float32_still_fails_at_single_precision(runs_single, mutation):
    (outcome,) = runs_single[mutation].outcomes
    d = outcome.diagnosis
    assert d.tolerances.precision == "single", d.text()
    if EXPECTED[mutation] is None:
        assert outcome.status == "passed", d.text()
        assert "PASSED at single precision" in d.text()
    elif mutation == "finite-difference tangent":
        # The one exception, and rightly so: forward differences with h = 1e-6 of the edge are off
        # by 5e-6, below what float32 resolves on this case (tolerance about 5e-5).
        assert d.errors.stiffness < d.tolerances.stiffness, d.text()
    else:
        assert outcome.status == "failed", d.text()


# ---------------------------------------------------------------- issue 29: families of mistakes
from conformance_mutations import FAMILY  # noqa: E402


@pytest.fixture(scope="module")
def family_runs(oracles):
    from common.cases import DEFAULT_MATERIALS
    from conformance.protocol import check_implementation

    cache: dict = {}

    def run(name):
        if name not in cache:
            material, engine, _ = FAMILY[name]
            cache[name] = check_implementation(
                engine,
                material=DEFAULT_MATERIALS[material],
                mesh="cube-small",
                states=("random",),
                probes=False,
                cache=oracles,
            )
        return cache[name]

    return run


@pytest.mark.parametrize("name", list(FAMILY))
def test_family_mistake_is_named(family_runs, name):
    """Each family's mistake is named first, by the mechanism that covers the family; nothing is
    ever called float32 round-off, and no cause is ambiguous where the case tells them apart.
    """
    (outcome,) = family_runs(name).outcomes
    d = outcome.diagnosis
    expected = FAMILY[name][2]
    codes = [f.code for f in d.findings]
    assert outcome.status == "failed", d.text()
    assert "single-precision" not in codes and "ambiguous" not in codes, d.text()
    if expected == "systematic-small":  # small, systematic, not identified: said so, honestly
        assert codes[0] == "unexplained" and expected in codes and not d.causes, d.text()
        return
    if expected == "finite-difference":  # no correction makes it exact: named first, with h
        assert codes[0] == expected and not d.causes, d.text()
        figs = d.findings[0].figures
        scheme, rule = name.split(" differences")[0], figs["rule"]
        assert figs["scheme"] == scheme and figs["explained"] > 0.99, d.text()
        assert rule == ("absolute" if scheme == "central" else "relative"), d.text()
        assert figs["step"] == pytest.approx(1e-4 if scheme == "central" else 1e-6, rel=0.05)
        return
    assert d.causes and d.causes[0].code == expected, d.text()
    assert d.causes[0].figures["residual"] <= 1e-10


@pytest.mark.parametrize(
    "name, words",
    [
        ("Mooney-Rivlin c1 and c2 exchanged", "parameters c1 and c2 exchanged"),
        ("St Venant-Kirchhoff lam and mu exchanged", "exchanged"),
        ("Neo-Hookean mu read in kPa", "other units"),
        ("Mooney-Rivlin c2 term with the wrong sign", "c2: its terms with the wrong sign"),
        ("Yeoh c20 term dropped", "c20: its terms missing"),
        ("Mooney-Rivlin c1 off by 6e-6 (float64)", "c1 slightly off"),
        ("Ogden with J^(-alpha/6)", "isochoric power of J halved"),
        ("Costa with F transposed", "C and B confused"),
        (
            "Mooney-Rivlin J^(-0.666667) (float64)",
            "J^(-2/3) of the formula is J^(-0.666667) in your engine",
        ),
    ],
)
def test_family_reading_in_words(family_runs, name, words):
    (outcome,) = family_runs(name).outcomes
    assert words in outcome.diagnosis.causes[0].title, outcome.diagnosis.text()


def test_the_fitted_coefficient_of_a_slightly_wrong_parameter(family_runs):
    (outcome,) = family_runs("Mooney-Rivlin c1 off by 6e-6 (float64)").outcomes
    figs = outcome.diagnosis.causes[0].figures
    c1 = figs["terms"].index(["c1"])
    assert figs["coefficients"][c1] == pytest.approx(1 + 6e-6, abs=1e-9)
