"""The report of ``mjed-verify check``: a self-contained HTML page, Markdown, JSON, and per-node
error fields as VTU files for ParaView (one per failing case, referenced from the report).
"""

from __future__ import annotations

import os
from typing import Dict, List, Optional

import numpy as np

from common.blocks import Paragraph, Preformatted, Table
from common.result import Status, StudyResult
from conformance.kit.cases import KitCase
from conformance.run import CheckRun

__all__ = ["write_report", "write_error_field", "new_report_dir"]


def new_report_dir(base: str, stem: str = "check") -> str:
    """A directory that did not exist: base/stem-YYYYmmdd-HHMMSS[-k]."""
    import time

    name = f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}"
    for k in range(1000):
        path = os.path.join(base, name if k == 0 else f"{name}-{k}")
        try:
            os.makedirs(path)
            return path
        except FileExistsError:
            continue
    raise FileExistsError(f"{base}: could not create a new report directory")


def write_error_field(
    path: str, case: KitCase, f: np.ndarray, f_o: np.ndarray, node_error: np.ndarray
) -> None:
    """VTU of the case's mesh at its current positions with point data:
    node_error (relative, force and stiffness rows), force_error = f - f_oracle (N).
    """
    import meshio

    mesh = meshio.Mesh(
        np.asarray(case.input.positions),
        [("tetra", np.asarray(case.input.cells))],
        point_data={
            "node_error": np.asarray(node_error, dtype=float),
            "force_error": np.asarray(f - f_o, dtype=float),
            "force_oracle": np.asarray(f_o, dtype=float),
        },
    )
    meshio.write(path, mesh)


def _fmt(x: Optional[float]) -> object:
    return "-" if x is None else float(x)


def _case_table(run: CheckRun) -> Table:
    rows = []
    for o in run.outcomes:
        d = o.diagnosis
        if d is None:
            rows.append([o.case_id, o.status, "-", "-", "-", "-", "-", o.message[:120]])
            continue
        c = d.consistency
        cons = (
            "-"
            if c is None or c.stiffness_statistic is None
            else f"{c.stiffness_statistic:.1e} (limit {c.stiffness_limit:.0e})"
        )
        cause = "; ".join(f.title for f in d.causes) or (
            "" if d.passed else next((f.title for f in d.findings if f.code == "unexplained"), "")
        )
        rows.append(
            [
                o.case_id,
                o.status,
                d.errors.force,
                d.errors.stiffness,
                _fmt(d.errors.energy),
                d.errors.symmetry,
                cons,
                cause,
            ]
        )
    for cid, msg in run.input_errors.items():
        rows.append([cid, "bad input", "-", "-", "-", "-", "-", msg[:120]])
    return Table(
        [
            "case",
            "status",
            "force err",
            "stiffness err",
            "energy err",
            "K asymmetry",
            "K vs own force",
            "cause",
        ],
        rows,
        caption="Relative errors against the oracle (tolerance 1e-10); 'K vs own force' is the "
        "probes' inconsistency beyond what the fit leaves for the oracle on the same probes, "
        "with its limit on that case",
    )


def write_report(
    folder: str, run: CheckRun, *, command: str, fields: Dict[str, str]
) -> Dict[str, str]:
    """Write index.html, report.md and results.json into ``folder``; returns their paths.

    fields: case id -> VTU path relative to ``folder`` (written by the caller).
    """
    from common.options import write_json
    from common.render import to_html, to_markdown

    # Each case is a typed result, so the report's summary says exactly what passed.
    status = {0: Status.PASSED, 1: Status.FAILED, 2: Status.ERROR}[run.exit_code]
    reason = "" if status is Status.PASSED else run.summary()
    results: List[StudyResult] = [
        StudyResult(
            key="summary",
            title="Cases",
            status=status,
            headline=run.summary(),
            command=command,
            reason=reason,
            blocks=(_case_table(run),),
        )
    ]
    for o in run.outcomes:
        if o.status == "passed":
            continue
        blocks = []
        if o.diagnosis is not None:
            blocks.append(Preformatted(o.diagnosis.text()))
        if o.message:
            blocks.append(Paragraph(o.message))
        if o.case_id in fields:
            blocks.append(
                Paragraph(
                    f"Per-node error field for ParaView: {fields[o.case_id]} (point data "
                    "node_error, force_error, force_oracle on the current positions)."
                )
            )
        failed = o.status == "failed"
        results.append(
            StudyResult(
                key=f"case-{len(results)}",
                title=o.case_id,
                status=Status.FAILED if failed else Status.ERROR,
                headline=f"{o.model} on {o.mesh}, state {o.state}",
                command=command,
                reason=(
                    _first_finding(o.diagnosis)
                    if failed and o.diagnosis is not None
                    else (o.message or o.status)
                ),
                blocks=tuple(blocks),
                seconds=o.seconds,
            )
        )
    for cid, msg in run.input_errors.items():
        results.append(
            StudyResult(
                key=f"case-{len(results)}",
                title=cid,
                status=Status.ERROR,
                headline="could not be read",
                command=command,
                reason=f"bad input: {msg}",
                blocks=(Paragraph(msg),),
            )
        )
    title = "mjed-verify check"
    preamble = [
        f"Command: {command}",
        run.summary(),
        "Conventions, tolerances and the meaning of each diagnosis: docs/conventions.md.",
    ]
    paths = {
        "html": os.path.join(folder, "index.html"),
        "markdown": os.path.join(folder, "report.md"),
        "json": os.path.join(folder, "results.json"),
    }
    with open(paths["html"], "w") as fh:
        fh.write(to_html(title, preamble, results, folder))
    with open(paths["markdown"], "w") as fh:
        fh.write(to_markdown(title, preamble, results))
    # strict JSON: a non-finite figure becomes null, listed with its value under "non_finite"
    write_json(paths["json"], {"command": command, **run.to_dict(), "fields": fields})
    return paths


def _first_finding(d) -> str:
    """The named cause (or the first finding) of a diagnosis, as one line for the summary."""
    findings = d.causes or list(d.findings)
    return findings[0].text() if findings else "failed with no finding"
