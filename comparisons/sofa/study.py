"""The SOFA study: SOFA's own hyperelastic force fields checked against the oracle, and the
paper's claim (MJED several times faster than the classical FEM) timed on SOFA's own code.

SOFA is not part of this project: the study runs where the engine program of
``conformance/adapters/sofa`` is built (``python -m conformance.adapters.sofa`` says how) and
is NOT RUN, with that reason, where it is not. Every verdict is one ``mjed-verify check``
command, recorded with the result so that a SOFA developer can run it again.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Callable, List, Optional, Sequence

from common.result import Check, StudyResult
from comparisons.sofa.figures import blocks
from comparisons.sofa.measurement import check_one, time_material
from comparisons.sofa.records import SofaTiming, SofaVerdict
from comparisons.sofa.setup import FORCEFIELDS, check_meshes, sofa_materials

__all__ = ["sofa_study"]

KEY, TITLE = "sofa", "SOFA's force fields: checked, and the paper's speed claim on SOFA's code"
TIMING_MESHES = ("cube-paper", "liver")


def sofa_study(
    plugin_meshes: Optional[Path] = None,
    quick: bool = False,
    materials: Optional[Sequence[str]] = None,
    forcefields: Sequence[str] = FORCEFIELDS,
    timing_calls: int = 10,
    checks_on: bool = True,
    timing_on: bool = True,
    progress: Callable[[str], None] = lambda s: None,
    command: str = "mjed-verify sofa",
) -> StudyResult:
    """Check every (force field, material, mesh) and time every (method, material) on the
    timing meshes; one StudyResult with the verdicts, the timings and their ratios.
    """
    from conformance.adapters.sofa import find_program, how_to_build

    program = find_program()
    if program is None:
        return StudyResult.not_run(KEY, TITLE, how_to_build(), command)
    names = list(materials or sofa_materials())
    verdicts: List[SofaVerdict] = []
    with tempfile.TemporaryDirectory(prefix="mjed-sofa-meshes-") as tmp:
        for label, mesh in check_meshes(Path(tmp), plugin_meshes, quick) if checks_on else ():
            for ff in forcefields:
                for name in names:
                    v = check_one(ff, name, label, mesh, program)
                    progress(f"check {ff} {name} on {label}: {v.passed}/{v.cases} passed")
                    verdicts.append(v)
    timings = _timings(names, forcefields, quick, timing_calls, progress) if timing_on else []
    checks = [
        Check(
            f"cases failed, SOFA {v.forcefield} {v.material} on {v.mesh}",
            float(v.cases - v.passed),
            0.0,
            note=v.diagnosis or v.bad_input,
        )
        for v in verdicts
    ]
    passed = sum(v.all_passed for v in verdicts)
    return StudyResult.from_checks(
        KEY,
        TITLE,
        checks,
        headline=f"{passed}/{len(verdicts)} force field x material x mesh verdicts pass "
        f"(SOFA program {program}, {_sofa_commit(program)})",
        command=command,
        data={
            "program": str(program),
            "sofa": _sofa_commit(program),
            "verdicts": [v.to_dict() for v in verdicts],
            "timings": [t.to_dict() for t in timings],
        },
        blocks=tuple(blocks(verdicts, timings)),
        not_covered=(
            "quick: cube-small instead of cube-paper, one plugin mesh, the liver not timed",
        )
        if quick
        else (),
    )


def _left_out(quick: bool, checks_on: bool, timing_on: bool):
    if quick:
        yield "quick: cube-small instead of cube-paper, one plugin mesh, the liver not timed"
    if not checks_on:
        yield "no checks (--skip-checks)"
    if not timing_on:
        yield "no timing (--skip-timing)"


def _timings(names, forcefields, quick, calls, progress) -> List[SofaTiming]:
    import meshes
    from common.states import apply_state

    rows: List[SofaTiming] = []
    for label in ("cube-small",) if quick else TIMING_MESHES:
        points, cells, _ = meshes.resolve(label)
        x = apply_state("random", points, cells)
        for name in names:
            if name == "Costa":  # SOFA's Costa takes no frame; the project's kernels do
                continue
            rows += time_material(name, label, points, cells, x, forcefields, calls, progress)
    return rows


def _sofa_commit(program: Path) -> str:
    """The SOFA and plugin commits the program was built from, when its build recorded them."""
    stamp = Path(program).with_name("sofa_commits.txt")  # written by the adapter's build
    return stamp.read_text().strip() if stamp.is_file() else "SOFA commit not recorded"
