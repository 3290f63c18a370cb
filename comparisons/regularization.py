"""The compressed-element regularisation study (paper, section 2.3).

A cube is compressed to half its height. We report (1) the number of negative eigenvalues of
the stiffness at the homogeneous half-height state, with and without regularisation, and
(2) the outcome of a static Newton solve whose linear systems are solved by Jacobi-CG: bottom
face clamped, top face pushed down to half the height in load steps, sides free.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import List

import numpy as np

import mjed
from mjed.solvers import conjugate_gradient

__all__ = ["RegularizationOutcome", "negative_eigenvalues", "static_compression", "run_study"]


def negative_eigenvalues(K, *, rel_tol: float = 1e-10) -> int:
    """Number of eigenvalues of the symmetric K below -rel_tol * max |eigenvalue| (dense)."""
    w = np.linalg.eigvalsh(K.toarray() if hasattr(K, "toarray") else K)
    return int((w < -rel_tol * np.abs(w).max()).sum())


@dataclass
class SolveOutcome:
    converged: bool
    message: str
    load_steps_done: int
    newton_iterations: int
    cg_iterations: int
    min_J: float


@dataclass
class RegularizationOutcome:
    material: str
    n_cells: int
    negative_eigenvalues_off: int
    negative_eigenvalues_on: int
    solve_off: SolveOutcome
    solve_on: SolveOutcome
    notes: List[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


def static_compression(
    mesh: mjed.TetMesh,
    material,
    *,
    regularize: bool,
    height_ratio: float = 0.5,
    load_steps: int = 4,
    newton_tol: float = 1e-8,
    max_newton: int = 200,
    cg_max_iterations: int = 2000,
) -> SolveOutcome:
    """Newton + Jacobi-CG static solve of the compression; never raises on failure."""
    X = mesh.points
    zmin, zmax = X[:, 2].min(), X[:, 2].max()
    h = zmax - zmin
    bottom = np.isclose(X[:, 2], zmin, atol=1e-9 * h)
    top = np.isclose(X[:, 2], zmax, atol=1e-9 * h)
    fixed = np.zeros((mesh.n_nodes, 3), dtype=bool)
    fixed[bottom] = True
    fixed[top, 2] = True
    free = ~fixed.ravel()
    field_ = mjed.HyperelasticForceField(mesh, material, regularize=regularize)
    x = X.copy()
    newton_total = cg_total = 0
    f_scale = None
    for step in range(1, load_steps + 1):
        # Predictor: scale the heights of all nodes like the top's, so no cell starts inverted.
        new_top = zmax - (1.0 - height_ratio) * h * step / load_steps
        old_top = x[top, 2].mean()
        x[:, 2] = zmin + (x[:, 2] - zmin) * (new_top - zmin) / (old_top - zmin)
        x[top, 2] = new_top
        for it in range(max_newton):
            try:
                f, K = field_.force_and_stiffness(x)
            except mjed.InvertedElementError as exc:
                return SolveOutcome(False, f"load step {step}, Newton iteration {it}: {exc}", step - 1, newton_total, cg_total, float("nan"))
            r = f.ravel()[free]
            if f_scale is None:
                f_scale = max(np.abs(K.diagonal()).max() * h, 1e-300)
            if np.linalg.norm(r) <= newton_tol * f_scale:
                break
            res = conjugate_gradient(K[free][:, free], r, tol=1e-10, max_iterations=cg_max_iterations)
            newton_total += 1
            cg_total += res.iterations
            if not res.converged:
                return SolveOutcome(
                    False, f"load step {step}, Newton iteration {it}: CG stopped ({res.reason}) after {res.iterations} iterations, residual {res.residual:.2e}",
                    step - 1, newton_total, cg_total, _min_J(mesh, x),
                )
            dx = np.zeros(3 * mesh.n_nodes)
            dx[free] = res.x
            x = x + dx.reshape(-1, 3)
        else:
            return SolveOutcome(False, f"load step {step}: Newton did not converge in {max_newton} iterations", step - 1, newton_total, cg_total, _min_J(mesh, x))
    return SolveOutcome(True, "converged", load_steps, newton_total, cg_total, _min_J(mesh, x))


def _min_J(mesh, x) -> float:
    F = np.einsum("mai,maj->mij", x[mesh.cells], mesh.D)
    return float(np.linalg.det(F).min())


def run_study(mesh: mjed.TetMesh, material, *, height_ratio: float = 0.5, load_steps: int = 4) -> RegularizationOutcome:
    """Eigenvalue counts at the homogeneous state and the two static solves."""
    X = mesh.points
    zmin = X[:, 2].min()
    x_h = X.copy()
    x_h[:, 2] = zmin + height_ratio * (X[:, 2] - zmin)
    counts = [
        negative_eigenvalues(mjed.HyperelasticForceField(mesh, material, regularize=r).stiffness(x_h)) for r in (False, True)
    ]
    solves = [static_compression(mesh, material, regularize=r, height_ratio=height_ratio, load_steps=load_steps) for r in (False, True)]
    return RegularizationOutcome(material.name, mesh.n_cells, counts[0], counts[1], solves[0], solves[1])
