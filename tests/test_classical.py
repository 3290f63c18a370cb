"""The classical Total Lagrangian FEM (reference_fem.classical) against MJED, against its own
derivatives (Taylor rates, central differences of W and S) and, if dolfinx is there, against
the UFL oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import MATERIALS as SHARED_MATERIALS
from conftest import box_mesh, perturbed

import mjed
from comparisons.equivalence.taylor import energy_force_rates, force_stiffness_rates
from mjed import materials as M
from reference_fem.classical import ClassicalGalerkin, strain_displacement
from reference_fem.classical_materials import VI, VJ, WEIGHT, classical_law, voigt

TOL = 1e-10


def _rotations(n, seed):
    """N proper rotations from QR of Gaussian matrices."""
    rng = np.random.default_rng(seed)
    Q, Rr = np.linalg.qr(rng.standard_normal((n, 3, 3)))
    Q = Q * np.sign(np.diagonal(Rr, axis1=1, axis2=2))[:, None, :]
    Q[np.linalg.det(Q) < 0, :, 0] *= -1
    return Q


MESH = box_mesh(2, jitter=0.3, seed=3)
N_CELLS = len(MESH[1])
COSTA = (0.9, 3.0, 1.0, 0.3, 0.8, 0.2, 0.1, 0.5)

# The shared set (conftest) plus the Costa frame variants that need this mesh's cell count.
MATERIALS = {
    **SHARED_MATERIALS,
    "Costa-frame": M.Costa(*COSTA, frame=_rotations(1, 7)[0]),
    "Costa-cellframes": M.Costa(*COSTA, frame=_rotations(N_CELLS, 8)),
}

# Pointwise laws: Costa's per-cell frames are replaced by one frame per sampled C.
N_SAMPLES = 12
POINTWISE = {k: v for k, v in MATERIALS.items() if k != "Costa-cellframes"}
POINTWISE["Costa-sampleframes"] = M.Costa(*COSTA, frame=_rotations(N_SAMPLES, 9))


@pytest.fixture(params=sorted(MATERIALS))
def name(request):
    return request.param


@pytest.fixture
def state():
    points, cells = MESH
    return points, cells, perturbed(points, np.random.default_rng(1234), 0.08)


def _rel(a, b):
    if sp.issparse(a):
        a, b = a.toarray(), b.toarray()
    return np.linalg.norm(a - b) / np.linalg.norm(b)


# ----------------------------------------------------------------------------- against mjed
def test_matches_mjed(name, state):
    points, cells, x = state
    material = MATERIALS[name]
    ref = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material)
    cl = ClassicalGalerkin(points, cells, material)
    f, K = cl.force_and_stiffness(x)
    assert (
        f.shape == (len(points), 3)
        and isinstance(K, sp.csr_matrix)
        and K.shape == (3 * len(points),) * 2
    )
    assert _rel(f, ref.force(x)) <= TOL
    assert _rel(K, ref.stiffness(x)) <= TOL
    assert _rel(cl.element_stiffness(x), ref.element_stiffness(x)) <= TOL
    assert abs(cl.energy(x) - ref.energy(x)) <= TOL * abs(ref.energy(x))
    # The separate calls give the same as the combined one.
    assert np.array_equal(cl.force(x), f)
    assert _rel(cl.stiffness(x), K) <= 1e-15


def test_rest_state(name):
    points, cells = MESH
    cl = ClassicalGalerkin(points, cells, MATERIALS[name])
    assert abs(cl.energy(points)) <= 1e-14
    f, K = cl.force_and_stiffness(points)
    assert np.abs(f).max() <= 1e-13
    ref = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), MATERIALS[name])
    assert _rel(K, ref.stiffness(points)) <= TOL


# ----------------------------------------------------------------------------- Taylor rates
def test_taylor_energy_force(name, state):
    points, cells, x = state
    cl = ClassicalGalerkin(points, cells, MATERIALS[name])
    v = np.random.default_rng(5).standard_normal(x.shape)
    rates = energy_force_rates(cl, x, v, eps0=1e-3)
    assert rates.min() >= 1.9, rates


def test_taylor_force_stiffness(name, state):
    points, cells, x = state
    cl = ClassicalGalerkin(points, cells, MATERIALS[name])
    v = np.random.default_rng(6).standard_normal(x.shape)
    rates = force_stiffness_rates(cl, x, v, eps0=1e-3)
    assert rates.min() >= 1.9, rates


# ----------------------------------------------------------------------------- pointwise laws
def _random_C(n, seed, scale=0.25):
    rng = np.random.default_rng(seed)
    F = np.eye(3) + scale * rng.standard_normal((n, 3, 3))
    F[np.linalg.det(F) < 0, :, 0] *= -1
    return np.swapaxes(F, 1, 2) @ F


def _sym_unit(I):
    """sym(e_i (x) e_j) for Voigt index I: the direction whose derivative is the (i, j) entry
    of a symmetric-tensor gradient (both off-diagonal entries move by h/2).
    """
    E = np.zeros((3, 3))
    i, j = VI[I], VJ[I]
    E[i, j] += 0.5
    E[j, i] += 0.5
    return E


@pytest.fixture(params=sorted(POINTWISE))
def law(request):
    return classical_law(POINTWISE[request.param])


def test_stress_is_twice_dW_dC(law):
    C = _random_C(N_SAMPLES, 11)
    S = voigt(law.stress(C))
    h = 1e-6
    S_fd = np.empty_like(S)
    for I in range(6):
        dC = h * _sym_unit(I)
        S_fd[:, I] = 2.0 * (law.energy(C + dC) - law.energy(C - dC)) / (2.0 * h)
    assert np.abs(S - S_fd).max() <= 1e-7 * np.abs(S_fd).max()


def _tangent_vs_fd(law, C, h=1e-6):
    S, CC = law.stress_and_tangent(C)
    CC_fd = np.empty_like(CC)
    for J in range(6):
        dC = h * _sym_unit(J)
        CC_fd[:, :, J] = 2.0 * (voigt(law.stress(C + dC)) - voigt(law.stress(C - dC))) / (2.0 * h)
    assert np.allclose(voigt(S), voigt(law.stress(C)), rtol=0, atol=1e-14 * np.abs(S).max())
    return CC, CC_fd


def test_tangent_is_twice_dS_dC(law):
    CC, CC_fd = _tangent_vs_fd(law, _random_C(N_SAMPLES, 12))
    assert np.abs(CC - CC_fd).max() <= 1e-7 * np.abs(CC_fd).max()
    # Major symmetry (CC is a Hessian of W in C).
    assert np.abs(CC - np.swapaxes(CC, 1, 2)).max() <= 1e-12 * np.abs(CC).max()


@pytest.mark.parametrize("alpha", [3.0, -2.0, 2.0, 0.7])
@pytest.mark.parametrize("gap", [0.0, 1e-12, 1e-9, 1e-6, 1e-3])
def test_ogden_tangent_at_repeated_eigenvalues(alpha, gap):
    """The divided differences at (near-)repeated eigenvalues of C, including C = l I."""
    law = classical_law(M.Ogden(1.0, alpha, 5.0))
    Q = _rotations(3, 21)
    lam = np.array(
        [
            [1.3, 1.3 * (1 + gap), 0.8],
            [1.1, 1.1 * (1 + gap), 1.1 * (1 - gap)],
            [0.9, 0.9, 0.9 * (1 + gap)],
        ]
    )
    C = Q @ (lam[:, :, None] * np.eye(3)) @ np.swapaxes(Q, 1, 2)
    CC, CC_fd = _tangent_vs_fd(law, C, h=1e-5)
    assert np.isfinite(CC).all()
    assert np.abs(CC - CC_fd).max() <= 1e-7 * np.abs(CC_fd).max()


# ----------------------------------------------------------------------------- pieces, errors
def test_strain_displacement_matrix(state):
    """B dx is the engineering Green-Lagrange strain increment, and B^T S_v = F S D_a."""
    points, cells, x = state
    mesh = mjed.TetMesh(points, cells)
    F = np.swapaxes(x[cells], 1, 2) @ mesh.D
    B = strain_displacement(F, mesh.D)
    dx = np.random.default_rng(3).standard_normal((len(cells), 4, 3))
    dF = np.swapaxes(dx, 1, 2) @ mesh.D
    dE = 0.5 * (np.swapaxes(F, 1, 2) @ dF + np.swapaxes(dF, 1, 2) @ F)
    assert np.allclose(B @ dx.reshape(-1, 12, 1), (voigt(dE) * WEIGHT)[:, :, None], atol=1e-13)
    S = classical_law(MATERIALS["NeoHookean"]).stress(np.swapaxes(F, 1, 2) @ F)
    FSD = mesh.D @ np.swapaxes(F @ S, 1, 2)
    assert np.allclose(
        (np.swapaxes(B, 1, 2) @ voigt(S)[:, :, None]).reshape(-1, 4, 3), FSD, atol=1e-13
    )


def test_inverted_element_is_refused():
    points, cells = MESH
    cl = ClassicalGalerkin(points, cells, MATERIALS["NeoHookean"])
    x = points.copy()
    x[:, 2] *= -1.0  # mirror: every cell inverted
    for call in (cl.energy, cl.force, cl.stiffness, cl.force_and_stiffness):
        with pytest.raises(mjed.InvertedElementError):
            call(x)
    flat = points.copy()
    flat[:, 2] = 0.0
    with pytest.raises(mjed.InvertedElementError):
        cl.force(flat)


def test_bad_positions_and_material():
    points, cells = MESH
    cl = ClassicalGalerkin(points, cells, MATERIALS["NeoHookean"])
    with pytest.raises(ValueError):
        cl.force(points[:-1])
    with pytest.raises(TypeError):
        ClassicalGalerkin(points, cells, object())
    with pytest.raises(ValueError):
        ClassicalGalerkin(points, cells, M.Costa(*COSTA, frame=_rotations(3, 1)))


# ----------------------------------------------------------------------------- UFL oracle
@pytest.mark.oracle
def test_matches_ufl_oracle(name, state):
    pytest.importorskip("dolfinx")
    import reference_fem

    if not reference_fem.dolfinx_available():
        pytest.skip("dolfinx not importable")
    points, cells, x = state
    material = MATERIALS[name]
    oracle = reference_fem.UFLOracle(points, cells, material)
    cl = ClassicalGalerkin(points, cells, material)
    f, K = cl.force_and_stiffness(x)
    assert _rel(f, oracle.force(x)) <= TOL
    assert _rel(K, oracle.stiffness(x)) <= TOL


def test_classical_law_dispatches_on_the_material_type():
    # A subclass inherits its base's law; an unregistered type gets an error naming it.
    class Softer(M.NeoHookean):
        pass

    C = np.diag([1.2, 0.9, 1.1])[None]
    assert np.array_equal(
        classical_law(Softer(mu=1.0, lam=2.0)).stress(C),
        classical_law(M.NeoHookean(mu=1.0, lam=2.0)).stress(C),
    )
    Fake = type("NeoHookean", (), {"mu": 1.0, "lam": 2.0})  # the right name is not enough
    with pytest.raises(TypeError, match=r"no classical law for material type .*NeoHookean"):
        classical_law(Fake())
