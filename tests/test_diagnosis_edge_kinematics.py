"""The deformation gradient formed from the edge matrices wrongly (conformance.diagnosis.
edge_kinematics): an engine written here that forms, per cell, Dm and Ds from the node
coordinates with the deformed edges stacked as rows (F' = Ds^T Dm^-1) and then computes a
correct Neo-Hookean cell at F' (MJED's field on the cell's own nodes placed at F' X), assembled.
Against it: the same engine with F formed right, and with a stress that is not at F'.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh, mjed_split

import mjed
from conformance.diagnosis.edge_kinematics import edge_kinematics_findings
from conformance.judge.compare import DOUBLE
from mjed import materials as M


class _Out:
    def __init__(self, force, stiffness):
        self.force, self.stiffness = force, stiffness


@pytest.fixture(scope="module")
def case():
    points, cells = box_mesh(2, jitter=0.2, seed=2)
    rng = np.random.default_rng(2)
    x = points @ np.diag([1.1, 0.95, 0.97]).T + 0.02 * rng.standard_normal(points.shape)
    model = M.NeoHookean(mu=600.0, lam=3000.0)
    _, f_o, K_o, s = mjed_split(model, points, cells, x)
    return model, points, cells, x, s


def _engine(case, rows: bool, scale: float = 1.0):
    model, points, cells, x, _ = case
    X, xs = points[cells], x[cells]
    Dm = np.stack([X[:, k] - X[:, 0] for k in (1, 2, 3)], axis=2)
    Ds = np.stack([xs[:, k] - xs[:, 0] for k in (1, 2, 3)], axis=1 if rows else 2)
    Fp = Ds @ np.linalg.inv(Dm)
    m = cells.shape[0]
    own = np.arange(4 * m).reshape(m, 4)
    field = mjed.HyperelasticForceField(mjed.TetMesh(X.reshape(-1, 3), own), model)
    xp = np.einsum("mij,maj->mai", Fp, X).reshape(-1, 3)
    fe, Ke = field.element_forces(xp), field.element_stiffness(xp)
    n = points.shape[0]
    f = np.zeros((n, 3))
    np.add.at(f, cells, scale * np.asarray(fe))
    dof = (3 * cells[:, :, None] + np.arange(3)).reshape(m, 12)
    K = sp.csr_matrix(
        (
            np.asarray(Ke).ravel(),
            (np.repeat(dof, 12, axis=1).ravel(), np.tile(dof, (1, 12)).ravel()),
        ),
        shape=(3 * n, 3 * n),
    )
    return _Out(f, K)


def _read(case, out):
    model, points, cells, x, s = case
    return edge_kinematics_findings(model, points, cells, x, out, s, DOUBLE)


def test_the_deformed_edges_stacked_as_rows_are_named(case):
    (f,) = _read(case, _engine(case, rows=True))
    assert f.code == "edge-kinematics" and "F = Ds^T Dm^-1" in f.title


def test_a_right_f_or_another_force_is_not_named(case):
    assert _read(case, _engine(case, rows=False)) == []
    assert _read(case, _engine(case, rows=True, scale=1.01)) == []
