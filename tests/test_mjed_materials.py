"""Costa and Ogden specifics, SOFA import, and the compressed-element regularisation."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, perturbed

import mjed
from comparisons.equivalence.taylor import energy_force_rates, force_stiffness_rates
from mjed import materials as M
from mjed.fibre import signed_split
from mjed.spectral import power_divided_differences


# ----------------------------------------------------------------------------- Costa
@pytest.mark.parametrize(
    "B",
    [
        np.array([[1.0, 0.3, 0.2], [0.3, 0.8, 0.1], [0.2, 0.1, 0.5]]),  # positive definite
        np.array([[1.0, 0.9, 0.2], [0.9, 0.5, 0.1], [0.2, 0.1, 0.5]]),  # second pivot negative
        np.array([[2.0, 0.0, 1.9], [0.0, 1.0, 0.0], [1.9, 0.0, 1.0]]),  # third pivot negative
    ],
)
@pytest.mark.parametrize("method", ["ldl", "eigen"])
def test_signed_split_reconstructs_entrywise_product(B, method, rng):
    s, d = signed_split(B, method)
    assert np.allclose(np.einsum("i,ij,ik->jk", s, d, d), B, atol=1e-14)
    X = rng.standard_normal((3, 3))
    assert np.allclose(
        sum(si * np.diag(di) @ X @ np.diag(di) for si, di in zip(s, d)), B * X, atol=1e-14
    )


def test_ldl_split_refuses_zero_pivot():
    # b_ss = b_fs^2 / b_ff makes the second pivot zero.
    with pytest.raises(ValueError, match="divides by zero: pivot 2"):
        M.Costa(1.0, 1.0, b_ff=1.0, b_fs=0.5, b_ss=0.25, b_fn=0.1, b_sn=0.2, b_nn=1.0)
    with pytest.raises(ValueError, match="pivot 1"):
        M.Costa(1.0, 1.0, b_ff=0.0, b_fs=0.5, b_ss=0.25, b_fn=0.1, b_sn=0.2, b_nn=1.0)
    # The eigen split takes the same B.
    M.Costa(1.0, 1.0, b_ff=1.0, b_fs=0.5, b_ss=0.25, b_fn=0.1, b_sn=0.2, b_nn=1.0, split="eigen")


def test_costa_frame_validation():
    with pytest.raises(ValueError, match="frame is not orthonormal"):
        M.Costa(1, 1, 1, 0, 1, 0, 0, 1, frame=np.diag([1.0, 2.0, 1.0]))
    R = np.repeat(np.eye(3)[None], 5, axis=0)
    R[3, 0, 0] = 1.1
    with pytest.raises(ValueError, match=r"not orthonormal \(cell 3\)"):
        M.Costa(1, 1, 1, 0, 1, 0, 0, 1, frame=R)
    with pytest.raises(ValueError, match="shape"):
        M.Costa(1, 1, 1, 0, 1, 0, 0, 1, frame=np.eye(4))
    points, cells = box_mesh(1)
    with pytest.raises(ValueError, match="per-cell data .* for 5 cells, but the mesh has 6 cells"):
        mjed.HyperelasticForceField(
            mjed.TetMesh(points, cells),
            M.Costa(1, 1, 1, 0, 1, 0, 0, 1, frame=np.repeat(np.eye(3)[None], 5, axis=0)),
        )


COSTA_B = dict(b_ff=1.0, b_fs=0.3, b_ss=0.8, b_fn=0.2, b_sn=0.1, b_nn=0.5)


def test_costa_frame_rotates_the_response(rng):
    """A frame R applied to the material equals the inverse rotation applied to the body."""
    points, cells = box_mesh(2, jitter=0.2)
    mesh = mjed.TetMesh(points, cells)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    rotated = mjed.TetMesh(points @ Q.T, cells)
    x = perturbed(points, rng, 0.05)
    f_ref = mjed.HyperelasticForceField(mesh, M.Costa(0.9, 3.0, **COSTA_B)).force(x)
    f_rot = mjed.HyperelasticForceField(rotated, M.Costa(0.9, 3.0, **COSTA_B, frame=Q)).force(
        x @ Q.T
    )
    assert np.allclose(f_rot, f_ref @ Q.T, atol=1e-12 * np.abs(f_ref).max())
    per_cell = np.repeat(Q[None], len(cells), axis=0)
    f_cells = mjed.HyperelasticForceField(
        rotated, M.Costa(0.9, 3.0, **COSTA_B, frame=per_cell)
    ).force(x @ Q.T)
    assert np.allclose(f_cells, f_rot, atol=1e-13 * np.abs(f_ref).max())


# ----------------------------------------------------------------------------- Ogden
def test_divided_differences_limits():
    lam = np.array([[1.0, 1.0, 1.0], [2.0, 2.0 + 1e-14, 3.0], [0.5, 1.5, 4.0]])
    p = 0.37
    th = power_divided_differences(lam, p)
    assert np.allclose(th[0], p)  # rest: all eigenvalues equal
    assert np.isclose(th[1, 0, 1], p * 2.0 ** (p - 1), rtol=1e-12)
    assert np.isclose(th[2, 0, 2], (0.5**p - 4.0**p) / (0.5 - 4.0), rtol=1e-14)
    assert np.isclose(th[2, 1, 1], p * 1.5 ** (p - 1), rtol=1e-14)


@pytest.mark.parametrize("alpha", [2.0, -2.0])
def test_ogden_reduces_to_invariants(alpha, rng):
    points, cells = box_mesh(2, jitter=0.2)
    mesh = mjed.TetMesh(points, cells)
    x = perturbed(points, rng, 0.06)
    ogden = mjed.HyperelasticForceField(mesh, M.Ogden(mu=1.2, alpha=alpha, k0=4.0))
    mu, k0 = 1.2, 4.0
    # alpha = 2: mu/4 (I1b - 3); alpha = -2: mu/4 (I2b - 3). (alpha = 4 is checked against the
    # oracle.)
    equiv = (
        M.MooneyRivlin(c1=mu / 4, c2=0.0, k0=k0)
        if alpha > 0
        else M.MooneyRivlin(c1=0.0, c2=mu / 4, k0=k0)
    )
    ref = mjed.HyperelasticForceField(mesh, equiv)
    assert np.isclose(ogden.energy(x), ref.energy(x), rtol=1e-12)
    f0, K0 = ref.force_and_stiffness(x)
    f1, K1 = ogden.force_and_stiffness(x)
    assert np.linalg.norm(f1 - f0) <= 1e-12 * np.linalg.norm(f0)
    assert abs(K1 - K0).max() <= 1e-11 * abs(K0).max()


@pytest.mark.parametrize("alpha", [3.0, -2.0, 1.5])
def test_ogden_exact_tangent_passes_taylor_at_rest_and_deformed(alpha, rng):
    points, cells = box_mesh(2, jitter=0.3)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), M.Ogden(1.0, alpha, 5.0))
    for x in (points, perturbed(points, rng, 0.03)):
        v = rng.standard_normal(x.shape)
        assert force_stiffness_rates(field, x, v, 1e-3).min() >= 1.9
        if x is not points:
            assert energy_force_rates(field, x, v, 1e-3).min() >= 1.9


def test_ogden_sofa_tangent_is_not_the_hessian(rng):
    points, cells = box_mesh(2, jitter=0.3)
    mesh = mjed.TetMesh(points, cells)
    x = perturbed(points, rng, 0.03)
    exact = mjed.HyperelasticForceField(mesh, M.Ogden(1.0, 3.0, 5.0)).stiffness(x)
    approx_field = mjed.HyperelasticForceField(mesh, M.Ogden(1.0, 3.0, 5.0, tangent="sofa"))
    approx = approx_field.stiffness(x)
    rel = abs(approx - exact).max() / abs(exact).max()
    assert 1e-6 < rel < 0.2
    # Same forces; and the approximation is exact at rest (H coaxial with C = Id).
    assert np.allclose(
        approx_field.force(x), mjed.HyperelasticForceField(mesh, M.Ogden(1.0, 3.0, 5.0)).force(x)
    )
    assert (
        abs(
            approx_field.stiffness(points)
            - mjed.HyperelasticForceField(mesh, M.Ogden(1.0, 3.0, 5.0)).stiffness(points)
        ).max()
        < 1e-12
    )


# ----------------------------------------------------------------------------- SOFA
@pytest.mark.parametrize(
    "name, params, kwargs, expected",
    [
        # SOFA examples/Component/SolidMechanics/FEM: the ParameterSets of its hyperelastic example
        # scenes
        ("ArrudaBoyce", "3448.2759 31034.483", {}, M.ArrudaBoyce(mu=3448.2759, k0=31034.483)),
        (
            "StVenantKirchhoff",
            "3448.2759 31034.483",
            {},
            M.StVenantKirchhoff(mu=3448.2759, lam=31034.483),
        ),
        ("NeoHookean", "3448.2759 31034.483", {}, M.NeoHookean(mu=3448.2759, lam=31034.483)),
        ("MooneyRivlin", "5000 7000 10", {}, M.MooneyRivlin(c1=5000, c2=7000, k0=10)),
        ("Ogden", "1500 500 5000", {}, M.Ogden(mu=1500, alpha=500, k0=5000)),
        # the MJED plugin's example and SOFA's scene test
        (
            "StVenantKirchhoff",
            "5.0336e+04 2.4664e+06",
            {},
            M.StVenantKirchhoff(mu=5.0336e4, lam=2.4664e6),
        ),
        (
            "MooneyRivlin",
            "151065.460 101709.668 1e07",
            {},
            M.MooneyRivlin(c1=151065.46, c2=101709.668, k0=1e7),
        ),
        ("Ogden", [5000, 1500, 3], {"ogden_order": "mjed"}, M.Ogden(mu=1500, alpha=3, k0=5000)),
        ("VerondaWestman", [1.0, 2.0, 3.0], {}, M.VerondaWestmann(c1=1.0, c2=2.0, k0=3.0)),
    ],
)
def test_from_sofa(name, params, kwargs, expected):
    assert M.from_sofa(name, params, **kwargs) == expected


def test_from_sofa_costa():
    mat = M.from_sofa("Costa", "0.9 3 1 0.3 0.8 0.2 0.1 0.5")
    assert (mat.a, mat.k0, mat.b_ff, mat.b_fs, mat.b_ss, mat.b_fn, mat.b_sn, mat.b_nn) == (
        0.9,
        3,
        1,
        0.3,
        0.8,
        0.2,
        0.1,
        0.5,
    )


def test_from_sofa_errors():
    with pytest.raises(ValueError, match=r"expects 3 parameters \[c1, c2, k0\], got 2"):
        M.from_sofa("MooneyRivlin", "1 2")
    with pytest.raises(
        ValueError, match=r"ogden_order='mjed' expects 3 parameters \[k0, mu, alpha\]"
    ):
        M.from_sofa("Ogden", "1 2", ogden_order="mjed")
    with pytest.raises(
        ValueError, match="unknown SOFA material 'StableNeoHookean'; supported: StVenantKirchhoff"
    ):
        M.from_sofa("StableNeoHookean", "1 2")
    with pytest.raises(ValueError, match="must hold numbers"):
        M.from_sofa("NeoHookean", "1 abc")
    with pytest.raises(ValueError, match="parameter mu"):
        M.from_sofa("NeoHookean", "-1 2")


def test_sofa_tangent_error_report():
    from comparisons.equivalence.ogden_tangent import sofa_tangent_errors

    points, cells = box_mesh(2, jitter=0.2)
    errs = sofa_tangent_errors(
        mjed.TetMesh(points, cells), M.Ogden(1.0, 3.0, 5.0), ["rest", "triaxial", "random"]
    )
    assert errs["rest"] < 1e-14
    assert 1e-6 < errs["triaxial"] < 0.1 and 1e-6 < errs["random"] < 0.1


COSTA_VALID = dict(a=1.0, k0=1.0, b_ff=1.0, b_fs=0.3, b_ss=0.8, b_fn=0.2, b_sn=0.1, b_nn=0.5)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(a=0.0), r"parameter a must be > 0"),
        (dict(a=-2.0), r"parameter a must be > 0"),
        (dict(k0=0.0), r"parameter k0 must be > 0 \(the bulk modulus"),
        (dict(k0=-1.0), r"parameter k0 must be > 0"),
        (dict(b_ff=-1.0), r"parameter b_ff must be >= 0, got -1.0: Q"),
        (dict(b_fs=-0.1), r"parameter b_fs must be >= 0"),
        (dict(b_nn=-1e-9), r"parameter b_nn must be >= 0"),
        (dict(b_ff=0.0, b_fs=0.0, b_ss=0.0, b_fn=0.0, b_sn=0.0, b_nn=0.0), r"at least one of b_ff"),
        (dict(b_sn=float("nan")), r"parameter b_sn must be a finite real number"),
        (dict(a=float("inf")), r"parameter a must be a finite real number"),
        (dict(k0="1.0"), r"parameter k0 must be a finite real number"),
        (dict(b_ss=True), r"parameter b_ss must be a finite real number"),
    ],
)
def test_costa_refuses_invalid_stiffness_parameters(change, message):
    with pytest.raises(ValueError, match="Costa: " + message):
        M.Costa(**{**COSTA_VALID, **change})
    # The SOFA route refuses them the same way.
    values = [
        {**COSTA_VALID, **change}[n]
        for n in ("a", "k0", "b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")
    ]
    if all(isinstance(v, float) for v in values):
        with pytest.raises(ValueError, match="Costa: " + message):
            M.from_sofa("Costa", values)


def test_costa_accepts_zero_and_indefinite_b():
    # Zero entries (no stiffening in that component) and an indefinite B matrix are valid: Q >= 0.
    M.Costa(**{**COSTA_VALID, "b_fs": 0.0, "b_fn": 0.0})
    M.Costa(**{**COSTA_VALID, "b_fs": 0.9, "b_ss": 0.5})


def test_a_negative_b_would_lower_the_energy_below_rest():
    # Why b_ij < 0 is refused: Q < 0 for a strain along that component alone.
    from mjed.fibre import FibreQuadratic
    from mjed.kinematics import Kinematics

    B = np.array([[1.0, -0.3, 0.2], [-0.3, 0.8, 0.1], [0.2, 0.1, 0.5]])
    g = FibreQuadratic(B, np.eye(3), split="eigen")
    F = np.array([[[1.0, 0.05, 0.0], [0.05, 1.0, 0.0], [0.0, 0.0, 1.0]]])  # E nearly pure fs shear
    assert g.value(Kinematics(F))[0] < 0.0
