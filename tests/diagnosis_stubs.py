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
