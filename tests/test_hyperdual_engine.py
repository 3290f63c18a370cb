"""The hyper-dual test engines (tests/hyperdual_engine.py): exact derivatives, and an engine
built on them passes the check where it computes the oracle's own energy, so that the tests
which give it another energy (a Gram-Schmidt or pushed-forward Costa frame, F transposed) can
trust its force and stiffness.
"""

from __future__ import annotations

import numpy as np
import pytest
from hyperdual_engine import HD, Namespace, density_engine, exp, hyperdual_F, ln, sqrt

from reference_fem import dolfinx_available


def test_second_derivatives_are_exact():
    x = np.array([0.7, 1.3, 2.9])
    h = HD(x, 1.0, 1.0, 0.0)
    y = exp(h) / sqrt(h) + ln(h) * h**-1.5 - 3.0 / h
    # by hand: g = e^x x^-1/2 + ln(x) x^-3/2 - 3/x
    g1 = np.exp(x) * (x**-0.5 - 0.5 * x**-1.5) + x**-2.5 - 1.5 * np.log(x) * x**-2.5 + 3 / x**2
    g2 = (
        np.exp(x) * (x**-0.5 - x**-1.5 + 0.75 * x**-2.5)
        - 4.0 * x**-3.5
        + 3.75 * np.log(x) * x**-3.5
        - 6 / x**3
    )
    assert np.allclose(y.b, g1, rtol=1e-14) and np.allclose(y.d, g2, rtol=1e-13)


def test_seeded_components_give_the_gradient_and_hessian_of_det():
    F = np.array([[[1.1, 0.2, -0.1], [0.05, 0.9, 0.3], [0.0, -0.2, 1.2]]])
    J = Namespace(hyperdual_F(F)).J
    cof = np.linalg.det(F[0]) * np.linalg.inv(F[0]).T  # dJ/dF
    assert np.allclose(J.b[0, ::9], cof.ravel(), rtol=1e-14)
    H = J.d[0].reshape(3, 3, 3, 3)  # d2J/dF_ik dF_jl = (cof_ik cof_jl - cof_il cof_jk) / J
    expected = (np.einsum("ik,jl->ikjl", cof, cof) - np.einsum("il,jk->ikjl", cof, cof)) / J.a[0, 0]
    assert np.allclose(H, expected, atol=1e-14)


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_engine_on_costas_own_energy_passes_the_check():
    from conformance.protocol import assert_matches_oracle
    from mjed.materials import Costa
    from mjed.materials.declaration import declaration_of

    formula = declaration_of(Costa).energy

    def density(model, k, F, R):
        return formula(lambda name: float(getattr(model, name)), k)

    engine = density_engine(density, frame_of=lambda model: model.frame)
    assert_matches_oracle(engine, material="Costa", mesh="cube-small", states=("random",))
