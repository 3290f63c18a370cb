"""Stand-ins for the check's case, engine output and oracle cache in the diagnosis tests that
build a mistaken engine from MJED: MJED plays the oracle (it agrees with it to round-off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from conformance.judge.oracle import Reference


@dataclass(frozen=True)
class CaseStub:
    """What a reading reads of a kit case: the mesh, the positions and the model."""

    points: np.ndarray
    cells: np.ndarray
    positions: np.ndarray
    model: object


@dataclass(frozen=True)
class OutputStub:
    """An engine's output: force (n, 3) and stiffness (3n, 3n)."""

    force: np.ndarray
    stiffness: sp.csr_matrix


class MjedCache:
    """The oracle cache with MJED evaluating every model (no energy)."""

    def reference(self, ci) -> Reference:
        return self.evaluate_once(ci, ci.model)

    def evaluate_once(self, ci, model) -> Reference:
        import mjed

        field = mjed.HyperelasticForceField(mjed.TetMesh(ci.points, ci.cells), model)
        f, K = field.force_and_stiffness(ci.positions)
        return Reference(0.0, np.asarray(f), sp.csr_matrix(K))


def mjed_cell_stress(points, cells, x, model) -> np.ndarray:
    """(m, 3, 3) per-cell S read back from MJED's element forces (f_a = -V0 F S D_a)."""
    import mjed
    from mjed.mesh import shape_vectors

    field = mjed.make_force_field(mjed.TetMesh(points, cells), model)
    fe = np.asarray(field.element_forces(x))
    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    P = -np.einsum("mja,mak->mkj", np.linalg.pinv(D), fe) / np.abs(V0)[:, None, None]
    return np.linalg.inv(F) @ P


def classical_cells(points, cells, x, model):
    """(f_o, K_o, V0, D, F, J, tau_of) for engines built in the tests: MJED's force and
    stiffness, the cells' rest volumes V0 (signed as MJED's), shape gradients D, F and J, and
    tau_of(Fs) the Kirchhoff stress of the project's classical law at per-cell gradients Fs.
    """
    import mjed
    from mjed.mesh import shape_vectors
    from reference_fem.classical import ClassicalGalerkin

    law = ClassicalGalerkin(points, cells, model).law
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f_o, K_o = field.force_and_stiffness(x)
    V0, D = shape_vectors(points, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)

    def tau_of(Fs):
        Cs = Fs.swapaxes(1, 2) @ Fs
        return Fs @ law.stress(Cs, np.linalg.det(Fs)) @ Fs.swapaxes(1, 2)

    return f_o, K_o, V0, D, F, np.linalg.det(F), tau_of


def cell_gradients(points, cells, x):
    """(V0, D, F, J) per cell of a linear tet mesh: rest volumes (m,), shape gradients
    dN_a/dX (m, 4, 3), deformation gradients and their determinants at positions x.
    """
    X = points[cells]
    Mt = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)
    Minv = np.linalg.inv(Mt)
    D = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)
    F = np.einsum("mai,maj->mij", x[cells], D)
    return np.abs(np.linalg.det(Mt)) / 6.0, D, F, np.linalg.det(F)
