"""Uniaxial closed forms: the analytic stresses themselves, then MJED's face reaction on a cube."""

import numpy as np
import pytest
from conftest import box_mesh

import mjed.materials as M
from common.cases import DEFAULT_MATERIALS
from comparisons.equivalence.closed_form import (
    ISOTROPIC,
    has_closed_form,
    principal_cauchy,
    uniaxial_cauchy,
    uniaxial_reaction_check,
)

STIFF_BULK = 1e8  # k0 / mu: the compressible forms approach the incompressible golden values


@pytest.mark.parametrize(
    "material, golden",
    [
        (M.NeoHookean(mu=1.0, lam=STIFF_BULK), 1.245714),
        (M.MooneyRivlin(c1=0.3, c2=0.2, k0=STIFF_BULK), 1.103347),
        (M.VerondaWestmann(c1=0.5, c2=1.3, k0=STIFF_BULK), 2.105386),
        (M.ArrudaBoyce(mu=1.0, k0=STIFF_BULK), 1.367657),
        (M.Ogden(mu=1.0, alpha=4.0, k0=STIFF_BULK), 0.832849),
        # sigma = 2 (lambda^2 - 1/lambda) W1 with x = lambda^2 + 2/lambda - 3 (incompressible):
        # Yeoh W1 = c10 + 2 c20 x + 3 c30 x^2, Gent W1 = mu / (2 (1 - x/Jm))
        (M.Yeoh(c10=0.5, c20=-0.05, c30=0.01, k0=STIFF_BULK), 1.160190),
        (M.Gent(mu=1.0, Jm=5.0, k0=STIFF_BULK), 1.350682),
    ],
    ids=lambda v: type(v).__name__ if not isinstance(v, float) else "",
)
def test_nearly_incompressible_limit_matches_published_uniaxial_stress(material, golden):
    # Golden values (lambda = 1.4) of the incompressible closed forms (textbook uniaxial stress).
    sigma, t = uniaxial_cauchy(material, 1.4)
    assert sigma == pytest.approx(golden, abs=2e-6)
    assert t == pytest.approx(1.4**-0.5, rel=1e-6)


def test_stvk_uniaxial_check_case():
    # mu = 1, lambda = 1.5, stretch 1.4: lateral stretch 0.84380092 and P11 = 1.7472 exactly.
    sigma, t = uniaxial_cauchy(M.StVenantKirchhoff(mu=1.0, lam=1.5), 1.4)
    assert t == pytest.approx(0.84380092, abs=1e-8)
    assert sigma * t * t == pytest.approx(1.7472, rel=1e-12)  # P11 = J sigma / lambda1


def test_hydrostatic_neo_hookean():
    a = 1.1
    s = principal_cauchy(M.NeoHookean(mu=2.0, lam=5.0), (a, a, a))
    assert np.allclose(s, (2.0 * (a * a - 1) + 5.0 * np.log(a**3)) / a**3, rtol=1e-14)


def test_closed_form_refuses_anisotropic_and_bad_stretches():
    with pytest.raises(ValueError, match="no closed form for Costa"):
        principal_cauchy(DEFAULT_MATERIALS["Costa"], (1.1, 1.0, 1.0))
    with pytest.raises(ValueError, match="finite and positive"):
        principal_cauchy(DEFAULT_MATERIALS["NeoHookean"], (1.1, -1.0, 1.0))


def test_closed_forms_dispatch_on_the_material_type():
    # Every isotropic default material has one, Costa has none, and a subclass inherits its base's.
    # Those of the decoupled classical form need no lines of their own (Yeoh, Gent).
    assert {type(m) for m in DEFAULT_MATERIALS.values() if has_closed_form(m)} == set(ISOTROPIC)
    assert set(ISOTROPIC) == {d.material for d in M.declarations()} - {M.Costa}

    class Softer(M.NeoHookean):
        pass

    assert has_closed_form(Softer(mu=2.0, lam=5.0))
    assert np.array_equal(
        principal_cauchy(Softer(mu=2.0, lam=5.0), (1.1, 1.0, 0.9)),
        principal_cauchy(M.NeoHookean(mu=2.0, lam=5.0), (1.1, 1.0, 0.9)),
    )

    class Unknown:  # not a material of this module: the error names its type
        pass

    assert not has_closed_form(Unknown())
    with pytest.raises(ValueError, match="no closed form for .*Unknown"):
        principal_cauchy(Unknown(), (1.1, 1.0, 1.0))


@pytest.mark.parametrize("name", [n for n, m in DEFAULT_MATERIALS.items() if has_closed_form(m)])
@pytest.mark.parametrize("stretch", [1.3, 0.8])
def test_mjed_face_reaction_equals_analytic_cauchy_stress(name, stretch):
    # Interior nodes jittered: the faces stay planar, the cells are irregular.
    points, cells = box_mesh(3, jitter=0.3)
    r = uniaxial_reaction_check(DEFAULT_MATERIALS[name], points, cells, stretch)
    assert r.rel_err < 1e-10
    assert r.lateral_reaction_rel < 1e-10


def test_face_reaction_check_detects_a_wrong_parameter():
    # The check can fail: MJED run with mu 0.1 % off disagrees with the analytic stress.
    points, cells = box_mesh(3, jitter=0.3)
    m = DEFAULT_MATERIALS["NeoHookean"]
    analytic, t = uniaxial_cauchy(m, 1.3)
    r = uniaxial_reaction_check(M.NeoHookean(mu=m.mu * 1.001, lam=m.lam), points, cells, 1.3)
    assert abs(r.sigma_mjed - analytic) / abs(analytic) > 1e-4
