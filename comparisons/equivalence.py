"""The equivalence harness: MJED against the UFL Galerkin oracle, case by case.

A case is one material on one mesh in one deformation state. Errors follow CONVENTIONS.md:

    force_rel_err     = ||f_mjed - f_oracle||_2 / ||f_oracle||_2
    stiffness_rel_err = ||K_mjed - K_oracle||_F / ||K_oracle||_F
    symmetry_err      = ||K_mjed - K_mjed^T||_F / ||K_mjed||_F

both in the input node order. At rest the oracle force is zero, so the force error is then
measured against the force scale ||K_oracle||_F * h (h the mean edge length): the force of an
element-sized displacement.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import partial
from typing import Callable, Iterable, Iterator, List, Optional, Sequence

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

import mjed
from comparisons.states import apply_state
from mjed.materials.base import Material

__all__ = ["FORCE_TOL", "STIFFNESS_TOL", "SYMMETRY_TOL", "CaseResult", "compare_arrays", "run_cases", "format_table"]

FORCE_TOL = 1e-10
STIFFNESS_TOL = 1e-10
SYMMETRY_TOL = 1e-12


@dataclass
class CaseResult:
    material: str
    mesh: str
    state: str
    n_cells: int
    n_nodes: int
    force_rel_err: float
    stiffness_rel_err: float
    symmetry_err: float
    passed: bool

    def to_dict(self) -> dict:
        return asdict(self)


def _mean_edge(points: np.ndarray, cells: np.ndarray) -> float:
    i, j = np.triu_indices(4, k=1)
    X = points[cells]
    return float(np.linalg.norm(X[:, i] - X[:, j], axis=2).mean())


def compare_arrays(f_m, K_m, f_o, K_o, force_scale: float) -> tuple:
    """(force_rel_err, stiffness_rel_err, symmetry_err) of MJED (f_m, K_m) against the oracle."""
    K_m = sp.csr_matrix(K_m)
    K_o = sp.csr_matrix(K_o)
    nK = sparse_norm(K_o)
    f_ref = max(float(np.linalg.norm(f_o)), force_scale * nK)
    df = float(np.linalg.norm(np.asarray(f_m) - np.asarray(f_o)))
    force_err = df / f_ref if f_ref > 0 else df
    stiff_err = float(sparse_norm(K_m - K_o)) / nK if nK > 0 else float(sparse_norm(K_m))
    nKm = sparse_norm(K_m)
    sym_err = float(sparse_norm(K_m - K_m.T)) / nKm if nKm > 0 else 0.0
    return force_err, stiff_err, sym_err


def run_cases(
    meshes: Sequence[tuple],
    materials: Sequence[Material],
    states: Sequence[str],
    *,
    oracle_factory: Optional[Callable] = None,
    progress: Optional[Callable[[str], None]] = None,
    comm=None,
) -> Iterator[CaseResult]:
    """Yield one CaseResult per (mesh, material, state).

    Args:
        meshes: (label, points (n, 3), cells (m, 4)) triples.
        materials: material instances.
        states: names from comparisons.states.
        oracle_factory: (points, cells, material) -> object with force(x), stiffness(x);
            defaults to reference_fem.UFLOracle (distributed over ``comm`` if given).
        comm: MPI communicator for an oracle distributed over several ranks. Every rank
            must call this with the same arguments (the oracle calls are collective); MJED
            and the comparison run on rank 0, which alone yields results.
    """
    root = comm is None or comm.rank == 0
    if oracle_factory is None:
        from reference_fem import UFLOracle

        oracle_factory = UFLOracle if comm is None else partial(UFLOracle, comm=comm)
    for label, points, cells in meshes:
        mesh = mjed.TetMesh(points, cells)
        h = _mean_edge(mesh.points, mesh.cells)
        # Off rank 0 the oracle reads no positions (it receives rank 0's).
        xs = {s: apply_state(s, mesh.points, mesh.cells) if root else None for s in states}
        for material in materials:
            if progress and root:
                progress(f"{label}: {material.name}")
            field = mjed.HyperelasticForceField(mesh, material) if root else None
            oracle = oracle_factory(mesh.points, mesh.cells, material)
            for state in states:
                x = xs[state]
                f_o, K_o = oracle.force(x), oracle.stiffness(x)
                if not root:
                    continue
                f_m, K_m = field.force_and_stiffness(x)
                fe, ke, se = compare_arrays(f_m, K_m, f_o, K_o, h)
                passed = fe <= FORCE_TOL and ke <= STIFFNESS_TOL and se <= SYMMETRY_TOL
                yield CaseResult(material.name, label, state, mesh.n_cells, mesh.n_nodes, fe, ke, se, bool(passed))


def format_table(results: Iterable[CaseResult]) -> str:
    """A fixed-width text table of the results."""
    rows = [("material", "mesh", "state", "cells", "nodes", "force err", "stiff err", "sym err", "")]
    for r in results:
        rows.append(
            (
                r.material, r.mesh, r.state, str(r.n_cells), str(r.n_nodes),
                f"{r.force_rel_err:.2e}", f"{r.stiffness_rel_err:.2e}", f"{r.symmetry_err:.2e}",
                "pass" if r.passed else "FAIL",
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))) for row in rows]
    lines.insert(1, "-" * len(lines[0]))
    return "\n".join(lines)
