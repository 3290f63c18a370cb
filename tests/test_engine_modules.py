"""The engine's modules one by one: layout, workspace, cell-wise algebra, aggregation, edge
blocks, the evaluation record and the force field's public seam (evaluate / assemble).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import MATERIALS, box_mesh, perturbed

import mjed
from mjed.aggregates import fold_groups
from mjed.cellwise import CellState, apply_matrix, edge_dot, stress_node_vectors
from mjed.edge_blocks import edge_blocks_to_element_matrices
from mjed.evaluation import CellEvaluation, Want
from mjed.layout import BlockLayout, VectorLayout, to_component_major
from mjed.sparse import EDGES
from mjed.workspace import Workspace


@pytest.fixture
def body():
    rng = np.random.default_rng(4)
    points, cells = box_mesh(2, jitter=0.2)
    return mjed.TetMesh(points, cells), perturbed(points, rng)


def _state(mesh, x):
    x_t = np.ascontiguousarray(x[mesh.cells].transpose(2, 1, 0))
    return CellState(x_t, np.ascontiguousarray(mesh.D.transpose(2, 1, 0)), Workspace())


# ------------------------------------------------------------------ layout and workspace
def test_layout_names_are_the_axis_orders_the_pattern_reads(body):
    mesh, x = body
    field = mjed.HyperelasticForceField(mesh, MATERIALS["NeoHookean"])
    ev = field.evaluate(x, want=Want.GRADIENT | Want.STIFFNESS)
    cell_major = np.ascontiguousarray(ev.gradient.transpose(2, 1, 0))  # (m, 4, 3)
    pattern = field.pattern
    # Same sums, added in another order: equal to round-off.
    assert np.allclose(
        pattern.assemble_vector_layout(ev.gradient, VectorLayout.COMPONENT_MAJOR),
        pattern.assemble_vector_layout(cell_major, VectorLayout.CELL_MAJOR),
        rtol=0,
        atol=1e-14,
    )
    blocks_cm = np.ascontiguousarray(ev.blocks.transpose(3, 2, 0, 1))  # (m, 6, 3, 3)
    K1 = pattern.assemble_edge_blocks(ev.blocks, BlockLayout.COMPONENT_MAJOR)
    K2 = pattern.assemble_edge_blocks(blocks_cm, BlockLayout.CELL_MAJOR)
    assert abs(K1 - K2).max() < 1e-13
    A = np.arange(24.0).reshape(2, 3, 4)
    assert np.array_equal(to_component_major(A), np.moveaxis(A, 0, -1))


def test_workspace_reuses_by_name_and_shape():
    ws = Workspace()
    a = ws("a", (3, 5))
    assert ws("a", (3, 5)) is a
    assert ws("b", (3, 5)) is not a  # two names never share memory
    assert ws("a", (4, 5)) is not a  # a new shape reallocates
    assert len(ws) == 2 and ws.nbytes == 8 * (15 + 20)


# ------------------------------------------------------------------ cell-wise algebra
def test_apply_matrix_and_edge_dot(rng):
    A, V = rng.standard_normal((3, 3, 7)), rng.standard_normal((3, 4, 7))
    assert np.allclose(apply_matrix(A, V), np.einsum("ijm,jam->iam", A, V), rtol=1e-15, atol=1e-15)
    u = rng.standard_normal((3, 4, 7))
    expected = np.stack([np.einsum("km,km->m", u[:, a], V[:, b]) for a, b in EDGES])
    assert np.allclose(edge_dot(u, V), expected, rtol=1e-15, atol=1e-15)


def test_cell_state_F_J_and_dJ(body):
    mesh, x = body
    st = _state(mesh, x)
    F = np.einsum("mai,maj->mij", x[mesh.cells], mesh.D)
    assert np.allclose(st.F, F, rtol=1e-14, atol=1e-14)
    assert np.allclose(st.J, np.linalg.det(F), rtol=1e-13)
    # d_a = dJ/dx_a, by central differences of det F on one cell.
    h, c = 1e-6, 3
    for a in range(4):
        for k in range(3):
            xp, xm = x.copy(), x.copy()
            xp[mesh.cells[c, a], k] += h
            xm[mesh.cells[c, a], k] -= h
            fd = (_state(mesh, xp).J[c] - _state(mesh, xm).J[c]) / (2 * h)
            assert st.dJ()[k, a, c] == pytest.approx(fd, rel=1e-7, abs=1e-9)
    assert st.dJ() is st.dJ()  # formed once


# ------------------------------------------------------------------ aggregation
def test_fold_groups_gives_the_energy_and_stress_of_the_material(body):
    mesh, x = body
    mat = MATERIALS["NeoHookean"]
    st = _state(mesh, x)
    agg = fold_groups(mat.decomposition(), st.kin, st.J)
    C = np.swapaxes(st.F, 1, 2) @ st.F
    lnJ = np.log(st.J)
    W = 0.5 * mat.mu * (np.trace(C, axis1=1, axis2=2) - 3) - mat.mu * lnJ + 0.5 * mat.lam * lnJ**2
    assert np.allclose(agg.energy, W, rtol=1e-12, atol=1e-14)
    # S = mu I + h J C^-1 with h = dW/dJ at fixed C = (lam ln J - mu) / J.
    S = mat.mu * np.eye(3) + (mat.lam * lnJ - mat.mu)[:, None, None] * np.linalg.inv(C)
    S_engine = np.broadcast_to(agg.S, S.shape) + (agg.h * st.J)[:, None, None] * np.linalg.inv(C)
    assert np.allclose(S_engine, S, rtol=1e-12, atol=1e-12)
    assert agg.rank_one == ()  # no exponential group, and no stiffness asked


def test_fold_groups_rank_one_terms_only_when_asked(body):
    mesh, x = body
    st = _state(mesh, x)
    groups = MATERIALS["VerondaWestmann"].decomposition()
    assert fold_groups(groups, st.kin, st.J).rank_one == ()
    agg = fold_groups(
        groups, st.kin, st.J, lambda S, h, k: stress_node_vectors(st, S, h, np.empty((3, 4, st.m)))
    )
    assert len(agg.rank_one) == 1 and agg.rank_one[0][1].shape == (3, 4, st.m)


# ------------------------------------------------------------------ edge blocks
@pytest.mark.parametrize("name", ["NeoHookean", "Costa", "Ogden"])
def test_edge_blocks_are_the_derivative_of_the_gradient(body, name):
    mesh, x = body
    field = mjed.HyperelasticForceField(mesh, MATERIALS[name])
    K = edge_blocks_to_element_matrices(field.evaluate(x, want=Want.STIFFNESS).public().edge_blocks)
    scale = np.abs(K).max()
    assert np.allclose(K, np.swapaxes(K, 1, 2), rtol=0, atol=1e-13 * scale)
    assert np.allclose(
        K.reshape(-1, 12, 4, 3).sum(axis=2), 0.0, atol=1e-13 * scale
    )  # translation invariance
    c, h = 5, 1e-6
    for j in range(12):
        xp, xm = x.copy(), x.copy()
        xp[mesh.cells[c, j // 3], j % 3] += h
        xm[mesh.cells[c, j // 3], j % 3] -= h
        gp = field.evaluate(xp, want=Want.GRADIENT).public().gradient[c].ravel()
        gm = field.evaluate(xm, want=Want.GRADIENT).public().gradient[c].ravel()
        assert np.allclose(K[c, :, j], (gp - gm) / (2 * h), rtol=1e-6, atol=1e-7 * scale)


# ------------------------------------------------------------------ evaluation and the seam
def test_evaluate_returns_what_is_asked_and_nothing_else(body):
    mesh, x = body
    field = mjed.HyperelasticForceField(mesh, MATERIALS["MooneyRivlin"])
    ev = field.evaluate(x, want=Want.GRADIENT)
    assert isinstance(ev, CellEvaluation)
    assert ev.energy is None and ev.blocks is None and ev.pk2 is None and ev.F is None
    assert ev.gradient.shape == (3, 4, mesh.n_cells) and ev.J.shape == (mesh.n_cells,)
    full = field.evaluate(x, want=Want.ENERGY | Want.GRADIENT | Want.STIFFNESS | Want.STRESS)
    assert full.energy.sum() == pytest.approx(field.energy(x), rel=1e-14)
    assert full.blocks.shape == (3, 3, 6, mesh.n_cells) and full.pk2.shape == (mesh.n_cells, 3, 3)
    assert np.allclose(
        full.F, np.einsum("mai,maj->mij", x[mesh.cells], mesh.D), rtol=1e-14, atol=1e-14
    )
    pub = full.public()
    assert np.shares_memory(pub.gradient, full.gradient) and pub.gradient.shape == (
        mesh.n_cells,
        4,
        3,
    )


def test_seam_assembles_the_same_force_and_stiffness(body):
    mesh, x = body
    field = mjed.HyperelasticForceField(mesh, MATERIALS["Costa"])
    ev = field.evaluate(x, want=Want.GRADIENT | Want.STIFFNESS)
    f, K = field.force_and_stiffness(x)
    assert np.array_equal(field.assemble_force(ev.gradient), f)
    assert abs(field.assemble_stiffness(ev.blocks) - K).max() == 0.0
    # Without out= every evaluation is fresh (a caller may keep it); with out= the blocks go there.
    again = field.evaluate(x, want=Want.STIFFNESS)
    assert not np.shares_memory(again.blocks, ev.blocks)
    buf = np.empty((3, 3, 6, mesh.n_cells))
    assert field.evaluate(x, want=Want.STIFFNESS, out=buf).blocks is buf


def test_seam_checks_its_input(body):
    mesh, x = body
    field = mjed.HyperelasticForceField(mesh, MATERIALS["NeoHookean"])
    with pytest.raises(ValueError, match="shape"):
        field.evaluate(x[:-1])
    bad = x.copy()
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        field.evaluate(bad)
    flipped = x.copy()
    c = mesh.cells[0]
    face = x[c[1:]].mean(axis=0)
    flipped[c[0]] = face + 0.5 * (face - x[c[0]])
    with pytest.raises(mjed.InvertedElementError):
        field.evaluate(flipped, want=Want.GRADIENT)


# ------------------------------------------------------------------ the force-only path
@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_force_alone_is_the_force_of_force_and_stiffness(body, name):
    # The force path skips the energy, S-hat, g2 and every tangent coefficient, but the
    # gradient is formed by the same operations: the same numbers, bit for bit.
    mesh, x = body
    field = mjed.HyperelasticForceField(mesh, MATERIALS[name])
    f, _ = field.force_and_stiffness(x)
    assert np.array_equal(field.force(x), f)
    assert field.evaluate(x, want=Want.GRADIENT).energy is None


def test_force_alone_still_refuses_bad_input(body):
    mesh, x = body
    field = mjed.HyperelasticForceField(mesh, MATERIALS["StVenantKirchhoff"])  # no ln J to trip on
    flipped = x.copy()
    c = mesh.cells[2]
    face = x[c[1:]].mean(axis=0)
    flipped[c[0]] = face + 0.5 * (face - x[c[0]])
    with pytest.raises(mjed.InvertedElementError):
        field.force(flipped)
    with pytest.raises(ValueError, match="non-finite"):
        field.force(np.where(x == x[0, 0], np.nan, x))


def test_determinant_without_the_full_cofactor_is_the_same(body):
    from mjed.kinematics import Kinematics

    mesh, x = body
    Ft = np.ascontiguousarray(_state(mesh, x).Ft)
    alone = Kinematics(Ft=Ft.copy()).J  # cof_t never formed
    k = Kinematics(Ft=Ft.copy())
    k.cof_t
    assert np.array_equal(alone, k.J)


def test_invariant_functions_may_give_either_stress_layout(body):
    from mjed.terms import InvariantFunction, JPower, Term, TermGroup

    class CellMajor(InvariantFunction):  # g = tr C, written with stress() only
        def value(self, kin):
            return kin.I1

        def stress(self, kin):
            return np.broadcast_to(2.0 * np.eye(3), (kin.m, 3, 3)).copy()

    class ComponentMajor(InvariantFunction):  # the same g, written with stress_t() only
        def value(self, kin):
            return kin.I1

        def stress_t(self, kin):
            return np.broadcast_to((2.0 * np.eye(3))[:, :, None], (3, 3, kin.m)).copy()

    mesh, x = body
    st = _state(mesh, x)
    assert np.array_equal(CellMajor().stress_t(st.kin), ComponentMajor().stress_t(st.kin))
    assert np.array_equal(CellMajor().stress(st.kin), ComponentMajor().stress(st.kin))
    groups = lambda g: (TermGroup((Term(JPower(-2.0 / 3.0), g),)),)  # noqa: E731
    a = fold_groups(groups(CellMajor()), st.kin, st.J)
    b = fold_groups(groups(ComponentMajor()), st.kin, st.J)
    assert np.array_equal(a.S, b.S) and np.array_equal(a.h, b.h)


def test_edge_scalar_assembly_equals_identity_blocks(rng):
    # The history stiffness of the viscous field: blocks s Id, node blocks by translation
    # invariance.
    from mjed.sparse import CSRPattern

    points, cells = box_mesh(3, jitter=0.2)
    pattern = CSRPattern(cells, len(points))
    s = rng.standard_normal((len(cells), 6))
    blocks = s[:, :, None, None] * np.eye(3)[None, None]
    K_ref = pattern.assemble_edge_blocks(blocks)
    L = pattern.edge_scalar_matrix(s)
    assert abs(sp.kron(L, sp.identity(3)) - K_ref).max() <= 1e-14 * np.abs(K_ref.data).max()
    data = np.zeros(pattern.nnz)
    pattern.add_scalar_blocks(data, L)
    assert np.abs(data - K_ref.data).max() <= 1e-14 * np.abs(K_ref.data).max()
    with pytest.raises(ValueError, match=r"\(m, 6\)"):
        pattern.edge_scalar_matrix(s[:, :5])
    with pytest.raises(ValueError, match="edge_scalar_matrix"):
        pattern.add_scalar_blocks(data[:-1], L)


def test_a_group_mixing_constant_and_per_cell_stresses_sums_them_per_cell(rng):
    # mu/2 I1 (f = 1: a constant S) beside c J^(-2/3) I1 (per-cell S) in one group: the sum is
    # broadcast over the cells. Declared as two groups instead, nothing mixes: same energy,
    # same force and tangent. Three cells is the size where a bad broadcast passes silently.
    import warnings

    from mjed.materials.base import Material
    from mjed.terms import I1Power, JPower, LogPolynomial, Term, TermGroup, Unity

    terms = (
        Term(JPower(0.0), I1Power(500.0, 1)),
        Term(JPower(-2 / 3), I1Power(300.0, 1)),
        Term(LogPolynomial(5000.0, -1000.0, 0.0), Unity()),
    )

    class OneGroup(Material):
        def decomposition(self):
            return (TermGroup(terms),)

    class Split(Material):
        def decomposition(self):
            return tuple(TermGroup((t,)) for t in terms)

    points, cells = box_mesh(2, jitter=0.2)
    for m in (3, len(cells)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # nodes no kept cell uses
            mesh = mjed.TetMesh(points, cells[:m])
        x = perturbed(points, rng, 0.05)
        f1, K1 = mjed.HyperelasticForceField(mesh, OneGroup()).force_and_stiffness(x)
        f2, K2 = mjed.HyperelasticForceField(mesh, Split()).force_and_stiffness(x)
        assert np.abs(f1 - f2).max() <= 1e-12 * np.abs(f2).max()
        assert abs(K1 - K2).max() <= 1e-12 * abs(K2).max()
        from mjed.compiled import numba_available

        if numba_available():  # the compiled kernel sums the same group
            f3, K3 = mjed.make_force_field(mesh, OneGroup(), backend="numba").force_and_stiffness(x)
            assert np.abs(f3 - f2).max() <= 1e-12 * np.abs(f2).max()
            assert abs(K3 - K2).max() <= 1e-12 * abs(K2).max()
