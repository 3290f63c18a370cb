"""The equivalence harness: MJED against the UFL Galerkin oracle, case by case.

A case is one material on one mesh in one deformation state. The errors are::

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
from typing import Callable, Iterator, List, Optional, Sequence

import mjed
from common.frames import with_default_frame
from common.states import apply_state
from common.tolerances import (
    FORCE_TOL,
    STIFFNESS_TOL,
    SYMMETRY_TOL,
    compare_arrays,
    mean_edge_length,
)
from mjed.materials.base import Material

__all__ = [
    "KEY",
    "TITLE",
    "CaseResult",
    "compare_arrays",
    "run_cases",
    "equivalence_command",
    "equivalence_study",
]

KEY = "equivalence"
TITLE = "Equivalence: MJED against the UFL oracle"


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


def _tet_meshes(meshes: Sequence[tuple]) -> List[tuple]:
    """(label, mjed.TetMesh) pairs: triples are validated into a TetMesh, pairs kept as given."""
    return [m if len(m) == 2 else (m[0], mjed.TetMesh(m[1], m[2])) for m in meshes]


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
        meshes: (label, points (n, 3), cells (m, 4)) triples, or (label, mjed.TetMesh) pairs
            (already validated: the study builds each mesh once and passes it on).
        materials: material instances. A material that needs a fibre frame and has none
            (Costa) gets the mesh's helical field (:func:`common.frames.with_default_frame`),
            the frames the conformance kit exports: MJED is held to what the kit asks of other
            engines.
        states: names from common.states.
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
    for label, mesh in _tet_meshes(meshes):
        h = mean_edge_length(mesh.points, mesh.cells)
        # Off rank 0 the oracle reads no positions (it receives rank 0's).
        xs = {s: apply_state(s, mesh.points, mesh.cells) if root else None for s in states}
        for given in materials:
            material = with_default_frame(given, mesh.points, mesh.cells)
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
                yield CaseResult(
                    material.name,
                    label,
                    state,
                    mesh.n_cells,
                    mesh.n_nodes,
                    fe,
                    ke,
                    se,
                    bool(passed),
                )


def equivalence_command(
    labels: Sequence[str],
    materials: Sequence[Material],
    states: Sequence[str],
    *,
    mpi_ranks: int = 1,
) -> str:
    """The command line that re-runs this selection (under mpirun when the oracle was
    distributed).
    """
    from common.reproduce import command, material_option, mesh_option, states_option

    material, comment = material_option(materials)
    prefix = ("mpirun", "-n", str(mpi_ranks)) if mpi_ranks > 1 else ()
    return command(
        "equivalence",
        prefix=prefix,
        comment=comment,
        material=material,
        mesh=mesh_option(labels),
        states=states_option(states),
    )


def _worst(values: Sequence[float]) -> Optional[float]:
    """The largest value, NaN if any is NaN (a NaN must fail, whatever its place), None if empty."""
    values = [float(v) for v in values]
    if not values:
        return None
    return float("nan") if any(v != v for v in values) else max(values)


def _box_meshes(meshes: Sequence[tuple]) -> List[tuple]:
    """The built-in cubes among the selected (label, TetMesh) pairs (axis-aligned boxes);
    cube-small if none.
    """
    import meshes as catalog

    cubes = [m for m in meshes if m[0] in catalog.names() and m[0].startswith("cube")]
    if cubes:
        return cubes
    points, cells, label = catalog.resolve("cube-small")
    return [(label, mjed.TetMesh(points, cells))]


#: Ogden exponents of the SOFA-tangent table beside the selected one: 2 (g = c I1, where the
#: coaxial tangent is exact: a control row) and the two ends of the usual soft-tissue range.
OGDEN_TANGENT_ALPHAS = (-2.0, 2.0, 6.0)


def _ogden_tangent(
    meshes: Sequence[tuple], materials: Sequence[Material], states: Sequence[str]
) -> dict:
    """{mesh label: {"alpha A": {state: ||K_sofa - K_exact||_F / ||K_exact||_F}}} for the first
    Ogden selected, at its own alpha and at OGDEN_TANGENT_ALPHAS; meshes: (label, TetMesh).
    """
    from dataclasses import replace

    from comparisons.equivalence.ogden_tangent import sofa_tangent_errors

    ogden = next((m for m in materials if isinstance(m, mjed.materials.Ogden)), None)
    if ogden is None:
        return {}
    alphas = list(dict.fromkeys((float(ogden.alpha), *OGDEN_TANGENT_ALPHAS)))
    return {
        label: {
            f"alpha {a:g}": sofa_tangent_errors(mesh, replace(ogden, alpha=a), states)
            for a in alphas
        }
        for label, mesh in meshes
    }


def _ogden_tangent_findings(tangent: dict) -> str:
    """What the SOFA-tangent table shows, in words, from its figures."""
    worst: dict = {}
    for rows in tangent.values():
        for alpha, errs in rows.items():
            worst[alpha] = max([worst.get(alpha, 0.0), *errs.values()])
    spread = ", ".join(f"{v:.1e} at {a}" for a, v in worst.items())
    return (
        "Not a pass/fail check: SOFA's MJED Ogden approximates the tangent; the forces are "
        "identical. The approximation is exact where C commutes with the perturbation (at rest) "
        "and where the power is linear (alpha 2, a control row), and not elsewhere. Largest error "
        f"over the states: {spread}. An inexact tangent slows Newton from quadratic to linear "
        "convergence; it does not change a converged answer."
    )


@dataclass(frozen=True)
class EquivalenceMeasurements:
    """What one equivalence run measured: the cases, the uniaxial rows and the Ogden table."""

    cases: List[CaseResult]
    uniaxial: List[dict]
    boxes: List[str]
    tangent: dict

    def to_dict(self) -> dict:
        return {
            "cases": [c.to_dict() for c in self.cases],
            "uniaxial_closed_form": self.uniaxial,
            "ogden_sofa_tangent_error": self.tangent,
        }


_NO_DOLFINX = (
    "the UFL oracle needs dolfinx, which is not installed (Debian: apt install "
    "python3-dolfinx; or make bootstrap)"
)


def _dolfinx_available() -> bool:
    from reference_fem import dolfinx_available

    return dolfinx_available()


def equivalence_study(
    meshes: Sequence[tuple],
    materials: Sequence[Material],
    states: Sequence[str],
    *,
    quick: bool = False,
    progress: Optional[Callable[[str], None]] = None,
    comm=None,
    oracle_factory: Optional[Callable] = None,
):
    """The equivalence study: every case against the oracle, the uniaxial closed form, and
    SOFA's approximate Ogden tangent against the exact one.

    Args:
        meshes, materials, states: as for :func:`run_cases`; mesh labels are names or paths
            as the user gave them (they go into the reproduce line).
        quick: the meshes are the quick set; the result says cube-paper was left out.
        comm: MPI communicator distributing the oracle (collective on every rank).

    Returns:
        A :class:`common.result.StudyResult` on rank 0 (None on the other ranks); NOT_RUN
        when dolfinx is missing. Checks: the worst force, stiffness and symmetry errors over
        all cases and the worst uniaxial closed-form errors, each against its tolerance.
        ``data`` holds ``cases``, ``uniaxial_closed_form`` and ``ogden_sofa_tangent_error``.
    """
    import time

    from common.result import StudyResult

    labels = [m[0] for m in meshes]
    cmd = equivalence_command(labels, materials, states, mpi_ranks=1 if comm is None else comm.size)
    if oracle_factory is None and not _dolfinx_available():
        return StudyResult.not_run(KEY, TITLE, _NO_DOLFINX, cmd)
    t0 = time.perf_counter()
    tet_meshes = _tet_meshes(meshes)  # each mesh validated once, then shared by every part
    measured = _measure(tet_meshes, materials, states, oracle_factory, progress, comm)
    if measured is None:
        return None
    not_covered = []
    if quick and "cube-paper" not in labels:
        not_covered.append(f"quick: {', '.join(labels)} instead of the paper's cube (cube-paper)")
    data = measured.to_dict()
    if comm is not None:
        data["mpi_ranks"] = comm.size
    return StudyResult.from_checks(
        KEY,
        TITLE,
        _equivalence_checks(measured),
        headline=_headline(measured, comm),
        command=cmd,
        reason=_failure_reason(measured),
        not_covered=tuple(not_covered),
        data=data,
        blocks=tuple(_blocks(measured, states)),
        seconds=time.perf_counter() - t0,
    )


def _measure(meshes, materials, states, oracle_factory, progress, comm):
    """Run every case, then (rank 0 only) the uniaxial closed form and the Ogden table."""
    from comparisons.equivalence.closed_form import uniaxial_checks

    cases = list(
        run_cases(
            meshes, materials, states, oracle_factory=oracle_factory, progress=progress, comm=comm
        )
    )
    if comm is not None and comm.rank != 0:
        return None
    if progress:
        progress("uniaxial closed form")
    boxes = _box_meshes(meshes)
    uniaxial = [
        row
        for label, mesh in boxes
        for row in uniaxial_checks(materials, label, mesh.points, mesh.cells)
    ]
    if progress:
        progress("Ogden: SOFA's tangent against the exact one")
    return EquivalenceMeasurements(
        cases, uniaxial, [b[0] for b in boxes], _ogden_tangent(meshes, materials, states)
    )


def _where(c: CaseResult) -> str:
    return f"{c.material} on {c.mesh}, {c.state}"


def _equivalence_checks(m: EquivalenceMeasurements) -> list:
    """The worst error of each kind over all cases and over the uniaxial rows."""
    from common.result import Check

    cases, uniaxial, n = m.cases, m.uniaxial, len(m.cases)
    checks = []
    for attr, tol, what in (
        ("force_rel_err", FORCE_TOL, "force"),
        ("stiffness_rel_err", STIFFNESS_TOL, "stiffness"),
        ("symmetry_err", SYMMETRY_TOL, "symmetry of K"),
    ):
        # NaN sorts first, so a NaN case is the one named.
        worst = max(
            cases,
            key=lambda c: (getattr(c, attr) != getattr(c, attr), getattr(c, attr)),
            default=None,
        )
        checks.append(
            Check(
                f"{what} relative error, worst of {n} cases"
                + (f" ({_where(worst)})" if worst else ""),
                _worst([getattr(c, attr) for c in cases]),
                tol,
                note="" if cases else "no case ran",
            )
        )
    for key, what in (
        ("rel_err", "sigma_11 relative error"),
        ("lateral_reaction_rel", "side reaction / sigma_11"),
    ):
        checks.append(
            Check(
                f"uniaxial closed form: {what}, worst of {len(uniaxial)}",
                _worst([u[key] for u in uniaxial]),
                FORCE_TOL,
                note="" if uniaxial else "no selected material has a closed form",
            )
        )
    return checks


def _failure_reason(m: EquivalenceMeasurements) -> str:
    bad_cases = [c for c in m.cases if not c.passed]
    bad_uniaxial = [u for u in m.uniaxial if not u["passed"]]
    parts = []
    if bad_cases:
        parts.append(
            f"{len(bad_cases)} of {len(m.cases)} cases outside the tolerances (first: "
            f"{_where(bad_cases[0])})"
        )
    if bad_uniaxial:
        u = bad_uniaxial[0]
        parts.append(
            f"{len(bad_uniaxial)} of {len(m.uniaxial)} uniaxial checks off (first: {u['material']} "
            f"at stretch {u['stretch']:g} on {u['mesh']})"
        )
    return "; ".join(parts)


def _headline(m: EquivalenceMeasurements, comm) -> str:
    cases, uniaxial = m.cases, m.uniaxial
    passed = sum(c.passed for c in cases)
    headline = f"{passed}/{len(cases)} cases pass"
    if cases:
        headline += (
            f"; worst force error {_worst([c.force_rel_err for c in cases]):.1e}, stiffness "
            f"{_worst([c.stiffness_rel_err for c in cases]):.1e}"
        )
    if comm is not None:
        headline += f" (oracle on {comm.size} MPI ranks)"
    if uniaxial:
        good = sum(u["passed"] for u in uniaxial)
        headline += (
            f"; uniaxial closed form {good}/{len(uniaxial)}, worst "
            f"{_worst([u['rel_err'] for u in uniaxial]):.1e}"
        )
    return headline


def _blocks(m: EquivalenceMeasurements, states: Sequence[str]) -> list:
    """The report section: the digest, every case, the uniaxial table and the Ogden table."""
    from common.blocks import Paragraph, Table

    blocks = [
        Paragraph(
            "Every material on every mesh and deformation state: nodal forces and tangent "
            "stiffness of MJED against the UFL Galerkin oracle (relative errors; tolerances 1e-10 "
            "for force and stiffness, 1e-12 for the symmetry of MJED's K), then the uniaxial "
            "closed form and SOFA's approximate Ogden tangent. Costa is given the mesh's helical "
            "fibre field, one frame per cell, as a conformance kit gives it to other engines."
        ),
        _digest(m.cases),
        Table(
            (
                "material",
                "mesh",
                "state",
                "cells",
                "force error",
                "stiffness error",
                "symmetry",
                "verdict",
            ),
            [
                (
                    c.material,
                    c.mesh,
                    c.state,
                    c.n_cells,
                    c.force_rel_err,
                    c.stiffness_rel_err,
                    c.symmetry_err,
                    c.passed,
                )
                for c in m.cases
            ],
            caption="Every case",
        ),
    ]
    if m.uniaxial:
        blocks += _uniaxial_blocks(m)
    if m.tangent:
        rows = [
            (label, alpha, *(errs[s] for s in states))
            for label, rows in m.tangent.items()
            for alpha, errs in rows.items()
        ]
        blocks += [
            Table(
                ("mesh", "Ogden alpha", *states),
                rows,
                caption="Ogden: ||K_sofa - K_exact||_F / ||K_exact||_F, SOFA's coaxial tangent "
                "against the exact Hessian",
            ),
            Paragraph(_ogden_tangent_findings(m.tangent)),
        ]
    return blocks


def _uniaxial_blocks(m: EquivalenceMeasurements) -> list:
    from common.blocks import Paragraph, Table
    from comparisons.equivalence.closed_form import UNIAXIAL_STRETCHES

    text = (
        f"Uniaxial stress closed form on {', '.join(m.boxes)} at stretches "
        f"{', '.join(f'{s:g}' for s in UNIAXIAL_STRETCHES)}: the cube is given the homogeneous "
        "stretch that frees its sides (lateral stretch from the analytic principal Cauchy "
        "stresses of our compressible energies); MJED's reaction on the loaded face over the "
        "current area must equal the analytic sigma_11 to 1e-10, with no reaction on the sides. "
        "Materials without a closed form (Costa, anisotropic) are not in this table."
    )
    rows = [
        (
            u["material"],
            u["mesh"],
            u["stretch"],
            u["lateral_stretch"],
            u["sigma_analytic"],
            u["sigma_mjed"],
            u["rel_err"],
            u["lateral_reaction_rel"],
            u["passed"],
        )
        for u in m.uniaxial
    ]
    return [
        Paragraph(text),
        Table(
            (
                "material",
                "mesh",
                "stretch",
                "lateral stretch",
                "sigma analytic (Pa)",
                "sigma MJED (Pa)",
                "rel. error",
                "side reaction",
                "verdict",
            ),
            rows,
        ),
    ]


def _digest(cases: Sequence[CaseResult]):
    """Worst errors per material and mesh, over the states (the full table follows it)."""
    from common.blocks import Table

    rows = []
    for material, mesh in dict.fromkeys((c.material, c.mesh) for c in cases):
        cs = [c for c in cases if c.material == material and c.mesh == mesh]
        rows.append(
            (
                material,
                mesh,
                cs[0].n_cells,
                len(cs),
                _worst([c.force_rel_err for c in cs]),
                _worst([c.stiffness_rel_err for c in cs]),
                all(c.passed for c in cs),
            )
        )
    return Table(
        (
            "material",
            "mesh",
            "cells",
            "states",
            "worst force error",
            "worst stiffness error",
            "verdict",
        ),
        rows,
        caption="Worst relative errors over the states, per material and mesh",
    )
