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
    top = np.isclose(X[:, 2], zmax, atol=1e-9 * h)
    fixed = np.zeros((mesh.n_nodes, 3), dtype=bool)
    fixed[np.isclose(X[:, 2], zmin, atol=1e-9 * h)] = True  # the bottom is clamped
    fixed[top, 2] = True  # the top is pushed down, free to slide
    newton = _Newton(
        mjed.HyperelasticForceField(mesh, material, regularize=regularize),
        ~fixed.ravel(),
        h,
        newton_tol,
        max_newton,
        cg_max_iterations,
    )
    x = X.copy()
    for step in range(1, load_steps + 1):
        # Predictor: scale the heights of all nodes like the top's, so no cell starts inverted.
        new_top = zmax - (1.0 - height_ratio) * h * step / load_steps
        old_top = x[top, 2].mean()
        x[:, 2] = zmin + (x[:, 2] - zmin) * (new_top - zmin) / (old_top - zmin)
        x[top, 2] = new_top
        x, failure, inverted = newton.solve(x)
        if failure is not None:
            # An inverted cell stops the evaluation itself: there is no J to report then.
            min_J = float("nan") if inverted else _min_J(mesh, x)
            return SolveOutcome(
                False,
                f"load step {step}{failure}",
                step - 1,
                newton.iterations,
                newton.cg_iterations,
                min_J,
            )
    return SolveOutcome(
        True, "converged", load_steps, newton.iterations, newton.cg_iterations, _min_J(mesh, x)
    )


@dataclass
class _Newton:
    """Newton's method with Jacobi-CG on the free dofs; counts its iterations across calls."""

    field: object
    free: np.ndarray
    h: float
    tol: float
    max_iterations: int
    cg_max_iterations: int
    iterations: int = 0
    cg_iterations: int = 0
    f_scale: Optional[float] = None

    def solve(self, x: np.ndarray):
        """(x, None, False) once converged, else (x, why, inverted): why continues a sentence
        naming the load step; inverted says an inverted cell stopped the evaluation.
        """
        free = self.free
        for it in range(self.max_iterations):
            try:
                f, K = self.field.force_and_stiffness(x)
            except mjed.InvertedElementError as exc:
                return x, f", Newton iteration {it}: {exc}", True
            r = f.ravel()[free]
            if self.f_scale is None:
                self.f_scale = max(np.abs(K.diagonal()).max() * self.h, 1e-300)
            if np.linalg.norm(r) <= self.tol * self.f_scale:
                return x, None, False
            res = conjugate_gradient(
                K[free][:, free], r, tol=1e-10, max_iterations=self.cg_max_iterations
            )
            self.iterations += 1
            self.cg_iterations += res.iterations
            if not res.converged:
                why = (
                    f", Newton iteration {it}: CG stopped ({res.reason}) after "
                    f"{res.iterations} iterations, residual {res.residual:.2e}"
                )
                return x, why, False
            dx = np.zeros(x.size)
            dx[free] = res.x
            x = x + dx.reshape(-1, 3)
        return x, f": Newton did not converge in {self.max_iterations} iterations", False


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

    from common.reproduce import command, material_option
    from common.result import StudyResult

    t0 = time.perf_counter()
    mesh = mjed.TetMesh(points, cells)
    out = []
    for m in materials:
        if progress:
            progress(m.name)
        out.append(run_study(mesh, m))
    material, comment = material_option(materials)
    return StudyResult.from_checks(
        KEY,
        TITLE,
        _checks(out),
        headline=_headline(out),
        command=command("regularization", comment=comment, material=material, mesh=label),
        data={"mesh": label, "results": [o.to_dict() for o in out]},
        blocks=_blocks(label, mesh, out),
        seconds=time.perf_counter() - t0,
    )


def _checks(out: List[RegularizationOutcome]) -> list:
    """What the regularisation must never do: change a force, or make K unsymmetric."""
    from common.result import Check

    return [
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


def _headline(out: List[RegularizationOutcome]) -> str:
    cleared = sum(o.negative_eigenvalues_on == 0 for o in out)
    solved_on = sum(o.solve_on.converged for o in out)
    solved_off = sum(o.solve_off.converged for o in out)
    n = len(out)
    return (
        f"no negative eigenvalue left with the regularisation for {cleared}/{n} materials; "
        f"static solve succeeds for {solved_on}/{n} with it, {solved_off}/{n} without"
    )


def _blocks(label: str, mesh, out: List[RegularizationOutcome]) -> tuple:
    from common.blocks import Paragraph, Table

    rows = []
    for o in out:
        for tag, neg, solve in (
            ("off", o.negative_eigenvalues_off, o.solve_off),
            ("on", o.negative_eigenvalues_on, o.solve_on),
        ):
            why = solve.message if not solve.converged else ""
            verdict = "solved" if solve.converged else "failed"
            rows.append(
                (o.material, tag, neg, verdict, solve.newton_iterations, solve.cg_iterations, why)
            )
    text = (
        f"The {label} mesh ({mesh.n_cells} cells) compressed to half its height: negative "
        "eigenvalues of K at the homogeneous half-height state, and a static Newton + Jacobi-CG "
        "solve in 4 load steps (bottom clamped, top pushed down, sides free), with and without "
        "the regularisation of the f''(J) term. The paper gives no figure to reach, so these "
        "outcomes are reported, not held to a target; a material whose instability does not "
        "come from a volumetric f(J) term (St Venant-Kirchhoff) keeps it."
    )
    header = (
        "material",
        "regularise",
        "negative eigenvalues",
        "static solve",
        "Newton its",
        "CG its",
        "why it failed",
    )
    return (Paragraph(text), Table(header, rows, caption=f"{label}, compressed to half its height"))
