"""Shape-function gradients built wrongly (conformance.diagnosis.shape_gradients): assigned to
the cell's nodes in another order. The mistaken engine is a St Venant-Kirchhoff engine written
here by hand (its stiffness by complex step of its force, exact to round-off), not MJED; MJED
stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.shape_gradients import shape_gradient_findings
from conformance.judge.compare import DOUBLE
from mjed import materials as M


def _svk_engine(points, cells, x, G_of, mu=1.0, lam=2.0, origin=None):
    """Force (n, 3) and stiffness of W = lam/2 (tr E)^2 + mu tr(E^2) with the shape gradients
    G_of(M^-1 rows (m, 4, 3)) -> (m, 4, 3) used for F and the force; V0 the true volume, or
    with ``origin`` (a node order) det[X_o1 - X_o0, X_o2 - X_o0, X_o3 - X_o0] / 6.
    """
    X = points[cells]
    Mt = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)
    V0 = np.linalg.det(Mt) / 6.0
    if origin is not None:
        Xo = X[:, list(origin)]
        V0 = np.linalg.det(np.swapaxes(Xo[:, 1:] - Xo[:, :1], 1, 2)) / 6.0
    Minv = np.linalg.inv(Mt)
    D = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)  # right gradients
    G = G_of(D)
    n, m = points.shape[0], cells.shape[0]

    def force(y):
        F = np.einsum("mai,maj->mij", y[cells], G)
        E = 0.5 * (np.einsum("mki,mkj->mij", F, F) - np.eye(3))
        S = lam * np.trace(E, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * mu * E
        fe = -V0[:, None, None] * np.einsum("mij,mjk,mak->mai", F, S, G)
        f = np.zeros((n, 3), dtype=fe.dtype)
        np.add.at(f, cells.ravel(), fe.reshape(4 * m, 3))
        return f

    h = 1e-30
    cols = []
    for k in range(3 * n):  # complex step: K = -df/dx, exact to round-off
        y = x.astype(complex)
        y.reshape(-1)[k] += 1j * h
        cols.append(-np.imag(force(y)).ravel() / h)
    return force(x), sp.csr_matrix(np.column_stack(cols))


def _case(seed):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    model = M.StVenantKirchhoff(mu=1.0, lam=2.0)
    return points, cells, x, model, *mjed_split(model, points, cells, x)


@pytest.mark.parametrize("perm", [(1, 2, 3, 0), (1, 0, 3, 2), (0, 2, 1, 3)])
def test_gradients_assigned_in_another_node_order_are_named(perm):
    points, cells, x, model, split, f_o, K_o, s = _case(0)
    assert np.allclose(_svk_engine(points, cells, x, lambda D: D)[0], f_o, atol=1e-12)
    f, K = _svk_engine(points, cells, x, lambda D: D[:, list(perm)])
    found = shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "gradients-node-order-" + "".join(map(str, perm))
    assert str(perm) in found[0].title and "shape-function gradients" in found[0].title


def test_a_node_order_with_the_volume_from_its_own_edges_is_named():
    """An odd order with V0 = det / 6 of the reordered edges: negative, force and K flip."""
    points, cells, x, model, split, f_o, K_o, s = _case(2)
    perm = (1, 2, 3, 0)
    f, K = _svk_engine(points, cells, x, lambda D: D[:, list(perm)], origin=perm)
    found = shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["gradients-node-order-1230-negative-volume"]
    assert "negative" in found[0].title
    # an even order keeps the volume's sign: named without it
    perm = (1, 0, 3, 2)
    f, K = _svk_engine(points, cells, x, lambda D: D[:, list(perm)], origin=perm)
    found = shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["gradients-node-order-1032"]


def test_other_gradient_mistakes_are_not_given_a_node_order():
    """Transposed gradients are named as such; gradients of a wrong size fit no order."""
    points, cells, x, model, split, f_o, K_o, s = _case(1)

    def transposed(D):
        Minv_t = np.swapaxes(D[:, 1:], 1, 2)
        return np.concatenate([-Minv_t.sum(axis=1, keepdims=True), Minv_t], axis=1)

    f, K = _svk_engine(points, cells, x, transposed)
    found = shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["gradients-transposed"]
    f, K = _svk_engine(points, cells, x, lambda D: 1.01 * D[:, [1, 2, 3, 0]])
    assert shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE) == []
    assert shape_gradient_findings(split, model, points, x, f_o, K_o, s, DOUBLE) == []


# ---------------------------------------------------------------- gradients that do not sum to 0
def _node_zero_engine(weights):
    """Mooney-Rivlin from C (J = sqrt(det C), as an engine that forms W from C has it), with
    node 0's gradient written sum_b weights[b - 1] D_b; hyper-dual, independent of MJED.
    """
    from hyperdual_engine import density_engine, det, ln, sqrt

    def density(model, k, F, R):
        J = sqrt(det(k.C))
        I1b = J ** (-2.0 / 3.0) * k.I1
        I2b = J ** (-4.0 / 3.0) * k.I2
        return model.c1 * (I1b - 3.0) + model.c2 * (I2b - 3.0) + model.k0 / 2.0 * ln(J) * ln(J)

    def gradients(D):
        D = D.copy()
        D[:, 0] = np.einsum("b,mbi->mi", np.asarray(weights), D[:, 1:])
        return D

    return density_engine(density, gradients=gradients)


@pytest.mark.parametrize(
    "code, weights",
    [("gradient-0-sign", (1.0, 1.0, 1.0)), ("gradient-0-without-2", (-1.0, 0.0, -1.0))],
)
def test_a_node_zero_gradient_written_wrongly_is_named(code, weights):
    from types import SimpleNamespace

    from conformance.diagnosis.shape_gradients import gradient_slip_findings

    model = default_material("MooneyRivlin")
    points, cells = box_mesh(2, jitter=0.2, seed=5)
    x = points @ np.diag([1.1, 0.95, 0.92]).T
    x = x + 0.02 * np.random.default_rng(5).standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    case = SimpleNamespace(points=points, cells=cells, positions=x, model=model)
    with np.errstate(invalid="ignore"):  # the namespace's own ln(det F') where F' inverts
        f, K, _ = _node_zero_engine(weights)(case)
    found = gradient_slip_findings(split, model, points, x, f.reshape(-1, 3), K, s, DOUBLE)
    assert [x.code for x in found] == [code], [x.title for x in found]
    # the oracle's own output is none of them
    assert gradient_slip_findings(split, model, points, x, f_o, K_o, s, DOUBLE) == []


def test_gradients_and_volumes_from_the_current_positions_are_named():
    """An engine initialised on the deformed state: its rest geometry is the current one."""
    from types import SimpleNamespace

    from conformance.diagnosis.shape_gradients import gradient_slip_findings

    model = default_material("MooneyRivlin")
    points, cells = box_mesh(2, jitter=0.2, seed=6)
    x = points @ np.diag([1.1, 0.95, 0.92]).T
    x = x + 0.02 * np.random.default_rng(6).standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    deformed_as_rest = SimpleNamespace(points=x, cells=cells, positions=x, model=model)
    f, K, _ = _node_zero_engine((-1.0, -1.0, -1.0))(deformed_as_rest)  # node 0 right here
    found = gradient_slip_findings(split, model, points, x, f.reshape(-1, 3), K, s, DOUBLE)
    assert [x.code for x in found] == ["gradients-current-volume"], [x.title for x in found]


def test_the_gradient_of_the_positions_taken_for_that_of_the_displacements_is_named():
    """FElupe's F = I + grad u written with the positions: F = I + grad x."""
    from types import SimpleNamespace

    from hyperdual_engine import density_engine

    from conformance.diagnosis.shape_gradients import gradient_slip_findings

    model = default_material("StVenantKirchhoff")
    points, cells = box_mesh(2, jitter=0.2, seed=7)
    x = points @ np.diag([1.1, 0.95, 0.92]).T
    x = x + 0.02 * np.random.default_rng(7).standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)

    def density(model, k, F, R):
        E = k.E
        trE = E[0, 0] + E[1, 1] + E[2, 2]
        EE = sum(E[i, j] * E[i, j] for i in range(3) for j in range(3))
        return model.lam / 2.0 * trE * trE + model.mu * EE

    engine = density_engine(density, deformation=lambda F: F + np.eye(3))
    case = SimpleNamespace(points=points, cells=cells, positions=x, model=model)
    with np.errstate(invalid="ignore"):
        f, K, _ = engine(case)
    found = gradient_slip_findings(split, model, points, x, f.reshape(-1, 3), K, s, DOUBLE)
    assert [x.code for x in found] == ["F-identity-plus-positions"], [x.title for x in found]


def test_a_rest_edge_taken_from_another_node_is_named():
    """The rest edge matrix typed [X1 - X0, X2 - X0, X3 - X1]: M' = M (I - e1 e3^T), so the
    engine's gradients are D'_0 = D_0 - D_3, D'_1 = D_1 + D_3, D'_2 = D_2, D'_3 = D_3 (its
    volume right).
    """
    points, cells, x, model, split, f_o, K_o, s = _case(3)

    def slipped(D):
        return np.stack([D[:, 0] - D[:, 3], D[:, 1] + D[:, 3], D[:, 2], D[:, 3]], axis=1)

    f, K = _svk_engine(points, cells, x, slipped)
    found = shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["rest-edge-3-from-node-1"], [x.title for x in found]
    assert "X_3 - X_1 where X_3 - X_0 belongs" in found[0].title


@pytest.mark.parametrize("factor", [2.0, 1.0 / 3.0])
def test_every_gradient_scaled_is_named_with_its_factor(factor):
    """D'_a = k D_a for every node (a face area without its 1/2: k = 2), the rest volume
    right: F = k F at rest too. Named with k; a scale no engine writes (1.01) is not.
    """
    points, cells, x, model, split, f_o, K_o, s = _case(4)
    f, K = _svk_engine(points, cells, x, lambda D: factor * D)
    found = shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["gradients-scaled"], [x.title for x in found]
    assert abs(found[0].figures["factor"] - factor) < 1e-12
    f, K = _svk_engine(points, cells, x, lambda D: 1.01 * D)
    assert shape_gradient_findings(split, model, points, x, f, K, s, DOUBLE) == []


def _assembly_engine(points, cells, x, G_of, mu=1.0, lam=2.0):
    """St Venant-Kirchhoff with F from the right gradients (F = Ds M^-1) and the force and
    element matrices built with G_of(right gradients): P by hand, dP/dF by complex step.
    """
    X = points[cells]
    Mt = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)
    V0 = np.linalg.det(Mt) / 6.0
    Minv = np.linalg.inv(Mt)
    D = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)
    G = G_of(D)
    F = np.einsum("mai,maj->mij", x[cells], D)

    def piola(F):
        E = 0.5 * (np.einsum("mki,mkj->mij", F, F) - np.eye(3))
        S = lam * np.trace(E, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * mu * E
        return F @ S

    A = np.empty(F.shape + (3, 3))
    for ll in range(3):
        for L in range(3):
            H = np.zeros((3, 3), dtype=complex)
            H[ll, L] = 1e-30j
            A[:, :, :, ll, L] = np.imag(piola(F + H)) / 1e-30
    fe = -V0[:, None, None] * np.einsum("mkI,maI->mak", piola(F), G)
    Ke = V0[:, None, None, None, None] * np.einsum("maI,mkIlL,mbL->makbl", G, A, G)
    from conformance.diagnosis.elements import assemble

    return assemble(cells, points.shape[0], fe, Ke.reshape(-1, 12, 12))


def _columns(D):
    G = D.copy()
    G[:, 1:] = np.swapaxes(D[:, 1:], 1, 2)  # the columns of M^-1 for its rows
    G[:, 0] = -G[:, 1:].sum(axis=1)
    return G


def _node_zero_from_columns(D):
    G = D.copy()
    G[:, 0] = -np.swapaxes(D[:, 1:], 1, 2).sum(axis=1)
    return G


@pytest.mark.parametrize(
    "G_of, code",
    [
        (_columns, "assembly-gradients-transposed"),
        (_node_zero_from_columns, "assembly-gradient-0-columns"),
    ],
)
def test_an_assembly_operator_built_apart_from_f_is_named(G_of, code):
    """dF/dx (the B matrix) built from other gradients than F = Ds M^-1."""
    from conformance.diagnosis.shape_gradients import gradient_slip_findings

    points, cells, x, model, split, f_o, K_o, s = _case(8)
    f, K = _assembly_engine(points, cells, x, G_of)
    found = gradient_slip_findings(split, model, points, x, f, K, s, DOUBLE)
    assert [x.code for x in found] == [code], [x.title for x in found]
    right = _assembly_engine(points, cells, x, lambda D: D)  # the right operator: the oracle
    assert np.abs(right[0] - f_o).max() <= 1e-12 * np.abs(f_o).max()
