"""The diagnosis' pure parts, without the oracle: consistency probes, convention corrections,
localisation.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh

from conformance.diagnosis.diagnose import diagnose
from conformance.diagnosis.hypotheses import component_major_to_node_major, describe_permutation
from conformance.judge.compare import scales
from conformance.judge.consistency import PROBE_TOL, consistency


def quartic(x):
    """W = sum x^4 / 4 + sum x_i x_{i+1}: force and exact Hessian."""
    flat = x.ravel()
    f = -(flat**3 + np.roll(flat, 1) + np.roll(flat, -1))
    n = flat.size
    off = sp.diags([np.ones(n - 1), np.ones(n - 1)], [-1, 1]) + sp.csr_matrix(
        ([1.0, 1.0], ([0, n - 1], [n - 1, 0])), shape=(n, n)
    )
    K = sp.diags(3 * flat**2) + off
    W = float(np.sum(flat**4) / 4 + np.sum(flat * np.roll(flat, -1)))
    return f.reshape(x.shape), K.tocsr(), W


def test_consistency_of_an_exact_and_a_wrong_tangent():
    rng = np.random.default_rng(0)
    x = rng.uniform(0.5, 1.5, (6, 3))
    d = rng.standard_normal(x.shape) * 1e-3
    probes = [(x + d / 2**k, *[quartic(x + d / 2**k)[i] for i in (0, 2)]) for k in range(4)]
    f, K, W = quartic(x)
    good = consistency(x, f, K, W, probes)
    assert good.force_stiffness < 1e-8 and good.energy_force < 1e-8
    assert all(abs(r - 2) < 0.05 for r in good.rates_force)
    bad = consistency(x, f, 1.01 * K, W, probes)
    assert (
        bad.force_stiffness == pytest.approx(0.01 / 1.01, rel=1e-6)
        and bad.force_stiffness > PROBE_TOL
    )  # relative to K d
    assert all(abs(r - 1) < 0.1 for r in bad.rates_force)
    assert (
        consistency(x, f, K, W, probes[:1]).force_stiffness is None
    )  # one probe: not measured, said so


def test_permutation_words():
    assert "offset by +1" in describe_permutation((np.arange(10) + 1) % 10)
    assert "1-based" in describe_permutation((np.arange(10) + 1) % 10)
    assert "nodes permuted: 2 of 10 nodes moved (3->4, 4->3)" in describe_permutation(
        np.array([0, 1, 2, 4, 3, 5, 6, 7, 8, 9])
    )


def test_component_major_map():
    n = 4
    f = np.arange(12.0).reshape(n, 3)  # node-major
    written = f.T.ravel()  # what a component-major engine writes
    assert np.array_equal(written[component_major_to_node_major(n)].reshape(n, 3), f)


def _synthetic(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    n = len(points)
    rng = np.random.default_rng(seed)
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(-1, 12)
    blocks = rng.standard_normal((len(cells), 12, 12))
    blocks = blocks @ np.swapaxes(blocks, 1, 2)
    K = sp.csr_matrix(
        (blocks.ravel(), (np.repeat(dofs, 12, axis=1).ravel(), np.tile(dofs, (1, 12)).ravel())),
        shape=(3 * n, 3 * n),
    )
    return points, cells, rng.standard_normal((n, 3)), K


def _diagnose_synthetic(points, cells, f, K, f_o, K_o, W=None, consistency=None):
    """The diagnosis of (f, K) against (f_o, K_o) at rest positions: without energies, or the
    engine's energy ``W`` against the oracle's 0 (energy scale 1); probes' ``consistency``.
    """
    s = scales(0.5, 0.0 if W is None else 1.0, f_o, K_o)
    return diagnose(
        "synthetic",
        f=f,
        K=K,
        W=W,
        f_o=f_o,
        K_o=K_o,
        W_o=0.0,
        s=s,
        points=points,
        cells=cells,
        x=points,
        consistency=consistency,
    )


@pytest.mark.parametrize(
    "mistake, code",
    [
        (lambda f, K, cells: (-f, K), "force-sign"),
        (lambda f, K, cells: (f, -K), "stiffness-sign"),
        (lambda f, K, cells: (f.T.reshape(-1, 3), K), "dof-order-force"),
        (lambda f, K, cells: (0.5 * f, 0.5 * K), "scale"),
    ],
)
def test_conventions_named_without_the_oracle(mistake, code):
    points, cells, f_o, K_o = _synthetic()
    f, K = mistake(f_o, K_o, cells)
    d = _diagnose_synthetic(points, cells, f, K, f_o, K_o)
    assert d.verdict == "failed" and d.causes and d.causes[0].code == code, d.text()


def test_localised_error_lists_the_cell():
    points, cells, f_o, K_o = _synthetic(1)
    f = f_o.copy()
    f[cells[7]] += 1e-3
    d = _diagnose_synthetic(points, cells, f, K_o, f_o, K_o)
    (cause,) = d.causes
    assert (
        cause.code == "localised"
        and 7 in cause.figures["cells"]
        and len(cause.figures["nodes"]) == 4
    )
    assert d.node_error[cells[7]].min() > 0 and np.count_nonzero(d.node_error) == 4


def test_a_graded_error_whose_tail_passes_is_not_a_place():
    """One error on every node, much larger on one cell's (a step's truncation grows with each
    cell's strain): the tail below the tolerance is still the same error, not round-off, so no
    place is named; the same error on the cell alone (the rest exact) is one.
    """
    points, cells, f_o, K_o = _synthetic(1)
    rng = np.random.default_rng(4)
    scale = np.abs(f_o).max()
    graded = 1e-11 * scale * rng.standard_normal(f_o.shape)  # under the tolerance alone
    graded[cells[7]] += 5e-9 * scale
    d = _diagnose_synthetic(points, cells, f_o + graded, K_o, f_o, K_o)
    assert d.verdict == "failed"
    assert not any(c.code == "localised" for c in d.causes), d.text()
    alone = np.zeros_like(f_o)
    alone[cells[7]] = graded[cells[7]]
    d = _diagnose_synthetic(points, cells, f_o + alone, K_o, f_o, K_o)
    assert [c.code for c in d.causes] == ["localised"], d.text()


def test_nothing_claimed_for_noise():
    points, cells, f_o, K_o = _synthetic(2)
    f = f_o + np.random.default_rng(9).standard_normal(f_o.shape) * 1e-3
    d = _diagnose_synthetic(points, cells, f, K_o, f_o, K_o)
    assert not d.causes and d.findings[0].code == "unexplained"


def _noisy_force_with(W, consistency):
    """The diagnosis of a force off by noise (stiffness and, with ``W`` = 0, energy right)."""
    points, cells, f_o, K_o = _synthetic(3)
    f = f_o + np.random.default_rng(3).standard_normal(f_o.shape) * 1e-3
    return _diagnose_synthetic(points, cells, f, K_o, f_o, K_o, W, consistency)


def test_an_unexplained_force_is_localised_to_the_stress_only_on_the_engines_own_evidence():
    """Energy right, force not its derivative, stiffness the derivative of the force: the
    unexplained finding says where to look (the stress formula); with any of the three
    missing or not holding it does not.
    """
    from conformance.judge.consistency import Consistency

    said = "the mistake is in the force's stress formula"
    stress_wrong = Consistency(force_stiffness=1e-11, energy_force=5e-3)
    d = _noisy_force_with(0.0, stress_wrong)
    assert not d.causes and d.findings[0].code == "unexplained", d.text()
    assert said in d.findings[0].evidence
    for W, c in (
        (None, stress_wrong),  # no energy
        (1e-3, stress_wrong),  # energy wrong
        (0.0, None),  # no probes
        (0.0, Consistency(force_stiffness=1e-3, energy_force=5e-3)),  # K not the force's
        (0.0, Consistency(force_stiffness=1e-11, energy_force=1e-12)),  # force the energy's
    ):
        d = _noisy_force_with(W, c)
        assert said not in d.findings[0].evidence, (W, c)


# ---------------------------------------------------------------- issue 29: never a wrong cause
def _mjed(material, seed=0):
    """MJED's (f, K) on a jittered box at a random deformation, for the given material."""
    import mjed

    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    x = points + 0.05 * np.random.default_rng(seed).standard_normal(points.shape)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material)
    f, K = field.force_and_stiffness(x)
    return f, sp.csr_matrix(K)


def test_float32_signature_tells_rounding_from_a_small_systematic_error():
    """A float64 engine with a parameter off by 6e-6 keeps the balance of the forces and of K's
    rows (its error comes from an energy); the same output rounded to float32 breaks it as float32
    rounding does. Only the latter may be called float32.
    """
    import dataclasses

    from conformance.diagnosis.roundoff import signature
    from mjed.materials import MooneyRivlin

    m = MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4)
    f_o, K_o = _mjed(m)
    f_s, K_s = _mjed(dataclasses.replace(m, c1=m.c1 * (1 + 6e-6)))
    systematic = signature(f_s, K_s, f_o, K_o)
    assert not systematic.float32_like and systematic.balance < 1e-6, systematic.text()
    assert "systematic" in systematic.text() and systematic.representable < 0.01
    rounded = signature(f_o.astype(np.float32).astype(np.float64), K_o.astype(np.float32), f_o, K_o)
    assert rounded.float32_like and rounded.representable == 1.0, rounded.text()


def test_coupled_terms_are_ambiguous_not_named():
    """Two terms with the same force and stiffness on the cases fitted: the fit agrees, names
    neither, and says which terms it cannot tell apart.
    """
    from conformance.diagnosis.readings import term_reading
    from conformance.diagnosis.term_fit import TermCase

    f_o, K_o = _mjed(__import__("mjed").materials.MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4))
    third = (0.25 * f_o, 0.25 * K_o)
    case = TermCase(
        [0.5 * f_o, third[0], third[0]],
        [0.5 * K_o, third[1], third[1]],
        1.25 * f_o,
        1.25 * K_o,
        float(np.linalg.norm(f_o)),
        float(sp.linalg.norm(K_o)),
        1e-10,
        1e-10,
    )
    r = term_reading([("a",), ("b",), ("c",)], [case], {"a": 1.0, "b": 2.0, "c": 3.0}, 1.0)
    assert r.finding.code == "term-coefficients-ambiguous" and r.finding.strength == "observed"
    assert "b, c" in r.finding.title


def test_two_distinct_readings_are_both_shown_as_ambiguous():
    from conformance.diagnosis.findings import FULL, Finding
    from conformance.diagnosis.readings import Reading, merge_readings

    f_o, K_o = _mjed(__import__("mjed").materials.NeoHookean(mu=1000.0, lam=5000.0))
    s = scales(0.5, 0.0, f_o, K_o)

    def reading(code, factor):
        return Reading(Finding(code, code, FULL, "", {}), factor * f_o, factor * K_o)

    (one,) = merge_readings([reading("a", 1.0), reading("b", 1.0)], s)
    assert one.code == "a" and "equivalently" in one.evidence and "b" in one.evidence
    lead, a, b = merge_readings([reading("a", 1.0), reading("b", 1.0 + 1e-6)], s)
    assert lead.code == "ambiguous" and lead.figures["codes"] == ["a", "b"]
    assert a.title.startswith("(ambiguous)") and b.title.startswith("(ambiguous)")


def test_the_kit_fit_separates_what_one_case_cannot():
    """Case A cannot tell its last two terms apart (the same force and stiffness); case B can.
    The fit over both names the third term, tripled, and gives the reading to both cases.
    """
    from dataclasses import dataclass, field

    import mjed
    from conformance.diagnosis.findings import OBSERVED, Finding
    from conformance.diagnosis.readings import kit_term_reading, term_reading
    from conformance.diagnosis.term_fit import TermCase

    M = mjed.materials
    P, Q, R = (
        _mjed(M.NeoHookean(mu=1000.0, lam=5000.0)),
        _mjed(M.MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4)),
        _mjed(M.StVenantKirchhoff(mu=3000.0, lam=9000.0)),
    )

    def case(terms, coefficients):
        f = sum(c * t[0] for c, t in zip(coefficients, terms))
        K = sum(c * t[1] for c, t in zip(coefficients, terms))
        fs, Ks = float(np.linalg.norm(f)), float(sp.linalg.norm(K))
        return TermCase([t[0] for t in terms], [t[1] for t in terms], f, K, fs, Ks, 1e-10, 1e-10)

    labels = [("a",), ("b",), ("c",)]
    params = {"a": 1.0, "b": 2.0, "c": 5.0}
    A, B = case([P, Q, Q], (1, 1, 3)), case([P, Q, R], (1, 1, 3))
    alone = term_reading(labels, [A], params, 1.0)
    assert alone.finding.code == "term-coefficients-ambiguous"

    @dataclass(frozen=True)
    class D:
        findings: list = field(default_factory=list)
        # no energy given, so nothing denies an energy reading (readings.stress_only)
        errors: object = field(default_factory=lambda: SimpleNamespace(energy=None))
        tolerances: object = None

        @property
        def causes(self):
            return [f for f in self.findings if f.strength == "explains"]

    diagnoses = [D([alone.finding]), D([Finding("unexplained", "unexplained", OBSERVED, "")])]
    entries = [(0, labels, A, params), (1, labels, B, params)]
    a, b = kit_term_reading(diagnoses, entries)
    for d in (a, b):
        (first,) = d.findings
        assert first.code == "term-coefficients" and first.figures["cases"] == 2
        assert "the c term tripled" in first.title or "c: its terms tripled" in first.title


def test_two_volumetric_terms_scaled_apart_on_one_j_are_not_named():
    """On one J two J-only terms' factors span any (U', U'') there: fitted as - mu ln J x -0.475
    and lam/2 (ln J)^2 x 1.22 for a sign slipped in d(mu ln J)/dJ. Said as ambiguous on one J,
    named where J varies (the flag is what differs: the same columns).
    """
    from conformance.diagnosis.readings import term_reading
    from conformance.diagnosis.term_fit import TermCase

    M = __import__("mjed").materials
    P, Q, R = (
        _mjed(M.NeoHookean(mu=1000.0, lam=5000.0)),
        _mjed(M.MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4)),
        _mjed(M.StVenantKirchhoff(mu=3000.0, lam=9000.0)),
    )
    a = (1.0, -0.475, 1.22)
    f = sum(c * t[0] for c, t in zip(a, (P, Q, R)))
    K = sum(c * t[1] for c, t in zip(a, (P, Q, R)))
    names = ("the term mu/2 (I1 - 3)", "the volumetric term - mu ln J", "the volumetric term X")
    args = ([P[0], Q[0], R[0]], [P[1], Q[1], R[1]], f, K)
    scales_ = (float(np.linalg.norm(f)), float(sp.linalg.norm(K)), 1e-10, 1e-10)
    labels, params = [("mu",), ("mu",), ("lam",)], {"mu": 1000.0, "lam": 5000.0}
    for one_j, code in ((True, "term-coefficients-ambiguous"), (False, "term-coefficients")):
        case = TermCase(*args, *scales_, names, one_j=one_j)
        r = term_reading(labels, [case], params, 1.0)
        assert r.finding.code == code, r.finding.title
    assert (
        "J is the same in every cell"
        in term_reading(
            labels, [TermCase(*args, *scales_, names, one_j=True)], params, 1.0
        ).finding.title
    )


def test_a_term_scaled_by_an_exponential_of_a_parameter_says_so():
    """Veronda-Westmann's c1 (exp(c2 (I1b - 3)) - 1) written c1 exp(c2 I1b) ...: the term scaled
    by e^(3 c2), the e^(-3 c2) of the shifted argument lost; a factor e^(3 c2) 1e-4 off, or a
    term without an exponential, is not said so.
    """
    from conformance.diagnosis.term_fit import exponential_words

    params = {"c1": 3000.0, "c2": 1.4}
    term = ["the isochoric term c1 (exp(c2 (I1b - 3)) - 1)"]
    said = exponential_words(float(np.exp(3 * 1.4)), params, term, 1e-6)
    assert said is not None and "e^(3 c2)" in said and "e^(-3 c2) lost" in said
    assert "e^(-c2)" in exponential_words(float(np.exp(-1.4)), params, term, 1e-6)
    assert exponential_words(float(np.exp(3 * 1.4)) * (1 + 1e-4), params, term, 1e-6) is None
    plain = ["the isochoric term c1 (I1b - 3)"]
    assert exponential_words(float(np.exp(3 * 1.4)), params, plain, 1e-6) is None


def test_a_factor_of_one_is_not_a_scaling():
    """Round-off at the tolerance is not 'scaled by 1' (found checking SOFA's classical field on a
    sliver in mm: stiffness error 1.04e-10, 'force and stiffness scaled: factor 1' named).
    """
    import numpy as np
    import scipy.sparse as sp

    from conformance.diagnosis.hypotheses import scale_corrections

    rng = np.random.default_rng(0)
    f_o = rng.normal(size=(4, 3))
    K_o = sp.csr_matrix(rng.normal(size=(12, 12)))
    near = scale_corrections(f_o, K_o, f_o * (1 + 1e-12), K_o * (1 + 1e-12), None, None)
    assert near == []
    far = scale_corrections(f_o, K_o, f_o * 1e-6, K_o * 1e-6, None, None)
    assert {code for code, *_ in far} == {"scale", "scale-stiffness", "scale-force"}


def test_the_readings_of_mistakes_run_in_their_declared_order_under_their_conditions():
    """conformance.run.READINGS: which readings a failed case's diagnosis gets, read from the
    declared list alone (the conditions see the diagnosis so far and the case's flags).
    """
    from conformance.run import READINGS

    names = [r.name for r in READINGS]
    assert len(set(names)) == len(names)

    def running(
        force_wrong,
        named=False,
        headline="unexplained",
        mistakes=True,
        causes=True,
        energy=None,
        stiffness_wrong=True,
    ):
        tol = SimpleNamespace(force=1e-10, stiffness=1e-10, energy=1e-10)
        findings = [SimpleNamespace(code=headline)]
        d = SimpleNamespace(
            causes=findings if named else [],
            findings=findings,
            errors=SimpleNamespace(
                force=1e-3 if force_wrong else 1e-12,
                stiffness=1e-3 if stiffness_wrong else 1e-12,
                energy=1e-12,
            ),
            tolerances=tol,
        )
        c = SimpleNamespace(
            read_mistakes=mistakes, read_causes=causes, out=SimpleNamespace(energy=energy)
        )
        return [r.name for r in READINGS if r.when(d, c)]

    force_right = set(running(False)) - set(running(True))
    force_wrong = set(running(True)) - set(running(False))
    assert len(force_wrong) == 8 and all(
        "differences of the energy density" in n
        or "invariant's gradient typed wrongly" in n
        or "giving the force alone" in n
        or "Voigt stress vector" in n
        or "hand-derived stress" in n
        or "f'(J)" in n
        or "stress written wrongly" in n
        or "hand-written stress" in n
        for n in force_wrong
    )
    assert names.index("a known approximation of the tangent") == min(
        names.index(n) for n in force_right
    )
    # a partial reading in the headline stops the difference readings, not the others
    partial = running(False, headline="finite-difference")
    assert set(running(False)) - set(partial) == {
        "differences with a step per cell",
        "differences in the strain, or a perturbation of F (Miehe's, or one of another form)",
        "a complex step or central differences of S in the components of E or C (the step's "
        "truncation), or a relative step's divisor",
        "the elasticity tensor applied to each node direction by differences of the stress "
        "along it (forward or central; one triangle of a cell's blocks mirrored, or not)",
        "central differences of P in each component of F (a first elasticity tensor)",
        "a spectral engine's principal block d tau_a / d ln lambda_b by differences of the "
        "principal Kirchhoff stresses (forward or central in ln lambda, or a relative step)",
    }
    # a cause named by the first diagnosis (no mistakes read): only the tangent term's
    # differences, and only with the force right
    assert running(False, named=True, mistakes=False) == [names[-1]]
    assert running(True, named=True, mistakes=False) == []
    # force and stiffness right and only the energy wrong (here, or by the probes): the energy
    # reading first; not without an energy, nor for a float32 energy, nor with --verdict-only
    energy_first = "the energy alone wrong, force and stiffness right"
    for headline in ("energy", "inconsistent-force"):
        only_energy = running(
            False,
            named=headline == "energy",
            headline=headline,
            mistakes=False,
            energy=1.0,
            stiffness_wrong=False,
        )
        assert only_energy[0].startswith(energy_first), only_energy
    assert not any(
        n.startswith(energy_first)
        for kw in (
            {"headline": "energy-float32"},
            {"headline": "energy", "causes": False},
            {"headline": "energy", "energy": None},
        )
        for n in running(
            False,
            **{"named": True, "mistakes": False, "energy": 1.0, "stiffness_wrong": False, **kw},
        )
    )
    # --verdict-only reads nothing
    assert running(True, mistakes=False, causes=False) == []
    assert running(False, named=True, mistakes=False, causes=False) == []
