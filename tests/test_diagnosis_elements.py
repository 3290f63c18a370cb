"""Mistakes inside the element (conformance.diagnosis.elements): a local dof order in the
scatter, and a force that is the divergence of another stress measure. Each mistaken engine is
built here by hand; MJED stands in for the oracle in the fast tests (the mechanism only needs
force and stiffness to split), and one test runs the whole check with the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import (
    assemble,
    element_split,
    order_findings,
    stress_measure_findings,
)
from conformance.judge.compare import DOUBLE
from reference_fem import dolfinx_available


def _state(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T
    x = x + 0.03 * np.random.default_rng(seed).standard_normal(points.shape)
    return points, cells, x


def _split(model, points, cells, x):
    return mjed_split(model, points, cells, x)


def test_component_major_element_matrix_is_named():
    from common.cases import default_material

    points, cells, x = _state()
    split, f_o, K_o, s = _split(default_material("Ogden"), points, cells, x)
    # the engine's mistake: its element matrix indexed [c, a] (4 c + a) scattered as 3 a + c
    Ke = split.Ke.reshape(-1, 4, 3, 4, 3).transpose(0, 2, 1, 4, 3).reshape(-1, 12, 12)
    _, K = assemble(cells, points.shape[0], split.fe, Ke)
    found = order_findings(split, f_o, K, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "element-order" and "component-major" in found[0].title
    assert "stiffness only" in found[0].title and "permuted" not in found[0].title
    # the correct output and a wrong one that no order explains: nothing named
    assert order_findings(split, f_o, K_o, s, DOUBLE) == []
    assert order_findings(split, f_o, K_o * 1.01, s, DOUBLE) == []


def test_local_nodes_permuted_in_force_and_stiffness_are_named():
    from common.cases import default_material

    points, cells, x = _state(1)
    split, f_o, K_o, s = _split(default_material("NeoHookean"), points, cells, x)
    p = (3 * np.array([1, 0, 2, 3])[:, None] + np.arange(3)).ravel()
    f, K = assemble(
        cells,
        points.shape[0],
        split.fe.reshape(-1, 12)[:, p].reshape(-1, 4, 3),
        split.Ke[:, p][:, :, p],
    )
    found = order_findings(split, f, K, s, DOUBLE)
    assert len(found) == 1 and "(1, 0, 2, 3)" in found[0].title, [x.title for x in found]
    assert "force and stiffness" in found[0].title


def test_a_dof_map_from_sorted_cells_is_named():
    """The element results in the kit's node order scattered through each cell's sorted node
    ids (the engine's own sort): named with how many cells moved; the right output, nothing.
    """
    from common.cases import default_material

    points, cells, x = _state(2)
    split, f_o, K_o, s = _split(default_material("VerondaWestmann"), points, cells, x)
    rows = np.array([sorted(c) for c in cells.tolist()])
    f, K = assemble(rows, points.shape[0], split.fe, split.Ke)
    found = order_findings(split, f, K, s, DOUBLE)
    moved = int(np.sum(np.any(rows != cells, axis=1)))
    assert moved > 0 and len(found) == 1, [x.title for x in found]
    assert "sorted" in found[0].title and found[0].figures["cells"] == moved
    assert order_findings(split, f_o, K_o, s, DOUBLE) == []


def _neo_hookean_piola(F, mu, lam):
    """P and dP/dF [k, i, l, j] of W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2, by hand."""
    Fit = np.linalg.inv(F).swapaxes(1, 2)
    J = np.linalg.det(F)
    lnJ = np.log(J)
    P = mu * (F - Fit) + (lam * lnJ)[:, None, None] * Fit
    eye = np.eye(3)
    A = (
        mu * np.einsum("kl,ij->kilj", eye, eye)[None]
        + (mu - lam * lnJ)[:, None, None, None, None] * np.einsum("mkj,mli->mkilj", Fit, Fit)
        + lam * np.einsum("mki,mlj->mkilj", Fit, Fit)
    )
    return P, A, J


def test_cauchy_stress_over_the_rest_volume_is_named():
    """An engine integrating sigma F^-T = P / J over the rest volume, written by hand."""
    from common.cases import default_material
    from mjed.mesh import shape_vectors

    model = default_material("NeoHookean")
    points, cells, x = _state(2)
    split, f_o, K_o, s = _split(model, points, cells, x)
    V0, D = shape_vectors(points, cells)
    V0 = np.abs(V0)
    F = np.einsum("mai,maj->mij", x[cells], D)
    P, A, J = _neo_hookean_piola(F, model.mu, model.lam)
    Fit = np.linalg.inv(F).swapaxes(1, 2)
    Pw = P / J[:, None, None]
    Aw = A / J[:, None, None, None, None] - np.einsum("mki,mlj->mkilj", Pw, Fit)
    fe = -V0[:, None, None] * np.einsum("mki,mai->mak", Pw, D)
    Ke = V0[:, None, None, None, None] * np.einsum("mai,mkilj,mbj->makbl", D, Aw, D)
    f, K = assemble(cells, points.shape[0], fe, Ke.reshape(-1, 12, 12))
    found = stress_measure_findings(split, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["stress-measure-cauchy-rest-volume"], found
    assert "Cauchy" in found[0].title
    assert stress_measure_findings(split, f_o, K_o, s, DOUBLE) == []


def test_p_transposed_is_named_only_where_p_is_not_symmetric():
    """An engine using P^T as P (force and its exact derivative): named on a general state; on
    a uniaxial stretch (F and S diagonal, P symmetric) its force is the oracle's, and the
    stiffness alone is no evidence of a stress measure: not named there.
    """
    from common.cases import default_material
    from mjed.mesh import shape_vectors

    model = default_material("NeoHookean")
    general = _state(3)
    points, cells, _ = general
    uniaxial = (points, cells, points @ np.diag([1.2, 0.93, 0.93]).T)
    for (points, cells, x), named in ((general, True), (uniaxial, False)):
        split, f_o, K_o, s = _split(model, points, cells, x)
        V0, D = shape_vectors(points, cells)
        V0 = np.abs(V0)
        F = np.einsum("mai,maj->mij", x[cells], D)
        P, A, _ = _neo_hookean_piola(F, model.mu, model.lam)
        Pt, At = P.swapaxes(1, 2), A.transpose(0, 2, 1, 3, 4)  # d(P^T)_ki / dF_lj
        fe = -V0[:, None, None] * np.einsum("mki,mai->mak", Pt, D)
        Ke = V0[:, None, None, None, None] * np.einsum("mai,mkilj,mbj->makbl", D, At, D)
        f, K = assemble(cells, points.shape[0], fe, Ke.reshape(-1, 12, 12))
        found = stress_measure_findings(split, f, K, s, DOUBLE)
        if named:
            assert [x.code for x in found] == ["stress-measure-piola-transposed"], found
        else:
            assert np.abs(f - f_o).max() <= 1e-12 * np.abs(f_o).max()  # the same force
            assert abs(K - K_o).max() > 1e-3 * abs(K_o).max()  # another stiffness
            assert found == [], found


@pytest.mark.parametrize(
    "built, code",
    [
        (lambda P, F: P.swapaxes(1, 2), "stress-measure-piola-transposed"),
        (lambda P, F: F @ P @ F.swapaxes(1, 2), "stress-measure-kirchhoff-as-second-piola"),
    ],
)
def test_a_force_alone_from_another_measure_is_named_beside_a_right_stiffness(built, code):
    """An F-based engine whose force is built from P^T (P flattened row-major against a
    column-major dF/dx) or from F tau (the Kirchhoff stress taken for S), its stiffness from the
    invariants and right: named as the force alone, the stiffness the oracle's.
    """
    from common.cases import default_material
    from mjed.mesh import shape_vectors

    model = default_material("NeoHookean")
    points, cells, x = _state(4)
    split, f_o, K_o, s = _split(model, points, cells, x)
    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    P, _, _ = _neo_hookean_piola(F, model.mu, model.lam)
    fe = -np.abs(V0)[:, None, None] * np.einsum("mki,mai->mak", built(P, F), D)
    f = assemble(cells, points.shape[0], fe, None)[0]
    found = stress_measure_findings(split, f, K_o, s, DOUBLE)
    assert [(x.code, x.figures.get("force_only")) for x in found] == [(code, True)], found
    assert "force alone" in found[0].title
    # the same force with a stiffness that is neither: nothing
    assert stress_measure_findings(split, f, 1.01 * K_o, s, DOUBLE) == []


def test_no_split_for_a_model_mjed_does_not_have_or_a_wrong_sum():
    from common.cases import default_material

    points, cells, x = _state()
    split, f_o, K_o, s = _split(default_material("NeoHookean"), points, cells, x)
    assert element_split(object(), points, cells, x, f_o, K_o, s, DOUBLE) is None
    assert (
        element_split(default_material("NeoHookean"), points, cells, x, f_o, K_o * 1.001, s, DOUBLE)
        is None
    )


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_check_names_the_element_order():
    """The whole check, with the oracle: an Ogden engine scattering component-major blocks (on
    one tetrahedron the local order is the global one: a mesh of several cells is needed).
    """
    import mjed
    from conformance.protocol import check_implementation

    def engine(case):
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
        Ke = field.element_stiffness(case.positions).reshape(-1, 4, 3, 4, 3)
        Ke = Ke.transpose(0, 2, 1, 4, 3).reshape(-1, 12, 12)
        f = field.force(case.positions)
        return f, assemble(case.cells, case.points.shape[0], np.zeros((len(Ke), 4, 3)), Ke)[1]

    run = check_implementation(
        engine, material="Ogden", mesh=box_mesh(2, jitter=0.2, seed=3), states=("random",)
    )
    for o in run.outcomes:
        assert o.status == "failed"
        assert o.diagnosis.findings[0].code == "element-order", o.diagnosis.text()


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_shape_function_gradients_transposed_are_named():
    """An engine whose D_a are the columns of M^-1: written here as the UFL oracle on cells
    whose rest edges are the rows of M (then its gradients are those columns), summed back.
    """
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle

    def engine(case):
        cells, m, n = case.cells, case.cells.shape[0], case.points.shape[0]
        X = case.points[cells]
        edges = X[:, 1:] - X[:, :1]  # (m, 3, 3), row a: edge a (M's column a)
        rows_of_m = np.swapaxes(edges, 1, 2)  # row a: M's row a, the new cell's edge a
        rest = np.concatenate([np.zeros((m, 1, 3)), rows_of_m], axis=1).reshape(-1, 3)
        o = UFLOracle(rest, np.arange(4 * m).reshape(m, 4), case.model)
        fe, Ke = o.force_and_stiffness(case.positions[cells].reshape(-1, 3))
        P = sp.csr_matrix((np.ones(4 * m), (np.arange(4 * m), cells.ravel())), shape=(4 * m, n))
        P3 = sp.kron(P, sp.identity(3)).tocsr()
        return P.T @ fe, (P3.T @ Ke @ P3).tocsr()

    run = check_implementation(
        engine, material="VerondaWestmann", mesh="cube-small", states=("random",), probes=False
    )
    (outcome,) = run.outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed" and len(d.causes) == 1, d.text()
    assert d.causes[0].code == "gradients-transposed", d.text()


def test_a_difference_stiffness_with_its_rows_from_a_reordered_force_is_named():
    """The element force written component-major and scattered node-major; the stiffness of
    differences (or a complex step) of that force takes its rows from it, its columns right.
    """
    from common.cases import default_material

    points, cells, x = _state(2)
    split, f_o, K_o, s = _split(default_material("VerondaWestmann"), points, cells, x)
    p = (3 * np.arange(4)[None, :] + np.arange(3)[:, None]).ravel()  # i = 4 c + a
    f, K = assemble(
        cells,
        points.shape[0],
        split.fe.reshape(-1, 12)[:, p].reshape(-1, 4, 3),
        split.Ke[:, p, :],
    )
    found = order_findings(split, f, K, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert "rows" in found[0].title and "component-major" in found[0].title


@pytest.mark.parametrize("code", ["element-columns-accumulated", "element-columns-coordinates"])
def test_perturbed_columns_of_an_element_stiffness_are_named(code):
    """A complex-step or difference element stiffness whose perturbation was not reset between
    the dofs, or whose relative step was divided by h alone; the force right.
    """
    from common.cases import default_material

    points, cells, x = _state(3)
    split, f_o, K_o, s = _split(default_material("Ogden"), points, cells, x)
    if code == "element-columns-accumulated":
        Ke = split.Ke @ np.triu(np.ones((12, 12)))
    else:
        Ke = split.Ke * x[cells].reshape(-1, 1, 12)
    _, K = assemble(cells, points.shape[0], split.fe, Ke)
    found = order_findings(split, f_o, K, s, DOUBLE)
    assert [x.code for x in found] == [code], [x.title for x in found]


def test_a_cauchy_stress_pushed_forward_with_f_transposed_is_named():
    """The Cauchy stress F^T S F / J for F S F^T / J: its force (and the complex-step stiffness of
    that force) is the divergence of P' = F^T F^-1 P F F^-T.
    """
    from common.cases import default_material
    from conformance.diagnosis.elements import STRESS_MEASURES, _measure_output, cell_piola

    points, cells, x = _state(4)
    split, f_o, K_o, s = _split(default_material("StVenantKirchhoff"), points, cells, x)
    P, A = cell_piola(split)
    f, K = _measure_output(split, P, A, STRESS_MEASURES["pushforward-transposed"][1])
    found = stress_measure_findings(split, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["stress-measure-pushforward-transposed"], found


@pytest.mark.parametrize("which", [0, 1, 2])
def test_element_matrix_values_stored_wrongly_are_named(which):
    """Each storage slip, written here with the engine's own packing (triu values read as tril
    positions; a (78, m) pair buffer or a (144, m) entry buffer reshaped for its transpose):
    named, the force right; the right matrices name nothing.
    """
    from common.cases import default_material

    points, cells, x = _state(3)
    split, f_o, K_o, s = _split(default_material("Gent"), points, cells, x)
    m = cells.shape[0]
    iu, il = np.triu_indices(12), np.tril_indices(12)
    if which == 0:
        Ke = np.zeros((m, 12, 12))
        Ke[:, il[0], il[1]] = split.Ke[:, iu[0], iu[1]]
        Ke = Ke + np.transpose(Ke, (0, 2, 1)) - Ke * np.eye(12)
    elif which == 1:
        buffer = np.empty((78, m))
        for p in range(78):
            buffer[p] = split.Ke[:, iu[0][p], iu[1][p]]
        pairs = buffer.reshape(m, 78)
        Ke = np.zeros((m, 12, 12))
        Ke[:, iu[0], iu[1]] = pairs
        Ke[:, iu[1], iu[0]] = pairs
    else:
        Ke = np.stack([split.Ke[:, i // 12, i % 12] for i in range(144)]).reshape(m, 12, 12)
    _, K = assemble(cells, points.shape[0], split.fe, Ke)
    found = order_findings(split, f_o, K, s, DOUBLE)
    assert [x.code for x in found] == ["element-storage"], [x.title for x in found]
    assert ("triu" in found[0].title) == (which == 0)
    assert ("(78, m)" in found[0].title) == (which == 1)


def test_a_dof_map_built_with_repeat_for_tile_is_named():
    """3 np.repeat(cells, 3, axis=1) + np.repeat(np.arange(3), 4): the engine's own scatter of
    its element matrices through that map (the force scattered by node, right).
    """
    import scipy.sparse as sp

    from common.cases import default_material

    points, cells, x = _state(4)
    split, f_o, K_o, s = _split(default_material("MooneyRivlin"), points, cells, x)
    dofs = 3 * np.repeat(cells, 3, axis=1) + np.repeat(np.arange(3), 4)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    n = 3 * points.shape[0]
    K = sp.csr_matrix((split.Ke.ravel(), (rows, cols)), shape=(n, n))
    found = order_findings(split, f_o, K, s, DOUBLE)
    assert [x.code for x in found] == ["element-storage"], [x.title for x in found]
    assert "np.repeat(np.arange(3), 4)" in found[0].title
