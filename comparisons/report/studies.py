"""The report's registry of studies, in the order they appear.

Each entry calls the study's own entry point (the same function its subcommand calls), which
returns a :class:`common.result.StudyResult`; nothing here composes a verdict, a check or
a table of a study of its own.
"""

from __future__ import annotations

from typing import Tuple

from common.result import StudyResult
from comparisons.report.runner import ReportStudy, StudyContext

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
    from common.progress import Progress
    from comparisons.equivalence.study import equivalence_study

    bar = Progress(
        len(ctx.meshes) * len(ctx.materials) + 2,
        "equivalence",
        enabled=None if ctx.show_progress else False,
    )
    try:
        return equivalence_study(
            ctx.meshes, ctx.materials, ctx.states, quick=ctx.quick, progress=bar.advance
        )
    finally:
        bar.close()


def _gpu(ctx: StudyContext) -> StudyResult:
    from comparisons.timing.gpu_section import gpu_study

    return gpu_study()


def _regularization(ctx: StudyContext) -> StudyResult:
    import meshes
    from comparisons.regularization.study import regularization_study

    points, cells, label = meshes.resolve("cube-small")
    return _with_status(
        ctx, "regularization", regularization_study, label, points, cells, ctx.materials
    )


def _rheometer(ctx: StudyContext) -> StudyResult:
    from comparisons.rheometer.study import rheometer_study

    return _with_status(
        ctx,
        "rheometer",
        rheometer_study,
        quick=ctx.quick,
        out_dir=ctx.figure_path("rheometer"),
        figure_root=ctx.run_dir,
    )


def _cross_release(ctx: StudyContext) -> StudyResult:
    from comparisons.cross_release.study import cross_release_study

    return _with_status(ctx, "cross-release", cross_release_study, quick=ctx.quick)


def _timing(ctx: StudyContext) -> StudyResult:
    from comparisons.timing.study import timing_study

    # The timing study times the materials of common/cases.py, chosen by name.
    names = [m.name for m in ctx.materials]
    return _with_status(
        ctx,
        "timing",
        timing_study,
        names,
        "cube-small" if ctx.quick else "cube-paper",
        quick=ctx.quick,
        out_dir=ctx.figure_path("timing"),
    )


def _scaling(ctx: StudyContext) -> StudyResult:
    from comparisons.timing.study import scaling_study

    return _with_status(
        ctx, "scaling", scaling_study, quick=ctx.quick, out_dir=ctx.figure_path("scaling")
    )


def _liver(ctx: StudyContext) -> StudyResult:
    from comparisons.liver.study import liver_study

    return _with_status(
        ctx,
        "liver",
        liver_study,
        quick=ctx.quick,
        out_dir=ctx.figure_path("liver"),
        series=not ctx.quick,
        relative_to=ctx.run_dir,
    )


def _sofa(ctx: StudyContext) -> StudyResult:
    from comparisons.sofa.study import sofa_study

    # NOT RUN (with how to build) where SOFA's engine program is missing, as on most machines.
    return _with_status(ctx, "SOFA", sofa_study, quick=ctx.quick)


def _provenance(ctx: StudyContext) -> StudyResult:
    from comparisons.provenance import provenance_study

    return provenance_study()


# ----------------------------------------------------------------------------- the registry
def report_studies() -> Tuple[ReportStudy, ...]:
    """The report's studies in order; the summary comes first and is written by the runner."""
    from comparisons import provenance
    from comparisons.cross_release import study as cross_release
    from comparisons.equivalence import study as equivalence
    from comparisons.liver import study as liver
    from comparisons.regularization import study as regularization
    from comparisons.rheometer import study as rheometer
    from comparisons.sofa import study as sofa
    from comparisons.timing import gpu_section as gpu_study
    from comparisons.timing import study as timing

    return (
        ReportStudy(equivalence.KEY, equivalence.TITLE, _equivalence),
        ReportStudy(timing.KEY, timing.TITLE, _timing),
        ReportStudy(timing.SCALING_KEY, timing.SCALING_TITLE, _scaling),
        ReportStudy(gpu_study.KEY, gpu_study.TITLE, _gpu),
        ReportStudy(regularization.KEY, regularization.TITLE, _regularization),
        ReportStudy(rheometer.KEY, rheometer.TITLE, _rheometer),
        ReportStudy(liver.KEY, liver.TITLE, _liver),
        ReportStudy(cross_release.KEY, cross_release.TITLE, _cross_release),
        ReportStudy(sofa.KEY, sofa.TITLE, _sofa),
        ReportStudy(provenance.KEY, provenance.TITLE, _provenance),
    )


def study_keys() -> Tuple[str, ...]:
    return tuple(s.key for s in report_studies())
