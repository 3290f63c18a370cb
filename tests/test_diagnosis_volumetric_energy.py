"""The volumetric (J-only) energy reading names an energy only when the per-cell change is one
function of J and the engine's own energy does not deny it (corpus 5: a pressure sign flipped
with the energy right, and an I2 typo, were told "volumetric energy differs"). Each engine is
built here: the oracle's stand-in (MJED) plus a per-cell spherical change.
"""

from __future__ import annotations

import numpy as np
from conftest import box_mesh, mjed_split

from conformance.diagnosis.diagnose import (
    _volumetric_findings,
    j_function_residual,
    j_function_steps,
)
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.tangent import _cell_derivatives
from conformance.judge.compare import DOUBLE
from mjed.materials import NeoHookean


def _random_state(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T + 0.04 * rng.standard_normal(points.shape)
    return points, cells, x


MODEL = NeoHookean(mu=3448.2759, lam=31034.483)


def test_a_j_only_function_is_told_from_a_per_cell_pressure():
    rng = np.random.default_rng(1)
    J = rng.uniform(0.85, 1.2, 40)
    g = 1e4 * (np.log10(J) - np.log(J))  # ln J read as log10 J
    dg = 1e4 * (1 / np.log(10) - 1) / J
    assert j_function_residual(J, g, dg) < 1e-3
    # nearby: the same sizes, but depending on another invariant of the cell
    other = rng.uniform(0.8, 1.2, 40)
    assert j_function_residual(J, g * other, dg * other) > 0.1
    assert np.isnan(j_function_residual(np.full(40, 1.1), g, dg))  # one J: nothing told


def _volumetric_engine(points, cells, x, a, b, f_o, K_o):
    """The oracle plus a per-cell spherical change: dU' = a_c, dU'' = b_c (each (m,))."""
    V0, _, dJ, H = _cell_derivatives(points, cells, x)
    V0 = np.abs(V0)
    fe = -(V0 * a)[:, None] * dJ
    Ke = V0[:, None, None] * (
        b[:, None, None] * dJ[:, :, None] * dJ[:, None, :] + a[:, None, None] * H
    )
    df, dK = assemble(cells, points.shape[0], fe.reshape(-1, 4, 3), Ke)
    return f_o + df, (K_o + dK).tocsr()


def _volumetric(points, cells, x, f, K, f_o, K_o, s, denies=False):
    full, partial = [], []
    worst = 1.0
    _volumetric_findings(points, cells, x, f - f_o, (K - K_o).tocsr(), s, worst, DOUBLE, full,
                         partial, denies)  # fmt: skip
    return full, partial


def test_the_volumetric_energy_is_named_only_when_one_function_of_j_and_not_denied():
    points, cells, x = _random_state(2)
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    J = np.abs(_cell_derivatives(points, cells, x)[1])
    g, dg = 2e3 * np.log(J) / J, 2e3 * (1 - np.log(J)) / J**2
    f, K = _volumetric_engine(points, cells, x, g, dg, f_o, K_o)
    full, _ = _volumetric(points, cells, x, f, K, f_o, K_o, s)
    assert [x.code for x in full] == ["volumetric"] and "energy differs" in full[0].title
    # the engine's energy denies it (equal to the oracle's, or not the force's potential)
    full, partial = _volumetric(points, cells, x, f, K, f_o, K_o, s, denies=True)
    assert full == [] and "energy does not say so" in partial[0].title
    # nearby: a per-cell pressure whose coefficient is not a function of J
    other = np.random.default_rng(5).uniform(0.5, 1.5, J.size)
    f, K = _volumetric_engine(points, cells, x, g * other, dg * other, f_o, K_o)
    full, partial = _volumetric(points, cells, x, f, K, f_o, K_o, s)
    assert full == [] and "not as one U(J)" in partial[0].title


def test_a_denied_volumetric_reading_is_the_cause_only_when_nothing_else_is():
    """The energy denies a J-only energy change: the reading is held back for the energy
    readings, and named last as a volumetric stress and tangent difference if none names one.
    """
    from conformance.diagnosis.diagnose import Diagnosis, denied_volumetric
    from conformance.diagnosis.findings import OBSERVED, Finding
    from conformance.judge.compare import Errors

    points, cells, x = _random_state(2)
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    J = np.abs(_cell_derivatives(points, cells, x)[1])
    g, dg = 2e3 * np.log(J) / J, 2e3 * (1 - np.log(J)) / J**2
    f, K = _volumetric_engine(points, cells, x, g, dg, f_o, K_o)
    _, (held,) = _volumetric(points, cells, x, f, K, f_o, K_o, s, denies=True)
    assert held.figures["denied"] is True
    unexplained = Finding("unexplained", "unexplained", OBSERVED, "", {})
    d = Diagnosis("c", "failed", Errors(0.1, 0.1, None, 0.0), [unexplained, held])
    (cause,) = denied_volumetric(d).causes
    assert cause.code == "volumetric" and "stress and tangent differ" in cause.title
    # nearby: not one function of J (never held), or another cause named: unchanged
    other = np.random.default_rng(5).uniform(0.5, 1.5, J.size)
    f, K = _volumetric_engine(points, cells, x, g * other, dg * other, f_o, K_o)
    _, (loose,) = _volumetric(points, cells, x, f, K, f_o, K_o, s, denies=True)
    assert not loose.figures.get("denied")
    d = Diagnosis("c", "failed", Errors(0.1, 0.1, None, 0.0), [unexplained, loose])
    assert denied_volumetric(d) is d
    named = Finding("term-coefficients", "k0 with the wrong sign", "explains", "", {})
    d = Diagnosis("c", "failed", Errors(0.1, 0.1, None, 0.0), [named, held])
    assert denied_volumetric(d) is d


def test_a_tangent_only_change_is_not_held_to_one_function_of_j():
    """U'' changed per cell with the force right (a hand-coded tangent dropping a term): no
    energy is claimed, so the one-function test does not apply and the tangent is named.
    """
    points, cells, x = _random_state(2)
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    J = np.abs(_cell_derivatives(points, cells, x)[1])
    f, K = _volumetric_engine(points, cells, x, 0.0 * J, 3e4 * np.log(J) / J**2, f_o, K_o)
    full, _ = _volumetric(points, cells, x, f, K, f_o, K_o, s)
    assert [x.code for x in full] == ["volumetric"] and "tangent differs" in full[0].title
    assert full[0].figures["j_function_residual"] > 0.1  # not one U(J): the gate would drop it


def test_a_denied_reading_on_a_single_j_is_not_held():
    """On a state with one J the one-function test cannot fail: a denied reading is not held
    for the fallback (an I2 typo's spherical term on a uniaxial state was named so).
    """
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    x = points @ np.diag([1.3, 1.0, 1.0]).T
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    J = np.abs(_cell_derivatives(points, cells, x)[1])
    f, K = _volumetric_engine(points, cells, x, 50.0 + 0 * J, 20.0 + 0 * J, f_o, K_o)
    _, (held,) = _volumetric(points, cells, x, f, K, f_o, K_o, s, denies=True)
    assert held.figures["denied"] is False


def test_j_function_steps_tells_one_function_of_j_from_a_per_cell_coefficient():
    rng = np.random.default_rng(4)
    J = rng.uniform(0.85, 1.2, 60)
    assert j_function_steps(J, 3e4 * np.log(J) / J**2) < 1e-2
    assert j_function_steps(J, np.exp(5 * J)) < 1e-2  # steep
    assert j_function_steps(J, 3e4 * rng.uniform(0.5, 1.5, 60)) > 0.3
    # nearby: mostly a function of J, times an invariant varying by +-20 % from cell to cell
    assert j_function_steps(J, np.exp(5 * J) * rng.uniform(0.8, 1.2, 60)) > 0.05
    assert np.isnan(j_function_steps(np.full(60, 1.1), J))  # one J: nothing told


def test_the_line_follows_what_a_smooth_function_leaves_on_the_same_cells():
    """A term's f''(J) times an invariant that barely varies (Gent's J^(-2/3) I1 near rest,
    I1 within 1 %) is not one function of J on a fine mesh; a steep smooth function on 20
    cells over a wide range of J still is (its interpolation is coarser there).
    """
    from conformance.diagnosis.j_functions import j_function_line

    rng = np.random.default_rng(5)
    J = rng.uniform(0.97, 1.03, 400)
    near = (J - 1.0) * J ** (-8.0 / 3.0) * (3.0 + rng.normal(0.0, 0.01, J.size))
    assert j_function_steps(J, near) > j_function_line(J, near)
    for v in ((J - 1.0) * J ** (-8.0 / 3.0), 1.0 / J):
        assert j_function_steps(J, v) <= j_function_line(J, v)
    coarse = rng.uniform(0.85, 1.2, 20)
    for v in (np.exp(5 * coarse), 3e4 * np.log(coarse) / coarse**2):
        assert j_function_steps(coarse, v) <= j_function_line(coarse, v)


def test_a_tangent_term_along_c_inverse_squared_not_of_j_is_not_the_volumetric_tangent():
    """An isochoric term along C^-1 (x) C^-1 with a wrong factor (a decoupled engine's
    projection P~ with +1/3) changes d2U/dJ2 per cell as an isochoric invariant does, not as
    one function of J: the volumetric tangent U''(J) is not named (corpus 6 was told so).
    """
    points, cells, x = _random_state(2)
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    J = np.abs(_cell_derivatives(points, cells, x)[1])
    per_cell = 3e4 * np.random.default_rng(6).uniform(0.5, 1.5, J.size)
    f, K = _volumetric_engine(points, cells, x, 0.0 * J, per_cell, f_o, K_o)
    full, partial = _volumetric(points, cells, x, f, K, f_o, K_o, s)
    assert full == [] and "not as one function of J" in partial[0].title
    assert "not the volumetric tangent" in partial[0].title


def test_on_a_single_j_a_tangent_term_along_c_inverse_squared_names_neither_reading():
    """One J: U''(J) and an isochoric term along C^-1 (x) C^-1 fit equally; neither is named."""
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    x = points @ np.diag([1.3, 1.0, 1.0]).T
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    J = np.abs(_cell_derivatives(points, cells, x)[1])
    f, K = _volumetric_engine(points, cells, x, 0.0 * J, 2e4 + 0.0 * J, f_o, K_o)
    full, partial = _volumetric(points, cells, x, f, K, f_o, K_o, s)
    assert full == [] and [x.code for x in partial] == ["volumetric"]
    assert "U''(J), or another term" in partial[0].title
    assert "too few distinct J" in partial[0].title


def test_a_tangent_part_off_by_a_simple_factor_is_said_in_words():
    """A part's error coefficient -1/2 (a factor 2 lost) is said "halved", and -1, +1, -2 as
    before; any other coefficient as the scale it gives.
    """
    from conformance.diagnosis.tangent import describe_coefficient

    assert "isochoric material tangent halved" in describe_coefficient(
        "isochoric material tangent", -0.5
    )
    assert "missing" in describe_coefficient("geometric", -1.0)
    assert "scaled by 1.3" in describe_coefficient("geometric", 0.3)


def test_a_tangent_part_that_leaves_most_of_a_small_error_is_not_named():
    """An error just above the tolerance (a step's truncation, 1e-10) that the geometric part
    only leans toward: the fit brings it under the tolerance but leaves most of it, so it is
    not named; the same part's own error of that size is.
    """
    import scipy.sparse as sp

    from conformance.diagnosis.diagnose import _tangent_findings
    from conformance.judge.compare import DOUBLE, errors

    rng = np.random.default_rng(2)
    n = 12
    A = rng.standard_normal((n, n))
    G = sp.csr_matrix(A + A.T)
    B = rng.standard_normal((n, n))
    M = sp.csr_matrix(B @ B.T)
    K_o = (G + M).tocsr()
    parts = {
        "geometric": G,
        "material_shear_shear": None,
        "material_normal_shear": None,
        "material_normal_normal": None,
        "geometric_volumetric": None,
        "material_volumetric": None,
    }
    f_o = rng.standard_normal((4, 3))
    from conformance.judge.compare import scales

    s = scales(0.5, 1.0, f_o, K_o)
    C = rng.standard_normal((n, n))
    other = sp.csr_matrix(C + C.T)  # not a part: the error's own direction

    def size(D):  # the relative stiffness error D makes
        return errors(f_o, (K_o + D).tocsr(), None, f_o, K_o, 0.0, s).stiffness

    tol = DOUBLE.stiffness
    g, o = G / size(G), other / size(other)  # each of unit error
    for D, named in ((tol * (0.7 * o + 1.0 * g), False), (12.0 * tol * g, True)):
        K = (K_o + D).tocsr()
        err = errors(f_o, K, None, f_o, K_o, 0.0, s)
        assert err.stiffness > tol
        full, partial = [], []
        _tangent_findings(K, K_o, parts, err, DOUBLE, full, partial)
        assert bool(full) == named, (full, partial)
