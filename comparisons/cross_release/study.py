"""Does the UFL oracle give the same numbers on every dolfinx release and process count?

A *snapshot* is the oracle's energy, force and stiffness for a fixed set of cases (materials
on ``cube-small`` in deformed states, including a Costa material with one fibre frame per
cell, which exercises the cell-wise data across ranks), computed by one interpreter on a given
number of MPI ranks. The *check* takes snapshots on several stacks (Debian's dolfinx 0.5.2 in
``.venv``, the PyPI wheel in ``.venv-modern``), each serial and on 2 ranks, and compares
every one with the first:

    energy:    |E_a - E_b| / |E_a|
    force:     ||f_a - f_b||_2 / ||f_a||_2
    stiffness: ||K_a - K_b||_F / ||K_a||_F

all in the input numbering; they must be <= 1e-12 (the oracles differ only by summation
order, so about 1e-15 is expected). A stack whose interpreter is absent is listed under
``missing`` with the reason, never silently dropped.

Command line (also run by ``.ci/run``)::

    python -m comparisons.cross_release check [--quick] [--json PATH]
    mpirun -n 2 python -m comparisons.cross_release snapshot --out PATH [--quick]
    python -m comparisons.cross_release compare A.npz B.npz
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg  # noqa: F401  (sp.linalg.norm)

from comparisons.cross_release.records import (
    CrossReleaseResult,
    MissingStack,
    SnapshotDiff,
    StackComparison,
    StackError,
    StackRun,
)

__all__ = [
    "TOLERANCE",
    "snapshot_cases",
    "take_snapshot",
    "save_snapshot",
    "load_snapshot",
    "compare_snapshots",
    "mpirun_command",
    "default_stacks",
    "cross_release_check",
    "CrossReleaseResult",
    "SnapshotDiff",
    "format_check",
    "provenance_summary",
    "cross_release_study",
]

KEY = "cross_release"
TITLE = "The oracle across dolfinx releases and MPI ranks"

TOLERANCE = 1e-12
REPO = Path(__file__).resolve().parents[2]  # comparisons/cross_release/study.py -> the repository
MESH = "cube-small"


def snapshot_cases(quick: bool) -> List[Tuple[str, object, str]]:
    """(case name, material, state) triples; ``quick`` keeps three materials and one state."""
    from common.cases import DEFAULT_MATERIALS
    from mjed import materials as M

    names = ["NeoHookean", "Ogden"] if quick else list(DEFAULT_MATERIALS)
    states = ["random"] if quick else ["random", "triaxial"]
    mats = [(n, DEFAULT_MATERIALS[n]) for n in names]
    # Costa with a seeded rotation per cell: the per-cell data must follow the partition.
    costa = DEFAULT_MATERIALS["Costa"]
    mats.append(("CostaCellFrames", M.Costa(**{**_fields(costa), "frame": _cell_frames()})))
    return [(f"{n}/{s}", mat, s) for n, mat in mats for s in states]


def _fields(material) -> dict:
    import dataclasses

    return {f.name: getattr(material, f.name) for f in dataclasses.fields(material) if f.init}


def _cell_frames() -> np.ndarray:
    """(m, 3, 3) seeded random rotations, one per cell of the snapshot mesh."""
    import meshes

    _, cells = meshes.load(MESH)
    q = np.random.default_rng(7).standard_normal((cells.shape[0], 3, 3))
    Q, R = np.linalg.qr(q)
    return Q * np.sign(np.diagonal(R, axis1=1, axis2=2))[:, None, :]


def take_snapshot(*, quick: bool = True, comm=None) -> Optional[dict]:
    """The oracle's results for :func:`snapshot_cases` on ``comm`` (collective).

    Returns, on rank 0: {"meta": {versions, mpi_ranks, cells_per_rank, mesh, quick},
    "cases": {name: {"energy": float, "force": (n, 3), "stiffness": CSR (3n, 3n)}}};
    None on the other ranks.
    """
    import meshes
    from common.states import apply_state
    from reference_fem import UFLOracle, compat

    comm = compat.comm_world() if comm is None else comm
    root = comm.rank == 0
    points, cells = meshes.load(MESH)
    out: Dict[str, dict] = {}
    cells_per_rank = None
    for i, (name, material, state) in enumerate(snapshot_cases(quick)):
        oracle = UFLOracle(points, cells, material, comm=comm)
        if i == 0:  # the partition is the same for every case
            cells_per_rank = comm.gather(int(oracle.numbering.input_cell_of_cell.size), root=0)
        x = apply_state(state, points, cells) if root else None
        energy = oracle.energy(x)
        force, K = oracle.force_and_stiffness(x)
        if root:
            out[name] = {"energy": energy, "force": force, "stiffness": K}
    if not root:
        return None
    meta = {
        "versions": compat.stack_versions(),
        "mpi_ranks": comm.size,
        "cells_per_rank": cells_per_rank,
        "mesh": MESH,
        "quick": quick,
    }
    return {"meta": meta, "cases": out}


def save_snapshot(path: str, snap: dict) -> None:
    """Write a snapshot as .npz (the metadata as a JSON string)."""
    arrays = {"meta": np.array(json.dumps(snap["meta"]))}
    for i, (name, case) in enumerate(snap["cases"].items()):
        K = sp.csr_matrix(case["stiffness"])
        arrays.update(
            {
                f"c{i}_name": np.array(name),
                f"c{i}_energy": np.array(case["energy"]),
                f"c{i}_force": case["force"],
                f"c{i}_K_data": K.data,
                f"c{i}_K_indices": K.indices,
                f"c{i}_K_indptr": K.indptr,
                f"c{i}_K_shape": np.array(K.shape),
            }
        )
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez(path, **arrays)


def load_snapshot(path: str) -> dict:
    """Inverse of :func:`save_snapshot`."""
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        cases = {}
        i = 0
        while f"c{i}_name" in z:
            K = sp.csr_matrix(
                (z[f"c{i}_K_data"], z[f"c{i}_K_indices"], z[f"c{i}_K_indptr"]),
                shape=tuple(z[f"c{i}_K_shape"]),
            )
            cases[str(z[f"c{i}_name"])] = {
                "energy": float(z[f"c{i}_energy"]),
                "force": z[f"c{i}_force"],
                "stiffness": K,
            }
            i += 1
    return {"meta": meta, "cases": cases}


def _rel(diff: float, ref: float) -> float:
    return diff / ref if ref > 0 else diff


def compare_snapshots(a: dict, b: dict, tol: float = TOLERANCE) -> SnapshotDiff:
    """Worst relative differences of snapshot ``b`` from the reference ``a``, per quantity.

    Raises:
        ValueError: if the two snapshots do not hold the same cases.
    """
    if set(a["cases"]) != set(b["cases"]):
        raise ValueError(
            f"snapshots hold different cases: {sorted(a['cases'])} vs {sorted(b['cases'])}"
        )
    worst = {"energy": 0.0, "force": 0.0, "stiffness": 0.0}
    for name, ca in a["cases"].items():
        cb = b["cases"][name]
        worst["energy"] = max(
            worst["energy"], _rel(abs(ca["energy"] - cb["energy"]), abs(ca["energy"]))
        )
        worst["force"] = max(
            worst["force"],
            _rel(
                float(np.linalg.norm(ca["force"] - cb["force"])), float(np.linalg.norm(ca["force"]))
            ),
        )
        dK = sp.linalg.norm(ca["stiffness"] - cb["stiffness"])
        worst["stiffness"] = max(
            worst["stiffness"], _rel(float(dK), float(sp.linalg.norm(ca["stiffness"])))
        )
    return SnapshotDiff(
        n_cases=len(a["cases"]),
        **{f"{k}_rel_diff": v for k, v in worst.items()},
        passed=bool(max(worst.values()) <= tol),
    )


# -- running snapshots on other interpreters and under mpirun ------------------------------
def mpirun_command(python: str, ranks: int) -> Tuple[List[str], Dict[str, str]]:
    """The launcher (argv prefix, extra environment) for ``ranks`` processes of ``python``.

    An interpreter whose directory holds its own ``mpirun`` (the PyPI wheel's MPICH in
    ``.venv-modern``) must use that one: its mpi4py speaks MPICH's launch protocol. Other
    interpreters use the ``mpirun`` on PATH (Debian: Open MPI), which refuses to run as root
    and to start more processes than it counts slots unless told so.

    Raises:
        FileNotFoundError: if no mpirun is found.
    """
    own = Path(python).parent / "mpirun"
    launcher = str(own) if own.exists() else shutil.which("mpirun")
    if launcher is None:
        raise FileNotFoundError("no mpirun on PATH (Debian: apt install openmpi-bin)")
    argv, env = [launcher, "-n", str(ranks)], {}
    version = subprocess.run([launcher, "--version"], capture_output=True, text=True).stdout
    if "Open MPI" in version or "OpenRTE" in version:
        argv.append("--oversubscribe")
        if hasattr(os, "geteuid") and os.geteuid() == 0:
            env = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    return argv, env


def default_stacks() -> List[Tuple[str, str, int]]:
    """(label, interpreter, ranks): each venv of this checkout, serial and on 2 ranks."""
    stacks = []
    for label, venv in (("debian", ".venv"), ("modern", ".venv-modern")):
        python = str(REPO / venv / "bin" / "python")
        stacks += [(f"{label}-serial", python, 1), (f"{label}-mpi2", python, 2)]
    return stacks


def _run_snapshot(python: str, ranks: int, out: str, quick: bool, timeout: float) -> None:
    argv = [python, "-m", "comparisons.cross_release", "snapshot", "--out", out] + (
        ["--quick"] if quick else []
    )
    env = dict(os.environ)
    if ranks > 1:
        prefix, extra = mpirun_command(python, ranks)
        argv = prefix + argv
        env.update(extra)
    proc = subprocess.run(
        argv, cwd=str(REPO), env=env, capture_output=True, text=True, timeout=timeout
    )
    if proc.returncode != 0:
        tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-8:])
        raise RuntimeError(f"snapshot failed (exit {proc.returncode}): {' '.join(argv)}\n{tail}")


def _why_missing(python: str, timeout: float) -> Optional[str]:
    """Why the stack of ``python`` is not installed here, or None if it is (interpreter and
    dolfinx).

    A stack without dolfinx is not installed, not broken: it is listed as missing, like an
    absent interpreter. Any other failure is left to the snapshot, which reports it as an error.
    """
    if not Path(python).exists():
        return f"{python} does not exist"
    probe = (
        "import sys; from reference_fem import dolfinx_available; sys.exit(0 if "
        "dolfinx_available() else 3)"
    )
    try:
        rc = subprocess.run(
            [python, "-c", probe], cwd=str(REPO), capture_output=True, timeout=timeout
        ).returncode
    except (OSError, subprocess.TimeoutExpired):
        return None
    return f"dolfinx cannot be imported by {python}" if rc == 3 else None


def cross_release_check(
    stacks: Optional[Sequence[Tuple[str, str, int]]] = None,
    *,
    quick: bool = True,
    timeout: float = 900.0,
) -> CrossReleaseResult:
    """Snapshots on every available stack, each compared with the first that ran.

    Returns:
        The stacks that ran (versions, cells per rank, seconds), their comparisons with the
        first, the stacks missing here and those that failed; its ``passed`` is False if any
        comparison fails, if a stack that exists fails to run, or if fewer than two snapshots
        could be taken. A stack whose interpreter is absent or cannot import dolfinx is listed
        under ``missing`` (not installed), not as an error. ``to_dict()`` gives the JSON.
    """
    stacks = list(default_stacks() if stacks is None else stacks)
    with tempfile.TemporaryDirectory() as tmp:
        runs = _snapshots(stacks, tmp, quick, timeout)
    reference, comparisons = None, []
    if runs.snapshots:
        reference, ref = runs.snapshots[0]
        comparisons = [
            StackComparison(label, compare_snapshots(ref, snap))
            for label, snap in runs.snapshots[1:]
        ]
    return CrossReleaseResult(
        tolerance=TOLERANCE,
        reference=reference,
        stacks=tuple(runs.ran),
        comparisons=tuple(comparisons),
        missing=tuple(runs.missing),
        errors=tuple(runs.errors),
    )


@dataclass
class _Runs:
    """What the snapshot loop found: the stacks that ran with their snapshots, the others."""

    ran: List[StackRun] = field(default_factory=list)
    snapshots: List[Tuple[str, dict]] = field(default_factory=list)
    missing: List[MissingStack] = field(default_factory=list)
    errors: List[StackError] = field(default_factory=list)


def _snapshots(stacks, tmp: str, quick: bool, timeout: float) -> _Runs:
    """The snapshot of every stack that runs; the missing and the failed stacks, listed."""
    runs = _Runs()
    missing: Dict[str, Optional[str]] = {}
    for i, (label, python, ranks) in enumerate(stacks):
        if python not in missing:
            missing[python] = _why_missing(python, timeout)
        if missing[python]:
            runs.missing.append(MissingStack(label, missing[python]))
            continue
        out = os.path.join(tmp, f"{i}.npz")
        t0 = time.perf_counter()
        try:
            _run_snapshot(python, ranks, out, quick, timeout)
        except (RuntimeError, FileNotFoundError, subprocess.TimeoutExpired) as exc:
            runs.errors.append(StackError(label, str(exc)))
            continue
        snap = load_snapshot(out)
        meta = snap["meta"]
        runs.ran.append(
            StackRun(
                label=label,
                python=python,
                ranks=ranks,
                versions=meta["versions"],
                cells_per_rank=meta["cells_per_rank"],
                seconds=round(time.perf_counter() - t0, 1),
            )
        )
        runs.snapshots.append((label, snap))
    return runs


def format_check(result: CrossReleaseResult) -> str:
    """A few lines of text for the check's result."""
    lines = []
    for s in result.stacks:
        v = s.versions
        lines.append(
            f"  {s.label:<14} dolfinx {v['dolfinx']:<13} ufl {v['ufl']:<10} petsc "
            f"{v['petsc']:<7} numpy {v['numpy']:<7} cells per rank {list(s.cells_per_rank)} "
            f"({s.seconds} s)"
        )
    for c in result.comparisons:
        d = c.diff
        lines.append(
            f"  {c.label} vs {result.reference}: energy {d.energy_rel_diff:.1e}, force "
            f"{d.force_rel_diff:.1e}, stiffness {d.stiffness_rel_diff:.1e} "
            f"({'pass' if d.passed else 'FAIL'}, tolerance {result.tolerance:g})"
        )
    for m in result.missing:
        lines.append(f"  NOT RUN: {m.label}: {m.reason}")
    for e in result.errors:
        lines.append(f"  ERROR: {e.label}: {e.error}")
    return "\n".join(lines)


def provenance_summary(path: Optional[str] = None) -> Optional[dict]:
    """The last check's verdict and stack versions, compact, for a report's provenance section.

    Reads the JSON that ``.ci/run`` and ``make cross-release`` write (default
    ``reports/cross_release.json``); None if there is none (the check was not run here).

    Raises:
        common.json_fields.RecordError: the file is not a check's result (names the file and
            the key).
    """
    path = str(REPO / "reports" / "cross_release.json") if path is None else path
    if not os.path.exists(path):
        return None
    with open(path) as fh:
        result = CrossReleaseResult.from_dict(json.load(fh), source=path)
    keys = ("dolfinx", "ufl", "petsc", "numpy", "python", "mpi")
    return {
        "passed": result.passed,
        "tolerance": result.tolerance,
        "reference": result.reference,
        "stacks": [
            {"label": s.label, "ranks": s.ranks, **{k: s.versions.get(k) for k in keys}}
            for s in result.stacks
        ],
        "worst_rel_diff": {c.label: c.diff.worst for c in result.comparisons},
        "not_run": list(result.not_run),
    }


def cross_release_study(
    *, quick: bool = False, stacks: Optional[Sequence[Tuple[str, str, int]]] = None, progress=None
):
    """The check as a typed result.

    Every comparison contributes its energy, force and stiffness differences as tolerance
    checks (TOLERANCE), and a stack that exists but fails to run is a failed check. A stack
    that is not installed here is listed under not_covered (a partial run); with fewer than two
    snapshots nothing is compared and the study is NOT RUN. ``quick`` keeps three cases; the
    result says so. ``data`` is the JSON form (``to_dict()``) of :func:`cross_release_check`'s
    :class:`CrossReleaseResult`.
    """
    from common.reproduce import command
    from common.result import StudyResult

    t0 = time.perf_counter()
    if progress:
        progress("snapshots on every stack (subprocesses)")
    res = cross_release_check(stacks, quick=quick)
    cmd = command("cross-release", quick=quick)
    not_covered = _left_out(res, quick)
    blocks = _blocks(res)
    seconds = time.perf_counter() - t0
    if len(res.stacks) < 2 and not res.errors:
        ran = ", ".join(s.label for s in res.stacks) or "none"
        missing = "; ".join(not_covered[: len(res.missing)]) or "no stack given"
        why = f"fewer than two stacks ran (ran: {ran}), nothing was compared; {missing}"
        return replace(
            StudyResult.not_run(KEY, TITLE, why, cmd),
            data=res.to_dict(),
            blocks=blocks,
            seconds=seconds,
        )
    return StudyResult.from_checks(
        KEY,
        TITLE,
        _checks(res),
        headline=_headline(res),
        command=cmd,
        not_covered=tuple(not_covered),
        data=res.to_dict(),
        blocks=blocks,
        seconds=seconds,
    )


def _left_out(res: CrossReleaseResult, quick: bool) -> List[str]:
    """The stacks not installed here, and the quick selection, in words."""
    out = [
        f"{m.label}: not installed here ({m.reason}; make bootstrap-modern installs the "
        "modern stack)"
        for m in res.missing
    ]
    if quick:
        n_quick, n_full = len(snapshot_cases(True)), len(snapshot_cases(False))
        out.append(f"quick: {n_quick} oracle cases instead of {n_full} (all materials, two states)")
    return out


def _blocks(res: CrossReleaseResult) -> tuple:
    from common.blocks import Paragraph, Preformatted, Table

    versions = ("dolfinx", "ufl", "petsc", "numpy", "python")
    stacks = [
        (s.label, s.ranks, *(s.versions.get(v) for v in versions), s.seconds) for s in res.stacks
    ]
    diffs = [
        (c.label, *(value for _, value in c.diff.by_quantity()), c.diff.passed)
        for c in res.comparisons
    ]
    return (
        Paragraph(
            f"The same oracle cases ({MESH}, deformed states, including Costa with one fibre frame "
            "per cell) on Debian's dolfinx and a current dolfinx, serially and on 2 MPI ranks, "
            "compared with the first stack that ran."
        ),
        Table(("stack", "ranks", *versions, "seconds"), stacks),
        Table(
            (f"against {res.reference}", "energy", "force", "stiffness", "verdict"),
            diffs,
            caption=f"Relative differences of the oracle's results (tolerance {res.tolerance:g})",
        ),
        Preformatted(format_check(res)),
    )


def _checks(res: CrossReleaseResult) -> list:
    """A failed stack is a failed check; every comparison is three tolerance checks."""
    from common.result import Check

    errors = "; ".join(e.label for e in res.errors)
    checks = [
        Check("stacks that exist but failed to run", float(len(res.errors)), 0.0, note=errors)
    ]
    for c in res.comparisons:
        checks += [
            Check(
                f"{c.label} against {res.reference}: {q} relative difference",
                value,
                res.tolerance,
            )
            for q, value in c.diff.by_quantity()
        ]
    return checks


def _headline(res: CrossReleaseResult) -> str:
    worst = max((c.diff.worst for c in res.comparisons), default=float("nan"))
    labels = ", ".join(s.label for s in res.stacks)
    return (
        f"{len(res.stacks)} stacks ran ({labels}); largest relative difference {worst:.1e} "
        f"(tolerance {res.tolerance:g})"
    )


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m comparisons.cross_release", description=__doc__.split("\n\n")[0]
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser(
        "snapshot", help="oracle results of the fixed cases on this interpreter (mpirun-aware)"
    )
    p.add_argument("--out", required=True)
    p.add_argument("--quick", action="store_true")
    p = sub.add_parser("compare", help="compare two snapshots")
    p.add_argument("reference")
    p.add_argument("other")
    p = sub.add_parser(
        "check", help="snapshots on every stack of this checkout, serial and on 2 ranks"
    )
    p.add_argument("--quick", action="store_true")
    p.add_argument("--json")
    args = parser.parse_args(argv)

    if args.command == "snapshot":
        from reference_fem.compat import comm_world
        from reference_fem.distributed import abort_on_error

        with abort_on_error(comm_world()):
            snap = take_snapshot(quick=args.quick)
            if snap is not None:
                save_snapshot(args.out, snap)
        return 0
    if args.command == "compare":
        print(
            json.dumps(
                compare_snapshots(
                    load_snapshot(args.reference), load_snapshot(args.other)
                ).to_dict(),
                indent=1,
            )
        )
        return 0
    # The same verdict as `mjed-verify cross-release` (exit 3 when a stack is missing); the
    # JSON keeps the raw check (CrossReleaseResult.to_dict()), which provenance_summary reads.
    from common.result import exit_code
    from common.terminal import format_result

    study = cross_release_study(quick=args.quick)
    print(format_result(study, details=False))
    if args.json:
        from common.options import write_json

        write_json(args.json, dict(study.data))
    return exit_code([study])


if __name__ == "__main__":
    sys.exit(main())
