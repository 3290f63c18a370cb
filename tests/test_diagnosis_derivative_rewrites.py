"""A derivative dW/dI typed wrongly in a hand-written stress, the energy right
(conformance.diagnosis.derivative_rewrites and formula_derivative).

The engines here write their first Piola stress by hand, P = psi1 dI1b/dF + U'(J) dJ/dF with the
derivative psi1 = dW/dI1b typed as its own formula, and take the element stiffness by complex
step of their element-force routine (or keep the energy's own stiffness); they are written with
this file's own kinematics, not the module's. MJED stands in for the oracle. Each mistake comes
with a nearby one that must not get this cause.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.derivative_rewrites import (
    StressRewrite,
    derivative_rewrite_findings,
    stress_rewrites,
)
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.formula_derivative import derivative
from conformance.diagnosis.variants import energy_expression
from conformance.judge.compare import DOUBLE
from reference_fem.user_energy import evaluate_formula

DECLARED = ["NeoHookean", "MooneyRivlin", "Yeoh", "ArrudaBoyce", "Gent", "VerondaWestmann",
            "Demiray"]  # fmt: skip


@pytest.mark.parametrize("name", DECLARED)
def test_the_written_derivative_is_the_derivative_of_the_energy(name):
    expression, params = energy_expression(default_material(name))
    rng = np.random.default_rng(7)
    values = {
        "I1": 3.0 + rng.uniform(0, 0.5, 5),
        "I2": 3.0 + rng.uniform(0, 0.5, 5),
        "I1b": 3.0 + rng.uniform(0, 0.5, 5),
        "I2b": 3.0 + rng.uniform(0, 0.5, 5),
        "J": rng.uniform(0.8, 1.2, 5),
    }
    checked = 0
    for k in values:
        written = derivative(expression, k)
        step = {**params, **values, k: values[k] + 1e-30j}
        expected = evaluate_formula(expression, step).imag / 1e-30
        got = np.broadcast_to(evaluate_formula(written, {**params, **values}), (5,))
        assert np.allclose(got, expected, rtol=1e-13, atol=1e-12 * np.abs(expected).max()), k
        checked += written != "0"
    assert checked >= 2  # an isochoric or I1 term and the volumetric term at least


def test_derivatives_of_every_function_of_the_syntax():
    formula = "a*sqrt(I1)**3/exp(-J) + pow(J, I1)*ln(I1b) - log(2*J)/I2 + (I1b - 3)**(-1/3)"
    values = {"a": 1.7, "I1": 3.3, "I2": 2.9, "I1b": 3.4, "J": 1.1}
    for k in ("I1", "I2", "I1b", "J"):
        step = {**values, k: values[k] + 1e-30j}
        expected = evaluate_formula(formula, step).imag / 1e-30
        assert evaluate_formula(derivative(formula, k), values) == pytest.approx(expected, 1e-13)
    assert derivative(formula, "I3") == "0"


def _shape_vectors(points, cells):
    E0 = (points[cells[:, 1:]] - points[cells[:, :1]]).transpose(0, 2, 1)
    G = np.linalg.inv(E0)  # rows: the gradients of N1, N2, N3
    return np.linalg.det(E0) / 6.0, np.concatenate([-G.sum(axis=1, keepdims=True), G], axis=1)


def _engine(points, cells, x, stress, stiffness=None, edge_based=False):
    """Force and stiffness of an engine whose per-cell first Piola stress is ``stress(F)``, its
    element stiffness the complex step of its element force (or ``stiffness`` as given);
    ``edge_based``: only the node blocks of local pairs a <= b kept, those of b > a written as
    their transposes.
    """
    V0, D = _shape_vectors(points, cells)

    def element_forces(xe):
        F = np.einsum("mak,maI->mkI", xe, D)
        return -V0[:, None, None] * np.einsum("mkI,maI->mak", stress(F), D)

    xe = x[cells].astype(complex)
    fe = element_forces(xe).real
    m, h = cells.shape[0], 1e-30
    Ke = np.zeros((m, 12, 12))
    for j in range(12):
        xp = xe.reshape(m, 12).copy()
        xp[:, j] += 1j * h
        Ke[:, :, j] = -(element_forces(xp.reshape(m, 4, 3)).imag / h).reshape(m, 12)
    if edge_based:
        for a in range(4):
            for b in range(a):
                upper = Ke[:, 3 * b : 3 * b + 3, 3 * a : 3 * a + 3]
                Ke[:, 3 * a : 3 * a + 3, 3 * b : 3 * b + 3] = upper.transpose(0, 2, 1)
    f, K = assemble(cells, points.shape[0], fe, Ke)
    return f, (K if stiffness is None else stiffness)


def _isochoric_stress(psi1, k0, transposed=False):
    """P = psi1(I1b) dI1b/dF + k0 ln J F^-T (W = Psi(I1b) + k0/2 (ln J)^2)."""

    def P(F):
        J = np.linalg.det(F)
        I1 = np.einsum("mij,mij->m", F, F)
        I1b = J ** (-2.0 / 3.0) * I1
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        dI1b = (J ** (-2.0 / 3.0))[:, None, None] * (
            2.0 * F - (2.0 / 3.0 * I1)[:, None, None] * FiT
        )
        out = psi1(I1b)[:, None, None] * dI1b + (k0 * np.log(J))[:, None, None] * FiT
        return out.transpose(0, 2, 1) if transposed else out

    return P


def _case(name, seed=1):
    model = default_material(name)
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag((1.1, 0.95, 0.92)).T + 0.03 * rng.standard_normal(points.shape)
    _, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, points, cells, x, f_o, K_o, s


def _find(case, f, K):
    model, points, cells, x, f_o, K_o, s = case
    return derivative_rewrite_findings(model, points, cells, x, f, K, f_o, K_o, s, DOUBLE)


def _gent_psi1(model, sign=-1.0):
    return lambda I1b: model.mu / 2.0 / (1.0 + sign * (I1b - 3.0) / model.Jm)


def test_gent_with_the_locking_denominators_sign_flipped_is_named():
    case = _case("Gent")
    model = case[0]
    right = _engine(*case[1:4], _isochoric_stress(_gent_psi1(model), model.k0))
    assert _find(case, *right) == []  # the right engine: nothing to name
    f, K = _engine(*case[1:4], _isochoric_stress(_gent_psi1(model, +1.0), model.k0))
    found = _find(case, f, K)
    assert [x.code for x in found] == ["stress-derivative-rewritten"], [x.title for x in found]
    assert "1 + (I1b - 3) / Jm" in found[0].title and "the energy right" in found[0].title
    assert found[0].figures["tangent"].startswith("its stiffness the derivative of that force")
    # the same stress with the energy's own stiffness (automatic differentiation of W)
    found = _find(case, f, case[5])
    assert [x.code for x in found] == ["stress-derivative-rewritten"]
    assert "energy's own" in found[0].figures["tangent"]


def _mooney_rivlin_projection(model, coefficient):
    """P = F S, S = 2 c1 dI1b/dC + 2 c2 dI2b/dC + k0 ln J C^-1, the C^-1 term of
    dI2b/dC = J^(-4/3) (I1 I - C - 2/3 I2 C^-1) written with ``coefficient`` for -2/3.
    """

    def P(F):
        C = F.transpose(0, 2, 1) @ F
        Ci = np.linalg.inv(C)
        J = np.linalg.det(F)[:, None, None]
        I1 = np.trace(C, axis1=1, axis2=2)[:, None, None]
        I2 = (I1**2 - np.trace(C @ C, axis1=1, axis2=2)[:, None, None]) / 2
        eye = np.eye(3)
        d1 = J ** (-2 / 3) * (eye - I1 / 3 * Ci)
        d2 = J ** (-4 / 3) * (I1 * eye - C + coefficient * I2 * Ci)
        return F @ (2 * model.c1 * d1 + 2 * model.c2 * d2 + model.k0 * np.log(J) * Ci)

    return P


def test_an_edge_based_engine_mirroring_the_tangent_of_its_wrong_stress_is_named():
    """A projection slip leaves a stress that derives from no energy, so its tangent is not
    symmetric: an engine that computes one triangle of each cell's blocks and mirrors it has
    neither that tangent nor the energy's.
    """
    case = _case("MooneyRivlin", seed=4)
    model = case[0]
    right = _engine(*case[1:4], _mooney_rivlin_projection(model, -2 / 3), edge_based=True)
    assert _find(case, *right) == []
    wrong = _engine(*case[1:4], _mooney_rivlin_projection(model, -1 / 3), edge_based=True)
    found = _find(case, *wrong)
    assert [x.code for x in found] == ["stress-derivative-rewritten"], [x.title for x in found]
    assert "a <= b" in found[0].figures["tangent"]


def test_the_one_over_j_of_ln_js_derivative_lost_is_named():
    """Gent's volumetric stress written k0 ln J J F^-T: d(k0/2 (ln J)^2)/dJ without the 1/J of
    d(ln J)/dJ; the stiffness the energy's own.
    """
    case = _case("Gent", seed=6)
    model = case[0]
    right = _isochoric_stress(_gent_psi1(model), model.k0)

    def wrong(F):
        J = np.linalg.det(F)
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        return right(F) + (model.k0 * np.log(J) * (J - 1.0))[:, None, None] * FiT

    found = _find(case, _engine(*case[1:4], wrong)[0], case[5])
    assert [x.code for x in found] == ["stress-derivative-rewritten"], [x.title for x in found]
    assert "(the derivative of ln(J) in the chain rule) lost" in found[0].title


def _yeoh_like_stress(model, projection):
    """Gent's P with dI1b/dF = J^(-2/3) (2 F + projection I1 F^-T) (right: -2/3)."""

    def P(F):
        J = np.linalg.det(F)
        I1 = np.einsum("mij,mij->m", F, F)
        I1b = J ** (-2.0 / 3.0) * I1
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        dI1b = (J ** (-2.0 / 3.0))[:, None, None] * (
            2.0 * F + (projection * I1)[:, None, None] * FiT
        )
        psi1 = _gent_psi1(model)(I1b)
        return psi1[:, None, None] * dI1b + (model.k0 * np.log(J))[:, None, None] * FiT

    return P


def test_the_projection_of_di1b_df_halved_is_named():
    """-1/3 I1 F^-T where -2/3 I1 F^-T belongs (the 2 of d(J^(-2/3))/dF dropped)."""
    case = _case("Gent", seed=7)
    model = case[0]
    assert _find(case, *_engine(*case[1:4], _yeoh_like_stress(model, -2.0 / 3.0))) == []
    found = _find(case, *_engine(*case[1:4], _yeoh_like_stress(model, -1.0 / 3.0)))
    assert [x.code for x in found] == ["stress-derivative-rewritten"], [x.title for x in found]
    assert "-1/6 I1 C^-1 (halved" in found[0].title


def test_demirays_minus_one_carried_into_its_derivative_is_named():
    case = _case("Demiray", seed=2)
    model = case[0]
    psi1 = lambda I1b: model.a / 2.0 * (np.exp(model.b * (I1b - 3.0)) - 1.0)  # noqa: E731
    found = _find(case, *_engine(*case[1:4], _isochoric_stress(psi1, model.k0)))
    assert [x.code for x in found] == ["stress-derivative-rewritten"], [x.title for x in found]
    assert "- 1" in found[0].title and "exp(" in found[0].title


def test_a_stress_mistake_outside_the_derivatives_is_not_named():
    # P^T for P: the derivatives right, the tensor wrong; and dW/dI1b scaled by 1.37, which
    # none of the rewrites (a sign, 2, 1/2, a parameter, a power of J) is
    case = _case("Gent", seed=3)
    model = case[0]
    transposed = _isochoric_stress(_gent_psi1(model), model.k0, transposed=True)
    assert _find(case, *_engine(*case[1:4], transposed)) == []
    scaled = lambda I1b: 1.37 * _gent_psi1(model)(I1b)  # noqa: E731
    assert _find(case, *_engine(*case[1:4], _isochoric_stress(scaled, model.k0))) == []


def test_no_rewrites_without_a_formula_in_scalar_invariants():
    assert stress_rewrites("lam/2*(E11 + E22 + E33)**2 + mu*E11**2", ("lam", "mu")) == []
    assert stress_rewrites("mu*(I1 - 3) + k*(I4 - 1)**2", ("mu", "k")) == []
    rewrites = stress_rewrites("mu/2*(I1b - 3) + k/2*ln(J)**2", ("mu", "k"))
    rewrites = [r for r in rewrites if isinstance(r, StressRewrite)]
    assert {r.invariant for r in rewrites} == {"I1b", "J"}
    assert len({(r.invariant, r.formula) for r in rewrites}) == len(rewrites)
    volumetric = [r.words for r in rewrites if r.words.startswith("dW/dJ")]
    assert volumetric and all("pressure" in w for w in volumetric)
    assert not any("/1)" in r.words for r in rewrites)  # J^(-1), not J^(-1/1)


def _mooney_rivlin_kirchhoff(model, power_of_det_b, i1_of_b=False):
    """P = tau F^-T, tau = 2 c1 dev(Bb) + 2 c2 dev(I1b Bb - Bb^2) + k0 ln J I, the isochoric
    Bb = det(B)^power B (-1/3: right; -2/3: det B where J belongs in J^(-2/3)).
    """

    def P(F):
        B = F @ F.transpose(0, 2, 1)
        Bb = np.linalg.det(B)[:, None, None] ** power_of_det_b * B
        I1b = np.trace(B if i1_of_b else Bb, axis1=1, axis2=2)[:, None, None]
        eye = np.eye(3)

        def dev(A):
            return A - np.trace(A, axis1=1, axis2=2)[:, None, None] / 3.0 * eye

        tau = 2 * model.c1 * dev(Bb) + 2 * model.c2 * dev(I1b * Bb - Bb @ Bb)
        tau = tau + (model.k0 * np.log(np.linalg.det(F)))[:, None, None] * eye
        return tau @ np.linalg.inv(F).transpose(0, 2, 1)

    return P


def test_the_isochoric_factor_applied_twice_in_a_kirchhoff_stress_is_named():
    case = _case("MooneyRivlin", seed=5)
    model = case[0]
    right = _engine(*case[1:4], _mooney_rivlin_kirchhoff(model, -1.0 / 3.0))
    assert np.allclose(right[0], case[4], rtol=0, atol=1e-9 * np.abs(case[4]).max())
    assert _find(case, *right) == []
    found = _find(case, *_engine(*case[1:4], _mooney_rivlin_kirchhoff(model, -2.0 / 3.0)))
    assert [x.code for x in found] == ["stress-isochoric-scaling"], [x.title for x in found]
    assert "J^(-4/3) B where J^(-2/3) B belongs" in found[0].title


def test_i1_for_i1b_in_the_i2b_stress_is_named():
    case = _case("MooneyRivlin", seed=6)
    P = _mooney_rivlin_kirchhoff(case[0], -1.0 / 3.0, i1_of_b=True)
    found = _find(case, *_engine(*case[1:4], P))
    assert [x.code for x in found] == ["stress-derivative-rewritten"], [x.title for x in found]
    assert "typed I1 = tr B" in found[0].title


def test_without_the_engines_energy_the_energy_is_not_said_to_be_right():
    case = _case("Gent", seed=7)
    model, points, cells, x, f_o, K_o, s = case
    f, K = _engine(points, cells, x, _isochoric_stress(_gent_psi1(model, +1.0), model.k0))
    found = derivative_rewrite_findings(
        model, points, cells, x, f, K, f_o, K_o, s, DOUBLE, energy_given=False
    )
    assert [x.code for x in found] == ["stress-derivative-rewritten"]
    assert "the energy right" not in found[0].title and "gives no energy" in found[0].title


def _mooney_rivlin_total_lagrangian(model, i2b_coefficient=-2.0 / 3.0):
    """P = F S, S = 2 c1 J^(-2/3) (I - I1/3 C^-1) + 2 c2 J^(-4/3) (I1 I - C + w I2 C^-1)
    + k0 ln J C^-1, w = -2/3 (right) or as given.
    """

    def P(F):
        C = F.transpose(0, 2, 1) @ F
        Ci = np.linalg.inv(C)
        J = np.linalg.det(F)[:, None, None]
        I1 = np.trace(C, axis1=1, axis2=2)[:, None, None]
        I2 = 0.5 * (I1**2 - np.trace(C @ C, axis1=1, axis2=2)[:, None, None])
        eye = np.eye(3)
        S = 2 * model.c1 * J ** (-2 / 3) * (eye - I1 / 3 * Ci)
        S = S + 2 * model.c2 * J ** (-4 / 3) * (I1 * eye - C + i2b_coefficient * I2 * Ci)
        return F @ (S + model.k0 * np.log(J) * Ci)

    return P


def test_the_isochoric_projection_with_i1bs_coefficient_in_di2b_dc_is_named():
    case = _case("MooneyRivlin", seed=8)
    model = case[0]
    right = _engine(*case[1:4], _mooney_rivlin_total_lagrangian(model))
    assert _find(case, *right) == []
    found = _find(case, *_engine(*case[1:4], _mooney_rivlin_total_lagrangian(model, -1.0 / 3.0)))
    assert [x.code for x in found] == ["stress-derivative-rewritten"], [x.title for x in found]
    assert "the C^-1 term of dI2b/dC written -1/3 I2 C^-1" in found[0].title


def _mooney_rivlin_first_piola(model, product):
    """P = c1 dI1b/dF + c2 dI2b/dF + k0 ln J F^-T with dI2/dF = 2 (I1 F - product(F, C))
    (right: F C).
    """

    def P(F):
        C = F.transpose(0, 2, 1) @ F
        J = np.linalg.det(F)[:, None, None]
        I1 = np.trace(C, axis1=1, axis2=2)[:, None, None]
        I2 = (I1**2 - np.trace(C @ C, axis1=1, axis2=2)[:, None, None]) / 2
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        dI1b = J ** (-2 / 3) * (2 * F - 2 / 3 * I1 * FiT)
        dI2b = J ** (-4 / 3) * (2 * (I1 * F - product(F, C)) - 4 / 3 * I2 * FiT)
        return model.c1 * dI1b + model.c2 * dI2b + model.k0 * np.log(J) * FiT

    return P


def test_di2_df_typed_with_c_f_is_named_as_the_operands_swapped():
    """Corpus 12's Mooney-Rivlin: C F where F C belongs in dI2/dF, the stiffness that force's
    complex step; the same engine with F C is right.
    """
    case = _case("MooneyRivlin", seed=5)
    model = case[0]
    right = _mooney_rivlin_first_piola(model, lambda F, C: F @ C)
    assert _find(case, *_engine(*case[1:4], right)) == []
    found = _find(case, *_engine(*case[1:4], _mooney_rivlin_first_piola(model, lambda F, C: C @ F)))
    assert [x.code for x in found] == ["stress-gradient-slip"], [x.title for x in found]
    assert found[0].figures["slip"] == "CF" and "C F" in found[0].title


def test_a_power_rules_coefficient_with_the_second_derivative_typed_apart_is_named():
    """Yeoh's c30 term differentiated as 2 c30 (I1b - 3)^2 (the coefficient from the lowered
    exponent) in the stress and wherever dW/dI1b enters the tangent, its second derivative
    6 c30 (I1b - 3) typed apart and right: the tangent is the right one plus the wrong
    coefficient times d2I1b/dF2, neither the derivative of the wrong stress nor the right one.
    """
    case = _case("Yeoh")
    model = case[0]

    def psi1(I1b, c3=3.0):
        s = I1b - 3.0
        return model.c10 + 2.0 * model.c20 * s + c3 * model.c30 * s**2

    right = _isochoric_stress(psi1, model.k0)

    def frozen(F):
        # the coefficient error is evaluated at the real F (held fixed under the complex step),
        # dI1b/dF at the perturbed one: the tangent gains that error times d2I1b/dF2 alone
        Fr = F.real
        I1b = np.linalg.det(Fr) ** (-2.0 / 3.0) * np.einsum("mij,mij->m", Fr, Fr)
        d = psi1(I1b, 2.0) - psi1(I1b)
        J = np.linalg.det(F)
        I1 = np.einsum("mij,mij->m", F, F)
        FiT = np.linalg.inv(F).transpose(0, 2, 1)
        dI1b = (J ** (-2.0 / 3.0))[:, None, None] * (
            2.0 * F - (2.0 / 3.0 * I1)[:, None, None] * FiT
        )
        return right(F) + d[:, None, None] * dI1b

    f, K = _engine(case[1], case[2], case[3], frozen)
    found = _find(case, f, K)
    assert len(found) == 1 and "written 2" in found[0].title, found
    assert "second derivatives d2W/dI2 typed" in found[0].figures["tangent"]
