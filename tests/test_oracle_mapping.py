"""Tests of the UFL oracle itself (reference_fem), independent of the mjed engine.

They check the numbering maps (shuffled meshes), the rest state, symmetry, closed-form
homogeneous deformations computed in NumPy from the same W, Ogden against its invariant
forms, and finite differences. Materials are mjed's declarations (the oracle dispatches on
their types and reads only their parameters, never mjed's term code).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest

pytest.importorskip(
    "dolfinx", reason="dolfinx is not installed (Debian: python3-dolfinx); the UFL oracle needs it"
)

import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg  # noqa: E402,F401  (sp.linalg.norm)
import ufl  # noqa: E402
from conftest import MATERIALS as TEST_MATERIALS  # noqa: E402

from mjed.materials import (  # noqa: E402
    Costa,
    NeoHookean,
    Ogden,
    StVenantKirchhoff,
    declarations,
)
from reference_fem import UFLOracle, dolfinx_available, strain_energy_density  # noqa: E402

# noqa: E402
from reference_fem.energies import energy_formula, register_energy, supported_materials
from reference_fem.sparse_map import CSRRenumbering  # noqa: E402

pytestmark = pytest.mark.oracle


# -- materials (mjed's declarations: the oracle dispatches on their types) ---------------
COSTA = dict(a=1.0, k0=5.0, b_ff=8.0, b_fs=4.0, b_ss=3.0, b_fn=4.0, b_sn=2.0, b_nn=3.0)
# every declared material, at the unit-scale parameters of the tests (conftest.MATERIALS; Costa
# with stiffer fibres, for a response that depends on the frame): a new declaration is covered
# without editing this file
MATERIALS = {d.name: TEST_MATERIALS[d.name] for d in declarations()}
MATERIALS["Costa"] = Costa(**COSTA)


# -- meshes and states ------------------------------------------------------------------
def random_rotations(rng: np.random.Generator, m: int) -> np.ndarray:
    """(m, 3, 3) random proper rotations."""
    Q, R = np.linalg.qr(rng.standard_normal((m, 3, 3)))
    Q = Q * np.sign(np.diagonal(R, axis1=1, axis2=2))[:, None, :]
    Q[np.linalg.det(Q) < 0, :, 0] *= -1.0
    return Q


def cube_mesh(n: int, jitter: float = 0.0, seed: int = 0):
    """Unit cube, n^3 sub-cubes of 6 tetrahedra each; points (N, 3), cells (6 n^3, 4).

    ``jitter`` moves every node randomly by up to jitter * h, making the cells irregular.
    """
    g = np.linspace(0.0, 1.0, n + 1)
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    P = P + jitter / n * np.random.default_rng(seed).uniform(-1, 1, P.shape)
    node = lambda i, j, k: (i * (n + 1) + j) * (n + 1) + k  # noqa: E731
    cells = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                v = [node(i + a, j + b, k + c) for a in (0, 1) for b in (0, 1) for c in (0, 1)]
                # Kuhn split: the six paths from corner 0 to corner 7 along the cube's edges.
                for p, q in ((4, 6), (4, 5), (2, 6), (2, 3), (1, 5), (1, 3)):
                    cells.append([v[0], v[p], v[q], v[7]])
    T = np.array(cells, dtype=np.int64)
    e = P[T[:, 1:]] - P[T[:, :1]]
    neg = np.linalg.det(e) < 0
    T[neg] = T[neg][:, [0, 2, 1, 3]]
    assert np.all(np.linalg.det(P[T[:, 1:]] - P[T[:, :1]]) > 0)
    return P, T


def deformed(P: np.ndarray, seed: int = 1, amp: float = 0.03) -> np.ndarray:
    """A smooth-ish random state: an affine map plus nodal noise (J stays > 0)."""
    rng = np.random.default_rng(seed)
    A = np.eye(3) + 0.15 * rng.standard_normal((3, 3))
    return P @ A.T + 0.1 + amp * rng.standard_normal(P.shape)


def rel(a, b) -> float:
    """Relative difference in the 2-norm (Frobenius for sparse matrices)."""
    if sp.issparse(a) or sp.issparse(b):
        return sp.linalg.norm(sp.csr_matrix(a) - b) / sp.linalg.norm(b)
    return np.linalg.norm(np.asarray(a) - b) / np.linalg.norm(b)


@pytest.fixture(scope="module")
def mesh():
    return cube_mesh(2, jitter=0.15, seed=3)


@pytest.fixture(scope="module")
def oracles(mesh):
    """One oracle per material on the irregular cube mesh (built once, reused)."""
    P, T = mesh
    return {name: UFLOracle(P, T, mat) for name, mat in MATERIALS.items()}


# -- (1) numbering: shuffled input gives the same answers -------------------------------
def _costa_cellwise(m: int) -> Costa:
    return Costa(**COSTA, frame=random_rotations(np.random.default_rng(7), m))


@pytest.mark.parametrize("kind", ["NeoHookean", "Costa-cellwise"])
def test_shuffled_numbering_gives_same_force_and_stiffness(mesh, kind):
    P, T = mesh
    rng = np.random.default_rng(11)
    perm = rng.permutation(len(P))  # new node i is old node perm[i]
    cperm = rng.permutation(len(T))  # new cell c is old cell cperm[c]
    new_of_old = np.empty_like(perm)
    new_of_old[perm] = np.arange(len(P))
    # Cyclic shift of the first three local vertices: an even permutation, keeps orientation.
    T_new = new_of_old[T[cperm]][:, [1, 2, 0, 3]]
    P_new = P[perm]
    if kind == "NeoHookean":
        mat_old = mat_new = MATERIALS["NeoHookean"]
    else:
        mat_old = _costa_cellwise(len(T))
        mat_new = dataclasses.replace(mat_old, frame=mat_old.frame[cperm])

    a, b = UFLOracle(P, T, mat_old), UFLOracle(P_new, T_new, mat_new)
    # The test is only meaningful if dolfinx really renumbered something.
    assert not np.array_equal(a.numbering.input_cell_of_cell, np.arange(len(T)))
    assert not np.array_equal(a.numbering.input_node_of_dof_node, np.arange(len(P)))

    x = deformed(P)
    f_a, K_a = a.force_and_stiffness(x)
    f_b, K_b = b.force_and_stiffness(x[perm])
    assert rel(f_b, f_a[perm]) <= 1e-12
    dof = (3 * perm[:, None] + np.arange(3)).ravel()
    assert rel(K_b, K_a[dof][:, dof]) <= 1e-12
    assert abs(b.energy(x[perm]) - a.energy(x)) <= 1e-12 * abs(a.energy(x))


def test_unused_input_node_gets_zero_force_and_empty_rows(mesh):
    P, T = mesh
    P2 = np.vstack([P[:5], [[3.0, 3.0, 3.0]], P[5:]])  # node 5 is not in any cell
    T2 = np.where(T >= 5, T + 1, T)
    o = UFLOracle(P2, T2, MATERIALS["NeoHookean"])
    x = deformed(P2)
    f, K = o.force_and_stiffness(x)
    assert K.shape == (3 * len(P2), 3 * len(P2))
    assert np.all(f[5] == 0) and K[15:18].nnz == 0 and K[:, 15:18].nnz == 0
    f_ref = UFLOracle(P, T, MATERIALS["NeoHookean"]).force(np.delete(x, 5, axis=0))
    assert rel(np.delete(f, 5, axis=0), f_ref) <= 1e-13


# -- (2) rest state, (3) symmetry --------------------------------------------------------
@pytest.mark.parametrize("name", list(MATERIALS))
def test_rest_state_has_zero_energy_and_force(oracles, mesh, name):
    P, _ = mesh
    o = oracles[name]
    assert abs(o.energy(P)) <= 1e-14
    assert np.abs(o.force(P)).max() <= 1e-13


@pytest.mark.parametrize("name", list(MATERIALS))
def test_stiffness_is_symmetric(oracles, mesh, name):
    K = oracles[name].stiffness(deformed(mesh[0]))
    assert K.shape == (3 * len(mesh[0]),) * 2
    assert sp.linalg.norm(K - K.T) <= 1e-13 * sp.linalg.norm(K)


# -- (4) homogeneous deformation of one tetrahedron, in closed form ----------------------
def W_stvk(F, mu, lam):
    E = 0.5 * (F.T @ F - np.eye(3))
    return 0.5 * lam * np.trace(E) ** 2 + mu * np.trace(E @ E)


def W_neo(F, mu, lam):
    lnJ = np.log(np.linalg.det(F))
    return 0.5 * mu * (np.trace(F.T @ F) - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2


def W_costa(F, R, a, k0, b_ff, b_fs, b_ss, b_fn, b_sn, b_nn):
    B = np.array([[b_ff, b_fs, b_fn], [b_fs, b_ss, b_sn], [b_fn, b_sn, b_nn]])
    J = np.linalg.det(F)
    Ef = R.T @ (0.5 * (F.T @ F - np.eye(3))) @ R
    return 0.5 * a * (np.exp(J ** (-4.0 / 3.0) * np.sum(B * Ef**2)) - 1.0) + k0 * (
        J * np.log(J) - J + 1.0
    )


def complex_step_P(W: Callable, F: np.ndarray) -> np.ndarray:
    """P = dW/dF by the complex step (exact to rounding for analytic W)."""
    h = 1e-30
    P = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            Fc = F.astype(complex)
            Fc[i, j] += 1j * h
            P[i, j] = W(Fc).imag / h
    return P


def one_tet():
    X = np.array([[0.1, 0.0, 0.05], [1.0, 0.1, 0.0], [0.2, 0.9, 0.1], [0.15, 0.2, 1.1]])
    M = (X[1:] - X[0]).T  # columns X_j - X_0
    V0 = np.linalg.det(M) / 6.0
    G = np.linalg.inv(M)  # row j-1 = grad of barycentric coordinate j
    D = np.vstack([-G.sum(axis=0), G])  # (4, 3) shape-function gradients D_a
    return X, np.array([[0, 1, 2, 3]]), V0, D


@pytest.mark.parametrize(
    "material, W",
    [
        (StVenantKirchhoff(mu=1.3, lam=2.1), lambda F: W_stvk(F, 1.3, 2.1)),
        (NeoHookean(mu=1.3, lam=2.1), lambda F: W_neo(F, 1.3, 2.1)),
    ],
    ids=["StVenantKirchhoff", "NeoHookean"],
)
def test_homogeneous_deformation_matches_closed_form(material, W):
    X, T, V0, D = one_tet()
    A = np.array([[1.2, 0.1, -0.05], [0.03, 0.9, 0.2], [0.1, -0.1, 1.05]])
    x = X @ A.T + np.array([0.3, -0.2, 0.1])
    P = complex_step_P(W, A)
    # The complex step agrees with the hand-derived first Piola-Kirchhoff stresses.
    mu, lam = material.mu, material.lam
    if type(material).__name__ == "StVenantKirchhoff":
        E = 0.5 * (A.T @ A - np.eye(3))
        P_hand = A @ (lam * np.trace(E) * np.eye(3) + 2.0 * mu * E)
    else:
        P_hand = mu * A + (lam * np.log(np.linalg.det(A)) - mu) * np.linalg.inv(A).T
    assert np.allclose(P, P_hand, rtol=1e-14, atol=1e-14)

    o = UFLOracle(X, T, material)
    assert o.energy(x) == pytest.approx(V0 * W(A), rel=1e-13)
    assert rel(o.force(x), -V0 * D @ P.T) <= 1e-13  # f_a = -V0 P D_a


def test_homogeneous_deformation_of_whole_mesh_matches_numpy_assembly(mesh):
    """Same closed form on many cells, assembled in NumPy in input numbering: checks the
    node map without going through the oracle's own numbering code twice.
    """
    P, T = mesh
    mu, lam = 1.3, 2.1
    A = np.array([[1.2, 0.1, -0.05], [0.03, 0.9, 0.2], [0.1, -0.1, 1.05]])
    Pk = complex_step_P(lambda F: W_neo(F, mu, lam), A)
    M = np.transpose(P[T[:, 1:]] - P[T[:, :1]], (0, 2, 1))  # (m, 3, 3) columns X_j - X_0
    V0 = np.linalg.det(M) / 6.0
    G = np.linalg.inv(M)
    D = np.concatenate([-G.sum(axis=1, keepdims=True), G], axis=1)  # (m, 4, 3)
    f = np.zeros_like(P)
    np.add.at(f, T, -V0[:, None, None] * D @ Pk.T)
    o = UFLOracle(P, T, NeoHookean(mu, lam))
    assert rel(o.force(P @ A.T), f) <= 1e-13


@pytest.mark.parametrize("per_cell", [False, True], ids=["frame33", "frame-per-cell"])
def test_costa_frame_homogeneous(per_cell):
    """A non-symmetric rotation R catches R^T E R vs R E R^T and the DG0 component layout."""
    X, T, V0, D = one_tet()
    R = random_rotations(np.random.default_rng(5), 1)
    mat = Costa(**COSTA, frame=R if per_cell else R[0])
    A = np.array([[1.1, 0.1, -0.05], [0.03, 0.95, 0.1], [0.08, -0.1, 1.02]])
    x = X @ A.T
    W = lambda F: W_costa(F, R[0], **COSTA)  # noqa: E731
    o = UFLOracle(X, T, mat)
    assert o.energy(x) == pytest.approx(V0 * W(A), rel=1e-13)
    assert rel(o.force(x), -V0 * D @ complex_step_P(W, A).T) <= 1e-13


# -- (5) Ogden against its invariant forms ---------------------------------------------
def assemble_custom(oracle: UFLOracle, W_of_F: Callable, x: np.ndarray):
    """Energy, force and stiffness of a hand-written UFL energy on the oracle's own mesh."""
    import dolfinx.fem as fem
    import dolfinx.fem.petsc as fem_petsc

    V, nb = oracle.function_space, oracle.numbering
    u = fem.Function(V)
    u.x.array[:] = nb.to_dof_order(x - oracle.points)
    F = ufl.Identity(3) + ufl.grad(u)
    dx = ufl.Measure("dx", domain=oracle.mesh, metadata={"quadrature_degree": 1})
    Pi = W_of_F(F) * dx
    R = ufl.derivative(Pi, u, ufl.TestFunction(V))
    K = ufl.derivative(R, u, ufl.TrialFunction(V))
    energy = fem.assemble_scalar(fem.form(Pi))
    force = -nb.to_input_order(fem_petsc.assemble_vector(fem.form(R)).array)
    A = fem_petsc.assemble_matrix(fem.form(K))
    A.assemble()
    Kmat = CSRRenumbering(nb.input_dof_of_dof, 3 * oracle.n_nodes)(*A.getValuesCSR())
    return energy, force, Kmat


def ogden_invariant_form(alpha: float, mu: float, k0: float) -> Callable:
    def W(F):
        C = F.T * F
        J = ufl.det(F)
        I1b = J ** (-2.0 / 3.0) * ufl.tr(C)
        I2b = J ** (-4.0 / 3.0) * 0.5 * (ufl.tr(C) ** 2 - ufl.tr(C * C))
        vol = 0.5 * k0 * ufl.ln(J) ** 2
        iso = {
            2.0: mu / 4 * (I1b - 3),
            4.0: mu / 16 * (I1b**2 - 2 * I2b - 3),
            -2.0: mu / 4 * (I2b - 3),
        }[alpha]
        return iso + vol

    return W


@pytest.mark.parametrize("alpha", [2.0, 4.0, -2.0])
def test_ogden_matches_invariant_forms(mesh, alpha):
    P, T = mesh
    o = UFLOracle(P, T, Ogden(mu=1.7, alpha=alpha, k0=4.0))
    W = ogden_invariant_form(alpha, 1.7, 4.0)
    Q = random_rotations(np.random.default_rng(8), 1)[0]
    stretched = lambda *lam: P @ (Q @ np.diag(lam) @ Q.T).T  # noqa: E731
    states = {
        # all eigenvalues distinct: the trigonometric formula
        "large": (deformed(P, amp=0.05), 1e-12),
        # |dev C| < 1e-3 tr C / 3: the isotropic series (forces ~1e-5, so a looser bound)
        "small": (P + 1e-5 * np.random.default_rng(2).standard_normal(P.shape), 1e-9),
        # two equal eigenvalues (r = +1 and r = -1), and nearly equal: the pair series
        "uniaxial": (stretched(1.3, 1.0, 1.0), 1e-12),
        "equibiaxial": (stretched(1.2, 1.2, 0.9), 1e-12),
        "near-uniaxial": (stretched(1.3, 1.0 + 1e-9, 1.0), 1e-12),
    }
    for name, (x, tol) in states.items():
        e_ref, f_ref, K_ref = assemble_custom(o, W, x)
        f, K = o.force_and_stiffness(x)
        assert abs(o.energy(x) - e_ref) <= 1e-12 * max(abs(e_ref), 1e-3), name
        assert rel(f, f_ref) <= tol, name
        assert rel(K, K_ref) <= 1e-12, name
    _, _, K_ref = assemble_custom(o, W, P)
    assert rel(o.stiffness(P), K_ref) <= 1e-13


@pytest.mark.parametrize(
    "stretches", [(1.2, 0.9, 1.05), (1.3, 1.0, 1.0)], ids=["distinct", "uniaxial"]
)
def test_ogden_general_alpha_homogeneous(stretches):
    """Alpha = 3 (no invariant form): NumPy eigenvalues and central differences."""
    X, T, V0, D = one_tet()
    mu, alpha, k0 = 1.3, 3.0, 4.0

    def W(F):
        J = np.linalg.det(F)
        lam = np.linalg.eigvalsh(F.T @ F)
        iso = mu / alpha**2 * (J ** (-alpha / 3) * np.sum(lam ** (alpha / 2)) - 3)
        return iso + 0.5 * k0 * np.log(J) ** 2

    Q = random_rotations(np.random.default_rng(4), 1)[0]
    A = (
        Q
        @ np.diag(stretches)
        @ Q.T
        @ np.array([[1.0, 0.0, 0.0], [0.0, 0.8, 0.6], [0.0, -0.6, 0.8]])
    )
    h = 1e-6
    P = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            dA = np.zeros((3, 3))
            dA[i, j] = h
            P[i, j] = (W(A + dA) - W(A - dA)) / (2 * h)
    o = UFLOracle(X, T, Ogden(mu, alpha, k0))
    assert o.energy(X @ A.T) == pytest.approx(V0 * W(A), rel=1e-13)
    assert rel(o.force(X @ A.T), -V0 * D @ P.T) <= 1e-8


# -- (6) finite differences ------------------------------------------------------------
@pytest.mark.parametrize("name", list(MATERIALS))
def test_central_differences(oracles, mesh, name):
    o = oracles[name]
    x = deformed(mesh[0], seed=4)
    d = np.random.default_rng(9).standard_normal(x.shape)
    h = 1e-6
    f, K = o.force_and_stiffness(x)
    dE = (o.energy(x + h * d) - o.energy(x - h * d)) / (2 * h)
    assert dE == pytest.approx(-np.sum(f * d), rel=1e-7)
    df = (o.force(x + h * d) - o.force(x - h * d)) / (2 * h)
    assert rel(df.ravel(), -(K @ d.ravel())) <= 1e-7


# -- input validation and dispatch ---------------------------------------------------------
def test_invalid_inputs_raise_clear_errors(mesh, oracles):
    P, T = mesh
    o = oracles["NeoHookean"]
    with pytest.raises(ValueError, match="shape"):
        o.force(P[:-1])
    with pytest.raises(ValueError, match="non-finite"):
        o.force(np.where(P == P[0, 0], np.nan, P))
    with pytest.raises(ValueError, match="positively oriented"):
        UFLOracle(P, T[:, [1, 0, 2, 3]], MATERIALS["NeoHookean"])
    with pytest.raises(ValueError, match="range"):
        UFLOracle(P, T + 1, MATERIALS["NeoHookean"])
    with pytest.raises(ValueError, match="no UFL energy"):
        UFLOracle(P, T, object())
    with pytest.raises(ValueError, match="orthonormal"):
        UFLOracle(P, T, Costa(**COSTA, frame=2.0 * np.eye(3)))
    x = P.copy()
    face = P[T[0, 1:]].mean(axis=0)
    x[T[0, 0]] = face + 0.5 * (face - P[T[0, 0]])  # through the opposite face: J < 0
    with pytest.raises(ValueError, match="J <= 0"):
        o.force(x)


def test_energy_registry_dispatches_on_type():
    # Every material mjed declares has exactly one UFL energy; a subclass inherits its base's.
    assert set(supported_materials()) >= {type(m) for m in MATERIALS.values()}
    assert energy_formula(Costa).takes_frame and not energy_formula(NeoHookean).takes_frame

    @dataclass(frozen=True)
    class Stiffer(NeoHookean):
        pass

    F = ufl.Identity(3)
    assert energy_formula(Stiffer) is energy_formula(NeoHookean)
    assert strain_energy_density(Stiffer(mu=1.0, lam=2.0), F) is not None

    # A type with the right class name but not registered is refused, naming the type.
    Fake = type("NeoHookean", (), {"mu": 1.0, "lam": 2.0})
    with pytest.raises(
        ValueError, match=r"no UFL energy for material type .*NeoHookean; register one"
    ):
        strain_energy_density(Fake(), F)
    with pytest.raises(ValueError, match="already registered"):
        register_energy(NeoHookean)(lambda p, F, frame: None)
    with pytest.raises(TypeError, match="needs a type"):
        register_energy("NeoHookean")


def test_overrides_replace_a_parameter_without_changing_the_material(mesh):
    # k0 = 0 drops MooneyRivlin's bulk term: W(F) = c1 (I1b - 3) + c2 (I2b - 3) at a homogeneous F.
    m = MATERIALS["MooneyRivlin"]
    A = np.array([[1.2, 0.1, 0.0], [0.0, 0.9, 0.05], [0.02, 0.0, 1.1]])
    W = strain_energy_density(m, ufl.as_matrix(A.tolist()), overrides={"k0": 0.0})
    J, C = np.linalg.det(A), A.T @ A
    I1, I2 = np.trace(C), 0.5 * (np.trace(C) ** 2 - np.trace(C @ C))
    expected = m.c1 * (J ** (-2 / 3) * I1 - 3.0) + m.c2 * (J ** (-4 / 3) * I2 - 3.0)
    assert float(W) == pytest.approx(expected, rel=1e-13)
    assert m.k0 == 5.0


def test_helpers():
    assert dolfinx_available()
    F = ufl.Identity(3)
    assert strain_energy_density(MATERIALS["NeoHookean"], F) is not None
    with pytest.raises(ValueError, match="frame"):
        strain_energy_density(MATERIALS["NeoHookean"], F, frame=ufl.Identity(3))
    # mjed refuses alpha = 0 on construction; the oracle's own guard is reached by forcing it.
    zero_alpha = Ogden(1.0, 1.0, 1.0)
    object.__setattr__(zero_alpha, "alpha", 0.0)
    with pytest.raises(ValueError, match="alpha"):
        strain_energy_density(zero_alpha, F)


def test_oracles_on_one_mesh_share_it_and_answer_as_if_alone(mesh):
    """Serial oracles on the same points and cells share the dolfinx mesh, space and numbering
    (reference_fem.ufl_oracle._mesh_space_numbering); each still answers as one built alone.
    """
    from reference_fem import ufl_oracle

    points, cells = mesh
    a = UFLOracle(points, cells, NeoHookean(mu=1000.0, lam=5000.0))
    b = UFLOracle(points, cells, Ogden(mu=900.0, alpha=3.0, k0=4000.0))
    assert a.mesh is b.mesh and a.numbering is b.numbering
    moved = points.copy()
    moved[0] += 1e-3
    assert UFLOracle(moved, cells, a._material).mesh is not a.mesh  # other points: its own
    x = points + np.random.default_rng(5).uniform(-0.02, 0.02, points.shape)
    fa, Ka = a.force(x), a.stiffness(x)
    ufl_oracle._SHARED.clear()  # built alone
    alone = UFLOracle(points, cells, a._material)
    assert alone.mesh is not a.mesh
    np.testing.assert_array_equal(fa, alone.force(x))
    assert abs(Ka - alone.stiffness(x)).max() == 0.0


def test_a_form_compiled_again_comes_from_memory(mesh):
    """The dolfinx JIT is asked once per form signature and options in a process
    (reference_fem.compat.install_jit_memo); a form with another signature is compiled.
    """
    from dolfinx import jit

    from reference_fem import compat

    points, cells = mesh
    oracle = UFLOracle(points, cells, NeoHookean(mu=1000.0, lam=5000.0))
    oracle.compile_forms()
    assert getattr(jit.ffcx_jit, "memoised", False)
    inner, asked = jit.ffcx_jit.__wrapped__, []

    def counting(comm, ufl_object, *args, **kwargs):
        asked.append(ufl_object)
        return inner(comm, ufl_object, *args, **kwargs)

    jit.ffcx_jit.__wrapped__ = counting
    try:
        u = compat.function(oracle.function_space, "u")
        dx = ufl.Measure("dx", domain=oracle.mesh, metadata={"quadrature_degree": 1})
        k = 1.0 + 0.25 * len(compat._JIT_MEMO)  # a form no earlier test compiled
        first = compat.compile_form(k * ufl.inner(ufl.grad(u), ufl.grad(u)) * dx)
        again = compat.compile_form(k * ufl.inner(ufl.grad(u), ufl.grad(u)) * dx)
        other = compat.compile_form(2 * k * ufl.inner(ufl.grad(u), ufl.grad(u)) * dx)
    finally:
        jit.ffcx_jit.__wrapped__ = inner
    assert len(asked) == 2  # the first form and the other one, not the first again
    u.x.array[:] = np.random.default_rng(2).uniform(-0.05, 0.05, u.x.array.shape)
    values = [compat.assemble_scalar_local(f) for f in (first, again, other)]
    assert values[0] == values[1] and values[2] == pytest.approx(2 * values[0], rel=1e-13)
