"""The compressed-element regularisation study (paper, section 2.3).

A cube is compressed to half its height. We report (1) the number of negative eigenvalues of
the stiffness at the homogeneous half-height state, with and without regularisation, and
(2) the outcome of a static Newton solve whose linear systems are solved by Jacobi-CG: bottom
face clamped, top face pushed down to half the height in load steps, sides free.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Callable, List, Optional

import numpy as np
from scipy.sparse.linalg import norm as sparse_norm

import mjed
from mjed.solvers import conjugate_gradient

#: The regularised stiffness must stay symmetric to round-off (as the equivalence study's K).
SYMMETRY_TOL = 1e-12

__all__ = [
    "KEY",
    "TITLE",
    "RegularizationOutcome",
    "negative_eigenvalues",
    "static_compression",
    "run_study",
    "regularization_study",
]

KEY = "regularization"
TITLE = "Compressed-element regularisation (paper section 2.3)"


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
    force_change: float  # max |f_on - f_off| / max |f_off| at the homogeneous state: must be 0
    asymmetry_on: float  # ||K_on - K_on^T||_F / ||K_on||_F
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
                return SolveOutcome(
                    False,
                    f"load step {step}, Newton iteration {it}: {exc}",
                    step - 1,
                    newton_total,
                    cg_total,
                    float("nan"),
                )
            r = f.ravel()[free]
            if f_scale is None:
                f_scale = max(np.abs(K.diagonal()).max() * h, 1e-300)
            if np.linalg.norm(r) <= newton_tol * f_scale:
                break
            res = conjugate_gradient(
                K[free][:, free], r, tol=1e-10, max_iterations=cg_max_iterations
            )
            newton_total += 1
            cg_total += res.iterations
            if not res.converged:
                return SolveOutcome(
                    False,
                    f"load step {step}, Newton iteration {it}: CG stopped ({res.reason}) after "
                    f"{res.iterations} iterations, residual {res.residual:.2e}",
                    step - 1,
                    newton_total,
                    cg_total,
                    _min_J(mesh, x),
                )
            dx = np.zeros(3 * mesh.n_nodes)
            dx[free] = res.x
            x = x + dx.reshape(-1, 3)
        else:
            return SolveOutcome(
                False,
                f"load step {step}: Newton did not converge in {max_newton} iterations",
                step - 1,
                newton_total,
                cg_total,
                _min_J(mesh, x),
            )
    return SolveOutcome(True, "converged", load_steps, newton_total, cg_total, _min_J(mesh, x))


def _min_J(mesh, x) -> float:
    F = np.einsum("mai,maj->mij", x[mesh.cells], mesh.D)
    return float(np.linalg.det(F).min())


def run_study(
    mesh: mjed.TetMesh, material, *, height_ratio: float = 0.5, load_steps: int = 4
) -> RegularizationOutcome:
    """Eigenvalue counts at the homogeneous state and the two static solves."""
    X = mesh.points
    zmin = X[:, 2].min()
    x_h = X.copy()
    x_h[:, 2] = zmin + height_ratio * (X[:, 2] - zmin)
    fields = [mjed.HyperelasticForceField(mesh, material, regularize=r) for r in (False, True)]
    (f_off, K_off), (f_on, K_on) = (field_.force_and_stiffness(x_h) for field_ in fields)
    counts = [negative_eigenvalues(K) for K in (K_off, K_on)]
    force_change = float(np.abs(f_on - f_off).max() / max(np.abs(f_off).max(), 1e-300))
    asymmetry = float(sparse_norm(K_on - K_on.T) / sparse_norm(K_on))
    solves = [
        static_compression(
            mesh, material, regularize=r, height_ratio=height_ratio, load_steps=load_steps
        )
        for r in (False, True)
    ]
    return RegularizationOutcome(
        material.name,
        mesh.n_cells,
        counts[0],
        counts[1],
        solves[0],
        solves[1],
        force_change,
        asymmetry,
    )


def regularization_study(
    label: str,
    points: np.ndarray,
    cells: np.ndarray,
    materials,
    *,
    progress: Optional[Callable[[str], None]] = None,
):
    """The study on one mesh (a box; built-in cube-small by default) for every material.

    The paper states no figure to reach, so the eigenvalue counts and the solves are findings,
    shown as they are. What the study is held to is what the regularisation must never do:
    change a force (it only rewrites a stiffness term), or make K unsymmetric.

    Returns:
        A :class:`common.result.StudyResult`; ``data`` is ``{"mesh", "results"}`` with
        one :class:`RegularizationOutcome` dict per material.
    """
    import time

    from common.blocks import Paragraph, Table
    from common.reproduce import command, material_option
    from common.result import Check, StudyResult

    t0 = time.perf_counter()
    mesh = mjed.TetMesh(points, cells)
    out = []
    for m in materials:
        if progress:
            progress(m.name)
        out.append(run_study(mesh, m))
    material, comment = material_option(materials)
    cmd = command("regularization", comment=comment, material=material, mesh=label)
    checks = [
        Check(
            "forces unchanged by the regularisation (max |f_on - f_off| / max |f_off|), worst of "
            f"{len(out)} materials",
            max(o.force_change for o in out),
            0.0,
        ),
        Check(
            f"symmetry of the regularised K (relative Frobenius), worst of {len(out)} materials",
            max(o.asymmetry_on for o in out),
            SYMMETRY_TOL,
        ),
    ]
    rows = []
    for o in out:
        for tag, neg, solve in (
            ("off", o.negative_eigenvalues_off, o.solve_off),
            ("on", o.negative_eigenvalues_on, o.solve_on),
        ):
            rows.append(
                (
                    o.material,
                    tag,
                    neg,
                    "solved" if solve.converged else "failed",
                    solve.newton_iterations,
                    solve.cg_iterations,
                    solve.message if not solve.converged else "",
                )
            )
    cleared = [o.material for o in out if o.negative_eigenvalues_on == 0]
    solved_on = sum(o.solve_on.converged for o in out)
    solved_off = sum(o.solve_off.converged for o in out)
    headline = (
        f"no negative eigenvalue left with the regularisation for {len(cleared)}/{len(out)} "
        f"materials; static solve succeeds for {solved_on}/{len(out)} with it, "
        f"{solved_off}/{len(out)} without"
    )
    blocks = (
        Paragraph(
            f"The {label} mesh ({mesh.n_cells} cells) compressed to half its height: negative "
            "eigenvalues of K at the homogeneous half-height state, and a static Newton + "
            "Jacobi-CG solve in 4 load steps (bottom clamped, top pushed down, sides free), with "
            "and without the regularisation of the f''(J) term. The paper gives no figure to "
            "reach, so these outcomes are reported, not held to a target; a material whose "
            "instability does not come from a volumetric f(J) term (St Venant-Kirchhoff) keeps it."
        ),
        Table(
            (
                "material",
                "regularise",
                "negative eigenvalues",
                "static solve",
                "Newton its",
                "CG its",
                "why it failed",
            ),
            rows,
            caption=f"{label}, compressed to half its height",
        ),
    )
    return StudyResult.from_checks(
        KEY,
        TITLE,
        checks,
        headline=headline,
        command=cmd,
        data={"mesh": label, "results": [o.to_dict() for o in out]},
        blocks=blocks,
        seconds=time.perf_counter() - t0,
    )
