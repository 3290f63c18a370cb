"""Element forces written to the wrong local nodes or with a local node's sign wrong, the
stiffness right (conformance.diagnosis.element_forces). The mistaken engines are small St
Venant-Kirchhoff engines written here in Sifakis' form (H = -V0 P Dm^-T gives the forces on
nodes 1, 2, 3; node 0's is minus their sum); MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.element_forces import force_node_findings
from conformance.judge.compare import DOUBLE

MODEL = default_material("StVenantKirchhoff")


def _case(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.12, 0.96, 0.9]).T + 0.03 * rng.standard_normal(points.shape)
    split, f_o, K_o = mjed_split(MODEL, points, cells, x)[:3]
    return points, cells, x, split, f_o, K_o


def _sifakis_forces(points, cells, x):
    """(m, 4, 3): H's three columns (forces on local nodes 1, 2, 3) and node 0's -(f1+f2+f3)."""
    Dm = np.swapaxes(points[cells[:, 1:]] - points[cells[:, :1]], 1, 2)
    Ds = np.swapaxes(x[cells[:, 1:]] - x[cells[:, :1]], 1, 2)
    Dm_inv = np.linalg.inv(Dm)
    F = Ds @ Dm_inv
    E = 0.5 * (np.swapaxes(F, 1, 2) @ F - np.eye(3))
    tr = np.trace(E, axis1=1, axis2=2)
    S = MODEL.lam * tr[:, None, None] * np.eye(3) + 2 * MODEL.mu * E
    V0 = np.abs(np.linalg.det(Dm)) / 6
    H = -V0[:, None, None] * (F @ S) @ np.swapaxes(Dm_inv, 1, 2)  # columns: f1, f2, f3
    f123 = np.swapaxes(H, 1, 2)
    return f123, -f123.sum(axis=1)


def _scatter(cells, n, fe):
    f = np.zeros((n, 3))
    np.add.at(f, cells, fe)
    return f


def test_the_hand_written_forces_are_the_oracles():
    points, cells, x, split, f_o, K_o = _case()
    f123, f0 = _sifakis_forces(points, cells, x)
    f = _scatter(cells, points.shape[0], np.concatenate([f0[:, None], f123], axis=1))
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max()


def test_forces_scattered_shifted_by_one_node_are_named():
    points, cells, x, split, f_o, K_o = _case(1)
    s = mjed_split(MODEL, points, cells, x)[3]
    f123, f0 = _sifakis_forces(points, cells, x)
    # the engine's mistake: H's columns then node 0, stacked [f1, f2, f3, f0], scattered to 0..3
    f = _scatter(cells, points.shape[0], np.concatenate([f123, f0[:, None]], axis=1))
    found = force_node_findings(split, f, K_o, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures["order"] == [1, 2, 3, 0] and found[0].figures["signs"] == [1] * 4
    assert "shifted by 1 local node" in found[0].title and "[f1, f2, f3, f0]" in found[0].title
    # the same forces with the stiffness wrong too: not a force-only slip
    assert force_node_findings(split, f, K_o * 1.01, s, DOUBLE) == []


def test_node0_force_with_its_sign_lost_is_named():
    points, cells, x, split, f_o, K_o = _case(2)
    s = mjed_split(MODEL, points, cells, x)[3]
    f123, f0 = _sifakis_forces(points, cells, x)
    f = _scatter(cells, points.shape[0], np.concatenate([-f0[:, None], f123], axis=1))
    found = force_node_findings(split, f, K_o, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures["order"] == [0, 1, 2, 3] and found[0].figures["signs"] == [-1, 1, 1, 1]
    assert "local node 0" in found[0].title and "do not sum to zero" in found[0].title


def test_nearby_mistakes_are_not_named():
    """The right force, the whole force's sign flipped, node 0's force doubled, and the forces
    of one cell only shifted: none is a per-cell map of the local nodes.
    """
    points, cells, x, split, f_o, K_o = _case(3)
    s = mjed_split(MODEL, points, cells, x)[3]
    f123, f0 = _sifakis_forces(points, cells, x)
    n = points.shape[0]
    right = np.concatenate([f0[:, None], f123], axis=1)
    one_cell = right.copy()
    one_cell[5] = np.roll(right[5], -1, axis=0)
    for f in (
        f_o,
        -f_o,
        _scatter(cells, n, np.concatenate([2 * f0[:, None], f123], axis=1)),
        _scatter(cells, n, one_cell),
    ):
        assert force_node_findings(split, f, sp.csr_matrix(K_o), s, DOUBLE) == []


def test_forces_raveled_components_first_against_a_cell_major_dof_map_are_named():
    """FElupe's trailing layout: r of shape (4, 3, m) summed with np.bincount over a (m, 12)
    dof map, both raveled.
    """
    points, cells, x, split, f_o, K_o = _case(2)
    s = mjed_split(MODEL, points, cells, x)[3]
    f123, f0 = _sifakis_forces(points, cells, x)
    r = np.concatenate([f0[:, None], f123], axis=1).transpose(1, 2, 0)  # (4, 3, m)
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 12)
    f = np.bincount(dofs.ravel(), weights=r.ravel(), minlength=3 * points.shape[0])
    found = force_node_findings(split, f.reshape(-1, 3), K_o, s, DOUBLE)
    assert [x.code for x in found] == ["element-force-layout"], [x.title for x in found]
    assert "(4, 3, m)" in found[0].title
