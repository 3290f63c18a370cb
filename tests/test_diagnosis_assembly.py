"""Assembly adding a repeated entry once (conformance.diagnosis.assembly): the mistaken engines
are written here with NumPy's own buffered fancy indexing (``f[dofs] -= fe``,
``K[rows, cols] += Ke``), not with the module's model of it; MJED stands in for the oracle in
the fast tests, and one test runs the whole check with the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from conformance.diagnosis.assembly import buffered_findings
from conformance.diagnosis.elements import assemble
from conformance.judge.compare import DOUBLE
from reference_fem import dolfinx_available


def _case(material, seed=0):
    """(split, oracle force, oracle stiffness, scales) of MJED on a jittered box, deformed."""
    from common.cases import default_material

    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    return mjed_split(default_material(material), points, cells, x)


def _dofs(cells):
    return (3 * cells[:, :, None] + np.arange(3)).reshape(cells.shape[0], 12)


def test_force_by_buffered_fancy_indexing_is_named():
    split, f_o, K_o, s = _case("StVenantKirchhoff")
    force = np.zeros(3 * split.n)
    force[_dofs(split.cells)] -= -split.fe.reshape(-1, 12)  # the mistake, as users write it
    assert np.linalg.norm(force.reshape(-1, 3) - f_o) > 0.1 * np.linalg.norm(f_o)
    found = buffered_findings(split, force.reshape(-1, 3), K_o, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].code == "assembly-repeated-once"
    assert found[0].figures["force_rule"] == "last" and found[0].figures["stiffness_rule"] == "sum"
    assert "force assembled" in found[0].title and "stiffness" not in found[0].title


def test_dense_stiffness_by_buffered_fancy_indexing_is_named():
    split, f_o, K_o, s = _case("NeoHookean", seed=1)
    m, dof = split.cells.shape[0], _dofs(split.cells)
    K = np.zeros((3 * split.n, 3 * split.n))
    rows = np.broadcast_to(dof[:, :, None], (m, 12, 12))
    cols = np.broadcast_to(dof[:, None, :], (m, 12, 12))
    K[rows, cols] += split.Ke  # the mistake
    found = buffered_findings(split, f_o, sp.csr_matrix(K), s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures == {**found[0].figures, "force_rule": "sum", "stiffness_rule": "last"}


def test_cells_written_backwards_are_told_from_the_last_write():
    """Cells looped in reverse: each shared entry keeps the FIRST cell's contribution."""
    split, f_o, K_o, s = _case("MooneyRivlin", seed=2)
    force = np.zeros(3 * split.n)
    backwards = np.ascontiguousarray(_dofs(split.cells)[::-1])  # a view would be written
    force[backwards] = np.ascontiguousarray(split.fe.reshape(-1, 12)[::-1])  # in memory order
    found = buffered_findings(split, force.reshape(-1, 3), K_o, s, DOUBLE)
    assert len(found) == 1 and found[0].figures["force_rule"] == "first", found


def test_one_contribution_per_entry_in_the_engines_own_order_is_named():
    """Triplets listed node block by node block (all cells' (a, b) block, then the next pair),
    then de-duplicated keeping the first of each entry: neither the first nor the last cell of
    the mesh's order, yet one cell's contribution per entry.
    """
    split, f_o, K_o, s = _case("NeoHookean", seed=4)
    m, dof = split.cells.shape[0], _dofs(split.cells)
    Ke = split.Ke.reshape(m, 4, 3, 4, 3)
    rows, cols, vals = [], [], []
    for a, b in [(a, b) for a in range(4) for b in range(4)][::-1]:
        rows.append(np.repeat(dof[:, 3 * a : 3 * a + 3], 3, axis=1).ravel())
        cols.append(np.tile(dof[:, 3 * b : 3 * b + 3], (1, 3)).ravel())
        vals.append(Ke[:, a, :, b, :].reshape(-1))
    rows, cols, vals = (np.concatenate(v) for v in (rows, cols, vals))
    N = 3 * split.n
    _, first = np.unique(rows.astype(np.int64) * N + cols, return_index=True)  # the mistake
    K = sp.csr_matrix((vals[first], (rows[first], cols[first])), shape=(N, N))
    assert abs(K - K_o).max() > 0.01 * abs(K_o).max()
    found = buffered_findings(split, f_o, K, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures["force_rule"] == "sum" and found[0].figures["stiffness_rule"] == "one"
    assert "your engine's own write order" in found[0].title


def test_nearby_assembly_mistakes_are_not_called_buffered():
    """A skipped cell, a doubled cell, a scaled force: not one contribution per entry."""
    split, f_o, K_o, s = _case("StVenantKirchhoff", seed=3)
    w = np.ones(split.cells.shape[0])
    w[5] = 0.0
    for weights in (w, np.where(np.arange(w.size) == 7, 2.0, 1.0)):
        f, K = assemble(
            split.cells,
            split.n,
            weights[:, None, None] * split.fe,
            weights[:, None, None] * split.Ke,
        )
        assert buffered_findings(split, f, K, s, DOUBLE) == []
    assert buffered_findings(split, 1.01 * f_o, K_o, s, DOUBLE) == []
    assert buffered_findings(split, f_o, K_o, s, DOUBLE) == []  # the right output: nothing


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_check_names_a_buffered_force_assembly():
    import mjed
    from conformance.protocol import check_implementation

    def engine(case):
        field = mjed.make_force_field(mjed.TetMesh(case.points, case.cells), case.model)
        fe = np.asarray(field.element_forces(case.positions))
        force = np.zeros(3 * case.points.shape[0])
        force[_dofs(case.cells)] += fe.reshape(-1, 12)
        return force.reshape(-1, 3), field.stiffness(case.positions)

    run = check_implementation(
        engine, material="StVenantKirchhoff", mesh="cube-small", states=("random",), probes=False
    )
    (outcome,) = run.outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed" and len(d.causes) == 1, d.text()
    assert d.causes[0].code == "assembly-repeated-once", d.text()
    assert "buffered fancy indexing" in d.causes[0].title
