"""The SOFA study's tables: verdicts, and timings with their ratio to SOFA's MJED."""

from __future__ import annotations

from typing import Optional, Sequence

from common.blocks import Paragraph, Table
from comparisons.sofa.records import SofaTiming, SofaVerdict

__all__ = ["blocks"]


def _fmt(x: Optional[float]) -> str:
    return "-" if x is None else f"{x:.1e}"


def blocks(verdicts: Sequence[SofaVerdict], timings: Sequence[SofaTiming]):
    """The report's blocks: the verdict table, then the timing table."""
    yield from _verdict_blocks(verdicts)
    if timings:
        yield _timing_table(timings)


def _verdict_blocks(verdicts: Sequence[SofaVerdict]):
    yield Paragraph(
        "Each row is one `mjed-verify check --command` run of SOFA's engine program (the "
        "command is in the JSON): the force field's force and its assembled stiffness "
        "(addForce as an implicit solver calls it, then addKToMatrix with kFactor = -1) "
        "against the oracle, every case of the states listed."
    )
    yield Table(
        [
            "force field",
            "material",
            "mesh",
            "passed",
            "worst force",
            "worst stiffness",
            "diagnosis (first failed case)",
        ],
        [
            [
                v.forcefield,
                v.material,
                v.mesh,
                f"{v.passed}/{v.cases}",
                _fmt(v.force_error),
                _fmt(v.stiffness_error),
                (v.diagnosis or v.bad_input)[:160],
            ]
            for v in verdicts
        ],
        caption="SOFA's force fields against the oracle",
    )


def _timing_table(timings: Sequence[SofaTiming]) -> Table:
    by = {(t.method, t.material, t.mesh): t for t in timings}
    rows = []
    for (method, material, mesh), t in by.items():
        ref = by.get(("sofa-mjed", material, mesh))
        rows.append(
            [
                method,
                material,
                mesh,
                t.n_cells,
                f"{t.force_s * 1e3:.3f}",
                f"{t.force_stiffness_s * 1e3:.3f}",
                "-" if t.dforce_s is None else f"{t.dforce_s * 1e3:.3f}",
                "-" if ref is None else f"{t.force_stiffness_s / ref.force_stiffness_s:.2f}",
            ]
        )
    yield Table(
        [
            "method",
            "material",
            "mesh",
            "cells",
            "force ms",
            "force+stiffness ms",
            "addDForce ms",
            "f+K time / SOFA MJED's",
        ],
        rows,
        caption="Median milliseconds per call, one thread, same run. SOFA's calls are timed "
        "inside its process (std::chrono around addForce, addKToMatrix, addDForce); the "
        "project's compiled kernels from Python (call overhead included). A ratio above 1: "
        "slower than SOFA's MJED.",
    )
