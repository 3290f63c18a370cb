"""Run the studies into a new run directory and publish it as reports/latest when complete.

Safety rules, in order of importance:
- a run never writes into an existing run directory, so the previous complete report survives
  whatever happens to this one;
- the run is assembled in ``<reports>/.partial-<name>`` and renamed when its report is written;
  only then does ``latest`` move (an atomic symlink replace);
- a study that raises becomes an "error" section saying what failed and why; the others run;
- an interrupted run (Ctrl-C) still writes what it has, as ``<name>-interrupted``, and leaves
  ``latest`` where it was.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field, is_dataclass
from typing import Callable, Dict, List, Optional, Sequence

from comparisons.blocks import Preformatted, Section, Table
from comparisons.report.render import to_html, to_markdown

__all__ = ["StudyContext", "Study", "RunOutcome", "run_report", "publish_latest"]


@dataclass(frozen=True)
class StudyContext:
    """What every study gets: where to write, how big to run, and the user's selections."""

    run_dir: str
    quick: bool
    materials: Sequence  # material instances
    meshes: Sequence  # (label, points, cells) for the equivalence study
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
        from comparisons.progress import StatusLine

        return StatusLine(f"  {label}", enabled=None if self.show_progress else False)


@dataclass(frozen=True)
class StudyResult:
    payload: dict
    blocks: list
    passed: bool = True
    message: str = ""
    headline: str = ""  # the one line the summary verdict shows for this study


@dataclass(frozen=True)
class Study:
    key: str
    title: str
    summary: str
    reproduce: str
    run: Callable[[StudyContext], StudyResult]


@dataclass
class RunOutcome:
    run_dir: str
    complete: bool
    sections: List[Section]
    results: Dict[str, dict] = field(default_factory=dict)

    @property
    def all_passed(self) -> bool:
        return self.complete and all(s.status in ("ok", "skipped") for s in self.sections)


def _jsonable(obj):
    if is_dataclass(obj) and not isinstance(obj, type):
        return asdict(obj)
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, float) and obj != obj:
        return None
    return str(obj)


def _new_run_name(reports_dir: str, quick: bool) -> str:
    base = time.strftime("%Y%m%d-%H%M%S") + ("-quick" if quick else "")
    name, k = base, 1
    while any(os.path.exists(os.path.join(reports_dir, n)) for n in (name, f".partial-{name}", f"{name}-interrupted")):
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
        raise OSError(f"{link} is a real directory, not a link; move it away so the report can be published")
    os.replace(tmp, link)
    return link


def _verdict_section(sections: Sequence[Section], results: Dict[str, dict]) -> Section:
    bad = [s for s in sections if s.status not in ("ok", "skipped")]
    eq = results.get("equivalence", {})
    cases = eq.get("cases", [])
    lines = []
    if cases:
        n_pass = sum(c["passed"] for c in cases)
        wf = max(c["force_rel_err"] for c in cases)
        wk = max(c["stiffness_rel_err"] for c in cases)
        lines.append(f"Equivalence: {n_pass}/{len(cases)} cases passed; worst force error {wf:.1e}, "
                     f"worst stiffness error {wk:.1e} (tolerance 1e-10).")
    elif "equivalence" in results or any(s.key == "equivalence" for s in sections):
        lines.append("Equivalence: no case ran.")
    verdict = "every check passed" if not bad else "NOT every check passed: " + "; ".join(
        f"{s.title} ({s.status}{': ' + s.message if s.message else ''})" for s in bad)
    rows = [(s.title, {"ok": "passed"}.get(s.status, s.status.upper() if s.status != "skipped" else "skipped"),
             "; ".join(t for t in (s.message, s.headline) if t), f"{s.seconds:.1f}") for s in sections]
    return Section(
        key="verdict", title="Summary verdict", status="ok" if not bad else "failed",
        summary=f"Verdict: {verdict}.", reproduce="mjed-verify all",
        blocks=[*(Preformatted(l) for l in lines),
                Table(("section", "status", "what it found", "seconds"), rows)],
        message="" if not bad else f"{len(bad)} section(s) did not pass",
    )


def run_report(
    reports_dir: str,
    studies: Sequence[Study],
    context_args: dict,
    *,
    quick: bool,
    command_line: Optional[Sequence[str]] = None,
    stream=None,
) -> RunOutcome:
    """Run every study, write index.html, report.md and results.json, publish latest.

    context_args: materials, meshes, states, show_progress (see StudyContext).
    """
    stream = stream if stream is not None else sys.stderr
    os.makedirs(reports_dir, exist_ok=True)
    name = _new_run_name(reports_dir, quick)
    partial = os.path.join(reports_dir, f".partial-{name}")
    os.makedirs(partial)
    ctx = StudyContext(run_dir=partial, quick=quick, **context_args)
    sections: List[Section] = []
    results: Dict[str, dict] = {}
    interrupted = False
    for i, study in enumerate(studies):
        sec = Section(key=study.key, title=study.title, summary=study.summary, reproduce=study.reproduce)
        if interrupted:
            sec.status, sec.message = "interrupted", "not run: the run was interrupted before this study"
            sections.append(sec)
            continue
        print(f"[{i + 1}/{len(studies)}] {study.title} ...", file=stream, flush=True)
        t0 = time.perf_counter()
        try:
            res = study.run(ctx)
            results[study.key] = res.payload
            sec.blocks = list(res.blocks)
            sec.status = "ok" if res.passed else "failed"
            sec.message = res.message
            sec.headline = res.headline
        except KeyboardInterrupt:
            interrupted = True
            sec.status, sec.message = "interrupted", "interrupted by the user during this study"
        except Exception as exc:  # a failed study must not take the report down with it
            sec.status = "error"
            sec.message = f"{type(exc).__name__}: {exc}"
            sec.blocks = [Preformatted("".join(traceback.format_exception(type(exc), exc, exc.__traceback__)[-6:]))]
            results[study.key] = {"error": sec.message}
        sec.seconds = time.perf_counter() - t0
        print(f"      {sec.status}{': ' + sec.message if sec.message else ''} ({sec.seconds:.1f} s)", file=stream, flush=True)
        sections.append(sec)

    sections.insert(0, _verdict_section(sections, results))
    cmd = " ".join(shlex.quote(a) for a in (command_line if command_line is not None else sys.argv))
    title = "MJED verification report" + (" (quick)" if quick else "")
    preamble = [f"Run {name} on {platform.node() or 'this machine'}, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}; command: {cmd}.",
                "MJED (Marchesseau et al., MICCAI 2010) checked force by force and stiffness by stiffness against a "
                "UFL Galerkin oracle, with timings, the rheometer study and the liver under gravity."]
    payload = {"run": name, "quick": quick, "command": cmd, "complete": not interrupted,
               "sections": [{"key": s.key, "title": s.title, "status": s.status, "message": s.message,
                             "seconds": s.seconds} for s in sections],
               "results": results}
    with open(os.path.join(partial, "results.json"), "w") as fh:
        json.dump(payload, fh, indent=1, default=_jsonable)
    with open(os.path.join(partial, "report.md"), "w") as fh:
        fh.write(to_markdown(title, preamble, sections))
    with open(os.path.join(partial, "index.html"), "w") as fh:
        fh.write(to_html(title, preamble, sections, partial))

    final = os.path.join(reports_dir, name + ("-interrupted" if interrupted else ""))
    os.rename(partial, final)
    if not interrupted:
        publish_latest(reports_dir, os.path.basename(final))
    return RunOutcome(run_dir=final, complete=not interrupted, sections=sections, results=results)
