"""Run the studies into a new run directory and publish it as reports/latest when complete.

Safety rules, in order of importance:

- a run never writes into an existing run directory, so the previous complete report survives
  whatever happens to this one;
- the run is assembled in ``<reports>/.partial-<name>`` and renamed when its report is written;
  only then does ``latest`` move (an atomic symlink replace);
- a study that raises becomes an ERROR result saying what failed and why; the others run;
- an interrupted run (Ctrl-C, or SIGTERM from a job scheduler or ``timeout``) still writes
  what it has, as ``<name>-interrupted``, and leaves ``latest`` where it was; if even that
  cannot be written, the ``.partial-*`` folder is removed, never left behind;
- a study left out by ``--only`` is listed as NOT RUN with that reason, never silently dropped.

The runner decides no verdict: each study returns its :class:`common.result.StudyResult`,
and the summary words them (:mod:`common.verdict`).
"""

from __future__ import annotations

import os
import platform
import shlex
import shutil
import signal
import sys
import threading
import time
import traceback
from dataclasses import dataclass, replace
from typing import Callable, List, Optional, Sequence

from common.blocks import Figure, Preformatted
from common.render import to_html, to_markdown
from common.result import StudyResult, exit_code
from common.verdict import not_covered_lines, status_label, verdict_sentence

__all__ = [
    "StudyContext",
    "ReportStudy",
    "RunOutcome",
    "run_report",
    "publish_latest",
    "report_command",
    "Terminated",
]


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: handled as an interruption, so that the run ends the way Ctrl-C ends it."""


def _raise_terminated(signum, frame) -> None:
    raise Terminated()


def _on_sigterm():
    """Install the SIGTERM handler (main thread only; signals cannot be caught elsewhere);
    returns the previous handler, or None when it could not be installed.
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_terminated)


@dataclass(frozen=True)
class StudyContext:
    """What every study gets: where to write, how big to run, and the user's selections."""

    run_dir: str
    quick: bool
    materials: Sequence  # material instances
    meshes: (
        Sequence  # (label, points, cells) for the equivalence study; labels as the user gave them
    )
    states: Sequence[str]
    show_progress: bool = True

    def figure_path(self, name: str) -> str:
        """Absolute path of a figure file inside the run directory's figures/ folder."""
        os.makedirs(os.path.join(self.run_dir, "figures"), exist_ok=True)
        return os.path.join(self.run_dir, "figures", name)

    def relative(self, path: str) -> str:
        return os.path.relpath(path, self.run_dir)

    def status(self, label: str):
        """A status-line callback for a study's progress (silent off a terminal)."""
        from common.progress import StatusLine

        return StatusLine(f"  {label}", enabled=None if self.show_progress else False)


@dataclass(frozen=True)
class ReportStudy:
    """One entry of the report's registry: the study's key and title, and how to run it in a
    report.
    """

    key: str
    title: str
    run: Callable[[StudyContext], StudyResult]


@dataclass
class RunOutcome:
    run_dir: str
    complete: bool
    results: List[StudyResult]

    def exit_code(self, *, allow_incomplete: bool = False) -> int:
        """The written policy (common.verdict.EXIT_POLICY); 130 for an interrupted run."""
        return exit_code(self.results, allow_incomplete=allow_incomplete) if self.complete else 130

    @property
    def all_passed(self) -> bool:
        return self.complete and exit_code(self.results) == 0


def report_command(ctx: StudyContext, only: Optional[Sequence[str]] = None) -> str:
    """``mjed-verify all ...`` with this run's selections (and ``--only`` if given)."""
    from common.reproduce import command, material_option, mesh_option, only_option, states_option

    material, comment = material_option(ctx.materials)
    return command(
        "all",
        comment=comment,
        quick=ctx.quick,
        material=material,
        mesh=mesh_option(m[0] for m in ctx.meshes),
        states=states_option(ctx.states),
        only=only_option(only),
    )


def _new_run_name(reports_dir: str, quick: bool) -> str:
    base = time.strftime("%Y%m%d-%H%M%S") + ("-quick" if quick else "")
    name, k = base, 1
    while any(
        os.path.exists(os.path.join(reports_dir, n))
        for n in (name, f".partial-{name}", f"{name}-interrupted")
    ):
        k += 1
        name = f"{base}-{k}"
    return name


def publish_latest(reports_dir: str, run_name: str) -> str:
    """Point ``<reports>/latest`` at run_name atomically (a relative symlink)."""
    link = os.path.join(reports_dir, "latest")
    tmp = os.path.join(reports_dir, f".latest-{os.getpid()}")
    if os.path.lexists(tmp):
        os.remove(tmp)
    os.symlink(run_name, tmp)
    if os.path.isdir(link) and not os.path.islink(link):
        raise OSError(
            f"{link} is a real directory, not a link; move it away so the report can be published"
        )
    os.replace(tmp, link)
    return link


def _relative_figures(result: StudyResult, run_dir: str) -> StudyResult:
    """Figure paths relative to the run directory: it is renamed when the report is written,
    so an absolute path into it would point nowhere in report.md afterwards.
    """
    blocks = tuple(
        Figure(os.path.relpath(b.path, run_dir), b.caption)
        if isinstance(b, Figure) and os.path.isabs(b.path)
        else b
        for b in result.blocks
    )
    return replace(result, blocks=blocks, command=_without_run_dir_out(result.command, run_dir))


def _paths_relative_to(obj, run_dir: str):
    """A copy of a JSON-like payload in which every string that is a path inside ``run_dir``
    (absolute, or as the studies were given it) is made relative to it: the directory is
    renamed once the report is written, so such paths would point nowhere in results.json.
    """
    root = os.path.abspath(run_dir)
    if isinstance(obj, dict):
        return {k: _paths_relative_to(v, run_dir) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_paths_relative_to(v, run_dir) for v in obj]
    if (
        isinstance(obj, str)
        and (obj.startswith(run_dir) or obj.startswith(root))
        and "\n" not in obj
    ):
        path = os.path.abspath(obj)
        if path == root or path.startswith(root + os.sep):
            return os.path.relpath(path, root)
    return obj


def _without_run_dir_out(command: str, run_dir: str) -> str:
    """The reproduce line without an ``--out`` into the report's own (temporary) run
    directory: re-running the study alone writes to its default place instead, and that
    directory is renamed when the report is written. Every other option is kept.
    """
    try:
        words = shlex.split(command)
    except ValueError:
        return command
    root = os.path.abspath(run_dir)
    kept, skip = [], False
    for i, w in enumerate(words):
        if skip:
            skip = False
            continue
        if (
            w == "--out"
            and i + 1 < len(words)
            and os.path.abspath(words[i + 1]).startswith(root + os.sep)
        ):
            skip = True
            continue
        kept.append(w)
    return command if len(kept) == len(words) else " ".join(shlex.quote(w) for w in kept)


def _run_one(study: ReportStudy, ctx: StudyContext) -> StudyResult:
    """The study's result, or an ERROR result naming the exception and its last frames."""
    try:
        result = study.run(ctx)
        if not isinstance(result, StudyResult):
            raise TypeError(
                f"study {study.key!r} returned {type(result).__name__}, not a StudyResult"
            )
        return _relative_figures(result, ctx.run_dir)
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # a failed study must not take the report down with it
        frames = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)[-6:])
        return StudyResult.error(
            study.key,
            study.title,
            f"{type(exc).__name__}: {exc}",
            report_command(ctx, only=[study.key]),
            blocks=[Preformatted(frames)],
        )


def run_report(
    reports_dir: str,
    studies: Sequence[ReportStudy],
    context_args: dict,
    *,
    quick: bool,
    only: Optional[Sequence[str]] = None,
    command_line: Optional[Sequence[str]] = None,
    stream=None,
) -> RunOutcome:
    """Run the selected studies, write index.html, report.md and results.json, publish latest.

    context_args: materials, meshes, states, show_progress (see StudyContext).
    only: the keys to run (None: all); the others are NOT RUN results saying so.
    """
    stream = stream if stream is not None else sys.stderr
    os.makedirs(reports_dir, exist_ok=True)
    name = _new_run_name(reports_dir, quick)
    partial = os.path.join(reports_dir, f".partial-{name}")
    os.makedirs(partial)
    previous = _on_sigterm()
    try:
        return _run_into(
            partial,
            reports_dir,
            name,
            studies,
            context_args,
            quick=quick,
            only=only,
            command_line=command_line,
            stream=stream,
        )
    except BaseException:
        # even the interrupted report could not be written (a second signal, a full disk):
        # remove the folder rather than leave a .partial-* behind
        shutil.rmtree(partial, ignore_errors=True)
        raise
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _run_studies(ctx: StudyContext, studies: Sequence[ReportStudy], only, stream):
    """Each selected study in turn; after an interruption the rest are NOT RUN, saying why.
    Returns (results, interrupted).
    """
    results: List[StudyResult] = []
    interrupted = False
    selected = [s for s in studies if only is None or s.key in only]
    for study in studies:
        again = report_command(ctx, only=[study.key])
        if only is not None and study.key not in only:
            why = f"not selected: --only {','.join(only)}"
            results.append(StudyResult.not_run(study.key, study.title, why, again))
            continue
        if interrupted:
            why = "the run was interrupted before this study"
            results.append(StudyResult.not_run(study.key, study.title, why, again))
            continue
        n = selected.index(study) + 1
        print(f"[{n}/{len(selected)}] {study.title} ...", file=stream, flush=True)
        t0 = time.perf_counter()
        try:
            result = _run_one(study, ctx)
        except KeyboardInterrupt as exc:
            interrupted = True
            how = (
                "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted by the user"
            )
            result = StudyResult.not_run(study.key, study.title, f"{how} during this study", again)
        result = result.with_seconds(time.perf_counter() - t0)
        why = f": {result.reason}" if result.reason else ""
        print(
            f"      {status_label(result)}{why} ({result.seconds:.1f} s)", file=stream, flush=True
        )
        results.append(result)
    return results, interrupted


def _write_run(
    partial: str,
    name: str,
    ctx: StudyContext,
    results,
    interrupted: bool,
    quick: bool,
    command_line,
) -> None:
    """results.json, report.md and index.html of a run, into its .partial folder."""
    from common.options import write_json

    cmd = " ".join(shlex.quote(a) for a in (command_line if command_line is not None else sys.argv))
    title = "MJED verification report" + (" (quick)" if quick else "")
    preamble = [
        f"Run {name} on {platform.node() or 'this machine'}, "
        f"{time.strftime('%Y-%m-%d %H:%M:%S %Z')}; command: {cmd}.",
        "MJED (Marchesseau et al., MICCAI 2010) checked force by force and stiffness by stiffness "
        "against a UFL Galerkin oracle, with timings, the rheometer study and the liver under "
        "gravity. How to read this report (statuses, exit codes, Reproduce lines): docs/report.md.",
        f"Selection: materials {', '.join(m.name for m in ctx.materials)}; meshes "
        f"{', '.join(m[0] for m in ctx.meshes)} (equivalence); states {', '.join(ctx.states)}.",
    ]
    payload = {
        "run": name,
        "quick": quick,
        "command": cmd,
        "complete": not interrupted,
        "exit_code": exit_code(results) if not interrupted else 130,
        "verdict": verdict_sentence(results),
        "not_covered": not_covered_lines(results),
        "studies": [r.to_dict() for r in results],
    }
    write_json(os.path.join(partial, "results.json"), _paths_relative_to(payload, partial))
    with open(os.path.join(partial, "report.md"), "w") as fh:
        fh.write(to_markdown(title, preamble, results))
    with open(os.path.join(partial, "index.html"), "w") as fh:
        fh.write(to_html(title, preamble, results, partial))


def _run_into(
    partial: str,
    reports_dir: str,
    name: str,
    studies: Sequence[ReportStudy],
    context_args: dict,
    *,
    quick: bool,
    only: Optional[Sequence[str]],
    command_line: Optional[Sequence[str]],
    stream,
) -> RunOutcome:
    ctx = StudyContext(run_dir=partial, quick=quick, **context_args)
    results, interrupted = _run_studies(ctx, studies, only, stream)
    _write_run(partial, name, ctx, results, interrupted, quick, command_line)
    final = os.path.join(reports_dir, name + ("-interrupted" if interrupted else ""))
    os.rename(partial, final)
    if not interrupted:
        publish_latest(reports_dir, os.path.basename(final))
    return RunOutcome(run_dir=final, complete=not interrupted, results=results)
