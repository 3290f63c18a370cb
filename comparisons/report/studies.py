"""The report's registry of studies, in the order they appear.

Each entry calls the study's own entry point (the same function its subcommand calls), which
returns a :class:`comparisons.result.StudyResult`; nothing here composes a verdict, a check or
a table of a study of its own. The only exceptions are marked TEMPORARY below: timing, scaling
and liver still return dicts today, and a thin wrapper turns those into results until their
owners' ``timing_study``, ``scaling_study`` and ``liver_study`` replace it at merge.
"""

from __future__ import annotations

from typing import List, Tuple

from comparisons.blocks import Figure, Paragraph, Table
from comparisons.report.runner import ReportStudy, StudyContext
from comparisons.result import Check, StudyResult

__all__ = ["report_studies", "study_keys"]


def _with_status(ctx: StudyContext, label: str, study, *args, **kwargs):
    """Run ``study(*args, progress=..., **kwargs)`` with a status line (terminal only)."""
    status = ctx.status(label)
    try:
        return study(*args, progress=status, **kwargs)
    finally:
        status.close()


# ----------------------------------------------------------------------------- the studies
def _equivalence(ctx: StudyContext) -> StudyResult:
    from comparisons.equivalence import equivalence_study
    from comparisons.progress import Progress

    bar = Progress(len(ctx.meshes) * len(ctx.materials) + 2, "equivalence", enabled=None if ctx.show_progress else False)
    try:
        return equivalence_study(ctx.meshes, ctx.materials, ctx.states, quick=ctx.quick, progress=bar.advance)
    finally:
        bar.close()


def _regularization(ctx: StudyContext) -> StudyResult:
    import meshes

    from comparisons.regularization import regularization_study

    points, cells, label = meshes.resolve("cube-small")
    return _with_status(ctx, "regularization", regularization_study, label, points, cells, ctx.materials)


def _rheometer(ctx: StudyContext) -> StudyResult:
    from comparisons.rheometer import rheometer_study

    return _with_status(ctx, "rheometer", rheometer_study, quick=ctx.quick, out_dir=ctx.figure_path("rheometer"),
                        figure_root=ctx.run_dir)


def _cross_release(ctx: StudyContext) -> StudyResult:
    from comparisons.cross_release import cross_release_study

    return _with_status(ctx, "cross-release", cross_release_study, quick=ctx.quick)


def _liver(ctx: StudyContext) -> StudyResult:
    from comparisons.liver import liver_study

    return _with_status(ctx, "liver", liver_study, quick=ctx.quick, out_dir=ctx.figure_path("liver"),
                        series=not ctx.quick, relative_to=ctx.run_dir)


def _provenance(ctx: StudyContext) -> StudyResult:
    from comparisons.provenance import provenance_study

    return provenance_study()


# ----------------------------------------------------------------------------- TEMPORARY
# TEMPORARY: replaced at merge by timing_study / scaling_study / liver_study (comparisons.timing,
# comparisons.liver), which their owners write. Until then these wrappers turn today's dicts
# into results: the speed and FPS targets become target checks, quick sizes not_covered.
def _target_checks(targets: list, relation: str) -> List[Check]:
    return [Check(f"{t['target']}" + (f", {t['material']}" if t.get("material") else ""), t["measured"],
                  float(t["required"]), relation, "target", note=t.get("note", "")) for t in targets]


def _timing(ctx: StudyContext) -> StudyResult:
    res = _run_timing_dict(ctx)
    mesh = "cube-small" if ctx.quick else "cube-paper"
    from comparisons.reproduce import command, material_option

    material, comment = material_option(ctx.materials)
    cmd = command("timing", comment=comment, quick=ctx.quick, material=material, mesh=mesh)
    s = res.data
    return StudyResult.from_checks(
        "timing", TIMING_TITLE, _target_checks(s.get("targets", []), ">="), headline=res.headline, command=cmd,
        not_covered=("quick: cube-small instead of cube-paper, fewer calls per measurement",) if ctx.quick else (),
        protocol=f"{s['settings']['iterations']} calls per measurement, median of {s['settings']['repeats']} interleaved "
                 "repeats; ratios per repeat", data=s, blocks=res.blocks)


def _scaling(ctx: StudyContext) -> StudyResult:
    res = _run_scaling_dict(ctx)
    from comparisons.reproduce import command

    s = res.data
    top = max((r["n_cells"] for r in s["rows"]), default=0)
    return StudyResult.from_checks(
        "scaling", SCALING_TITLE, _target_checks(s.get("targets", []), "<="), headline=res.headline,
        command=command("timing --scaling", quick=ctx.quick),
        not_covered=(f"quick: scaling sizes up to {top:,} cells (the full study goes to about 1e6)",) if ctx.quick else (),
        data=s, blocks=res.blocks)


class _Dict:
    """What the old dict-based composition below returns (TEMPORARY, see above)."""

    def __init__(self, data, blocks, headline=""):
        self.data, self.blocks, self.headline = data, tuple(blocks), headline


TIMING_TITLE = "Timing: MJED, classical FEM and dolfinx (paper Fig. 2)"
SCALING_TITLE = "Scaling with mesh size"


# ----------------------------------------------------------------------------- timing
def _run_timing_dict(ctx: StudyContext) -> _Dict:
    from comparisons.timing import run_timing

    names = [m.name for m in ctx.materials]
    res = _with_status(ctx, "timing", run_timing, names, "cube-small" if ctx.quick else "cube-paper",
                       out_dir=ctx.figure_path("timing"), quick=ctx.quick)
    med = {(r["material"], r["method"], r["what"]): r["median_s"] for r in res["results"]}
    ratio = {(r["material"], r["ratio"], r["what"]): r for r in res["ratios"]}
    methods = res["settings"]["methods"]
    rows = []
    for name in names:
        for what in ("force+stiffness", "force", "stiffness"):
            row = [name, what] + [1e3 * med[(name, m, what)] if (name, m, what) in med else None for m in methods]
            for other in ("classical", "dolfinx"):
                r = ratio.get((name, f"{other}/mjed", what))
                row.append(f"{r['median']:.2f} ({r['min']:.2f}-{r['max']:.2f})" if r else "")
            rows.append(row)
    mesh = res["mesh"]
    blocks = [Figure(ctx.relative(p), "Force + stiffness assembly time per material and method, in the style of the paper's Fig. 2")
              for p in res["figures"]]
    blocks.append(Paragraph(
        f"Mesh {mesh['name']}: {mesh['n_cells']} cells, {mesh['n_nodes']} nodes; each time is the mean of "
        f"{res['settings']['iterations']} calls, median over {res['settings']['repeats']} interleaved repeats; ratios are "
        "formed per repeat (median, then the range). Measured on the machine of the provenance section."))
    blocks.append(Table(("material", "what", *[f"{m} (ms)" for m in methods], "classical/mjed", "dolfinx/mjed"), rows))
    if res.get("memory"):
        blocks.append(Table(("material", "method", "peak memory (MiB)"),
                            [(m["material"], m["method"], (m.get("peak_bytes") or 0) / 2**20 if not m.get("error") else m["error"])
                             for m in res["memory"]], caption=res.get("memory_note", "")))
    fk = [r for r in res["ratios"] if r["what"] == "force+stiffness"]
    parts = []
    for other in ("classical", "dolfinx"):
        vals = [r["median"] for r in fk if r["ratio"] == f"{other}/mjed"]
        if vals:
            parts.append(f"{other}/mjed {min(vals):.2f} to {max(vals):.2f}")
    headline = f"force+stiffness on {mesh['name']}: " + ", ".join(parts) if parts else ""
    return _Dict(res, blocks, headline)


def _run_scaling_dict(ctx: StudyContext) -> _Dict:
    from comparisons.timing import run_scaling

    res = _with_status(ctx, "scaling", run_scaling, quick=ctx.quick, out_dir=ctx.figure_path("scaling"))
    blocks = [Figure(ctx.relative(p), "Time and peak memory per cell against mesh size (log axes)") for p in res["figures"]]
    blocks.append(Table(("method", "cells", "nodes", "f+K (s)", "us per cell", "peak MiB", "bytes per cell"),
                        [(r["method"], r["n_cells"], r["n_nodes"], r["seconds"], 1e6 * r["seconds_per_cell"],
                          r["peak_bytes"] / 2**20, r["peak_bytes_per_cell"]) for r in res["rows"]],
                        caption=f"{res['material']} on {res['settings']['mesh']}"))
    blocks.append(Table(("method", "how far it went"), sorted(res["stopped"].items())))
    per = [1e6 * r["seconds_per_cell"] for r in res["rows"] if r["method"] == "mjed"]
    top = max((r["n_cells"] for r in res["rows"]), default=0)
    headline = f"mjed {min(per):.2f} to {max(per):.2f} us per cell up to {top:,} cells" if per else ""
    return _Dict(res, blocks, headline)


# ----------------------------------------------------------------------------- the registry
def report_studies() -> Tuple[ReportStudy, ...]:
    """The report's studies in order; the summary comes first and is written by the runner."""
    from comparisons import cross_release, equivalence, liver, provenance, regularization, rheometer

    return (
        ReportStudy(equivalence.KEY, equivalence.TITLE, _equivalence),
        ReportStudy("timing", TIMING_TITLE, _timing),  # TEMPORARY wrapper (timing_study at merge)
        ReportStudy("scaling", SCALING_TITLE, _scaling),  # TEMPORARY wrapper (scaling_study at merge)
        ReportStudy(regularization.KEY, regularization.TITLE, _regularization),
        ReportStudy(rheometer.KEY, rheometer.TITLE, _rheometer),
        ReportStudy(liver.KEY, liver.TITLE, _liver),
        ReportStudy(cross_release.KEY, cross_release.TITLE, _cross_release),
        ReportStudy(provenance.KEY, provenance.TITLE, _provenance),
    )


def study_keys() -> Tuple[str, ...]:
    return tuple(s.key for s in report_studies())
