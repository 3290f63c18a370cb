"""Shared by the adapter tests (tests/test_adapters_*.py): the meshes and states every
third-party library is checked on, and the comparison with the UFL oracle.
"""

from __future__ import annotations

from typing import Dict, Iterator, Tuple

import numpy as np
import pytest

from common.states import apply_state, state_names

# The force scale of the equivalence study (rest state: f = 0 on both sides, so |f - f0| is
# measured against mean edge x |K|), reused so that both checks mean the same thing.
from common.tolerances import mean_edge_length as mean_edge
from comparisons.equivalence.study import compare_arrays

#: The meshes of the adapter checks (the brief: the smallest and a ~500-cell one).
ADAPTER_MESHES = ("single-tet", "cube-small")


def load_mesh(name: str) -> Tuple[np.ndarray, np.ndarray]:
    pytest.importorskip("meshio", reason="cube-small is stored as a gmsh file")
    import meshes

    return meshes.load(name)


def mesh_volume(points: np.ndarray, cells: np.ndarray) -> float:
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    return float(np.linalg.det(e).sum() / 6.0)


def errors_in_every_state(adapter, oracle, points, cells) -> Iterator[Tuple[str, Dict[str, float]]]:
    """(state, {"force", "stiffness", "energy_difference", "oracle_energy"}) for every state
    of common/states.py: relative force and stiffness errors as the equivalence study
    measures them, the library's total energy minus the oracle's (None if the adapter
    computes none) and the oracle's energy.
    """
    scale = mean_edge(points, cells)
    for state in state_names():
        x = apply_state(state, points, cells)
        f, K = adapter.force_and_stiffness(x)
        f0, K0 = oracle.force_and_stiffness(x)
        fe, ke, _ = compare_arrays(f, K, f0, K0, scale)
        energy = getattr(adapter, "energy", None)
        E0 = oracle.energy(x)
        dE = None if energy is None else energy(x) - E0
        yield state, {"force": fe, "stiffness": ke, "energy_difference": dE, "oracle_energy": E0}
