"""conformance.diagnosis.readings: a candidate energy is rejected on its force alone only where
no stiffness could make it match (so its stiffness form is never compiled for nothing), and the
oracle compiles each form when first used.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from conformance.diagnosis.readings import _force_may_match
from conformance.judge.compare import DOUBLE, Scales, errors, grown
from reference_fem import dolfinx_available


def _matches(out, f_c, K_c, s, tol) -> bool:
    """_matching's own test, with the candidate's stiffness."""
    e = errors(out.force, out.stiffness, None, f_c, K_c, 0.0, grown(s, f_c, K_c))
    return tol.within(e, energy=False)


@pytest.mark.parametrize("seed", range(40))
def test_a_candidate_that_matches_is_never_rejected_on_its_force(seed):
    """Candidates built near the match boundary, their stiffness up to 1e6 times the oracle's
    scale: whenever the full test matches, the force-only screen lets the candidate through.
    """
    rng = np.random.default_rng(seed)
    n = 12
    s = Scales(force=1.0, stiffness=10.0, energy=1.0)
    tol = replace(DOUBLE, force=1e-3, stiffness=1e-3)
    big = 10.0 ** rng.uniform(0, 6)
    K = sp.random(3 * n, 3 * n, density=0.3, random_state=seed, format="csr") * big * 10
    f = rng.standard_normal((n, 3)) * big
    out = SimpleNamespace(force=f, stiffness=K)
    seen = 0
    for scale in 10.0 ** rng.uniform(-5, -1.5, size=30):
        f_c = f + scale * big * rng.standard_normal(f.shape)
        K_c = K + sp.random(3 * n, 3 * n, density=0.3, random_state=rng.integers(1e9)) * (
            scale * big * 10
        )
        if _matches(out, f_c, K_c, s, tol):
            seen += 1
            assert _force_may_match(out, f_c, s, tol)
    assert seen  # the draw reached matching candidates, so the assertion was exercised


def test_a_candidate_far_off_in_force_is_rejected_and_nan_is_not():
    s = Scales(force=1.0, stiffness=1.0, energy=1.0)
    tol = replace(DOUBLE, force=1e-6, stiffness=1e-6)
    out = SimpleNamespace(force=np.ones((4, 3)), stiffness=sp.identity(12, format="csr"))
    assert not _force_may_match(out, 2.0 * np.ones((4, 3)), s, tol)
    assert _force_may_match(out, np.ones((4, 3)), s, tol)
    nan = SimpleNamespace(force=np.full((4, 3), np.nan), stiffness=out.stiffness)
    assert _force_may_match(nan, np.ones((4, 3)), s, tol)


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)")
def test_the_oracle_compiles_a_form_only_when_it_is_first_used():
    from common.cases import DEFAULT_MATERIALS
    from conformance.judge.oracle import OracleCache
    from conformance.kit.spec import CaseInput
    from reference_fem import UFLOracle

    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    cells = np.array([[0, 1, 2, 3]])
    x = points * 1.05
    oracle = UFLOracle(points, cells, DEFAULT_MATERIALS["NeoHookean"])
    assert not oracle._compiled
    f = oracle.force(x)
    assert set(oracle._compiled) == {"R"}
    case = CaseInput("lazy", points, cells, x, DEFAULT_MATERIALS["NeoHookean"])
    lazy = OracleCache().reference(case, lazy=True)
    eager = OracleCache().reference(case)
    assert np.array_equal(lazy.force, f) and np.array_equal(eager.force, f)
    assert (lazy.stiffness != eager.stiffness).nnz == 0 and lazy.energy == eager.energy


def test_an_energy_reading_is_said_of_the_stress_only_where_the_engine_energy_denies_it():
    """A pressure sign flipped in sigma and c with the energy right: the term fit's "k0: its
    terms with the wrong sign" compares force and stiffness alone, so it is said of them.
    """
    from conformance.diagnosis.findings import FULL, OBSERVED, Finding
    from conformance.diagnosis.readings import stress_only

    cause = Finding(
        "term-coefficients", "parameter k0: its terms with the wrong sign", FULL, "", {}
    )

    def diag(energy, findings=()):
        return SimpleNamespace(
            errors=SimpleNamespace(energy=energy), tolerances=DOUBLE, findings=list(findings)
        )

    (said,) = stress_only([cause], diag(0.0))
    assert said.title.startswith(cause.title) and "stress and tangent only" in said.title
    assert "energy is the oracle's" in said.title
    probes = Finding("inconsistent-force", "force is not minus ...", OBSERVED, "", {})
    (said,) = stress_only([cause], diag(0.2, [probes]))
    assert "not the derivative of your energy" in said.title
    # nearby: the energy differs too (an energy mistake), or no energy given: unchanged
    assert stress_only([cause], diag(0.2)) == [cause]
    assert stress_only([cause], diag(None)) == [cause]


def test_a_parameter_factor_equal_to_the_single_j_of_the_state_is_also_a_volume():
    """On a state with one J (uniaxial), a parameter scaled by J and that parameter's terms
    integrated over the deformed volume are the same engine: the value alone is not named.
    """
    from conftest import box_mesh

    from conformance.diagnosis.readings import _single_j, _single_j_factor
    from conformance.kit.spec import CaseInput
    from mjed.materials import NeoHookean

    points, cells = box_mesh(2, jitter=0.2, seed=3)
    model = NeoHookean(mu=3448.2759, lam=31034.483)
    ci = CaseInput("c", points, cells, points @ np.diag([1.3, 1.0, 1.0]).T, model)
    assert "deformed volume" in _single_j_factor(_single_j(ci), 1.3)
    assert "divided by J" in _single_j_factor(_single_j(ci), 1 / 1.3)
    assert _single_j_factor(_single_j(ci), 1.2) == ""
    rng = np.random.default_rng(0)  # nearby: J varies from cell to cell, a value is a value
    x = points @ np.diag([1.3, 1.0, 1.0]).T + 0.02 * rng.standard_normal(points.shape)
    assert _single_j_factor(_single_j(CaseInput("c", points, cells, x, model)), 1.3) == ""
