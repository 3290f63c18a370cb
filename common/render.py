"""Markdown and self-contained HTML from study results (figures embedded as data URIs).

One generic renderer serves every study: a :class:`common.result.StudyResult` is shown as
its status, headline and reason, what it left out, its protocol, its checks, the command that
reproduces it and then its own blocks. The summary at the top and the table of contents word
the statuses with :mod:`common.verdict`, so they say no more than the results do.
"""

from __future__ import annotations

import base64
import html
import os
from typing import List, Sequence

from common.blocks import Block, Figure, Paragraph, Preformatted, Table
from common.result import Check, Status, StudyResult
from common.terminal import format_cell
from common.verdict import not_covered_lines, status_label, verdict_sentence

__all__ = ["to_markdown", "to_html", "summary_blocks", "study_blocks", "status_class"]

SUMMARY_KEY = "summary"
SUMMARY_TITLE = "Summary"


def status_class(result: StudyResult) -> str:
    """CSS class of a status badge."""
    if result.status is Status.PASSED:
        return "partial" if result.partial else "passed"
    return result.status.name.lower().replace("_", "-")


def _checks_table(checks: Sequence[Check]) -> Table:
    return Table(
        ("check", "kind", "measured", "required", "verdict"),
        [
            (
                c.name + (f" ({c.note})" if c.note else ""),
                c.kind,
                "not measured" if c.measured is None else c.measured,
                f"{c.relation} {c.limit:g}",
                "not measured"
                if c.passed is None
                else ("met" if c.passed else ("FAIL" if c.kind == "tolerance" else "MISSED")),
            )
            for c in checks
        ],
        caption="What this study was held to",
    )


def study_blocks(r: StudyResult) -> List[Block]:
    """Everything shown for one study, after its status line, in order."""
    out: List[Block] = []
    if r.headline:
        out.append(Paragraph(r.headline))
    if r.not_covered:
        out.append(
            Preformatted(
                "Not covered by this run:\n" + "\n".join(f"- {item}" for item in r.not_covered)
            )
        )
    if r.protocol:
        out.append(Paragraph(f"Protocol: {r.protocol}"))
    if r.checks:
        out.append(_checks_table(r.checks))
    return out + list(r.blocks)


def summary_blocks(results: Sequence[StudyResult]) -> List[Block]:
    """The summary: the verdict, every study's status and headline, and what was left out."""
    out: List[Block] = [
        Paragraph(verdict_sentence(results)),
        Table(
            ("study", "status", "what it found", "seconds"),
            [
                (
                    r.title,
                    status_label(r),
                    r.reason if r.status is not Status.PASSED else r.headline,
                    f"{r.seconds:.1f}",
                )
                for r in results
            ],
        ),
    ]
    left_out = not_covered_lines(results)
    if left_out:
        out.append(
            Preformatted("Not covered by this run:\n" + "\n".join(f"- {line}" for line in left_out))
        )
    return out


# ----------------------------------------------------------------------------- Markdown
def _md_table(t: Table) -> List[str]:
    lines = [f"*{t.caption}*", ""] if t.caption else []
    lines.append("| " + " | ".join(t.headers) + " |")
    lines.append("|" + "|".join("---" for _ in t.headers) + "|")
    lines.extend(
        "| " + " | ".join(format_cell(c).replace("|", "\\|") for c in row) + " |" for row in t.rows
    )
    return lines


def _md_blocks(blocks: Sequence[Block]) -> List[str]:
    out: List[str] = []
    for b in blocks:
        if isinstance(b, Paragraph):
            out += [b.text, ""]
        elif isinstance(b, Table):
            out += _md_table(b) + [""]
        elif isinstance(b, Figure):
            out += [f"![{b.caption}]({b.path})", "", f"*{b.caption}*", ""]
        elif isinstance(b, Preformatted):
            out += ["```", b.text.rstrip(), "```", ""]
    return out


def _status_line(r: StudyResult) -> str:
    return f"{status_label(r)}" + (f": {r.reason}" if r.reason else "")


def to_markdown(title: str, preamble: Sequence[str], results: Sequence[StudyResult]) -> str:
    out = [f"# {title}", ""]
    for p in preamble:
        out += [p, ""]
    out += (
        ["Contents:", ""]
        + [f"- [{r.title}](#{r.key}): **{status_label(r)}**" for r in results]
        + [""]
    )
    out += [f"## {SUMMARY_TITLE}", ""] + _md_blocks(summary_blocks(results))
    for r in results:
        out += [
            f'<a id="{r.key}"></a>',
            "",
            f"## {r.title}",
            "",
            f"**Status: {_status_line(r)}** ({r.seconds:.1f} s)",
            "",
            f"Reproduce: `{r.command}`",
            "",
        ]
        out += _md_blocks(study_blocks(r))
    return "\n".join(out)


# ----------------------------------------------------------------------------- HTML
_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;
     margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1{border-bottom:2px solid #444}h2{margin-top:2em;border-bottom:1px solid #bbb}
table{border-collapse:collapse;margin:0.8em 0;font-size:0.88em}
td,th{border:1px solid #ccc;padding:2px 7px;text-align:right}
th{background:#f1f1f1}td:first-child,th:first-child{text-align:left}caption{text-align:left;font-style:italic}
.status{display:inline-block;padding:1px 8px;border-radius:4px;font-weight:600}
.passed{background:#d9f2d9}.partial,.target-missed,.not-run{background:#fbe7b5}.failed,.error{background:#f8d0d0}
code,pre{background:#f6f6f6;font-size:0.9em}pre{padding:0.6em;overflow-x:auto;white-space:pre-wrap}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:0.9em;color:#444}
nav li{margin:0.1em 0}.fail-cell{color:#b00;font-weight:600}
"""


def _embed(run_dir: str, rel: str) -> str:
    path = os.path.join(run_dir, rel)
    try:
        with open(path, "rb") as fh:
            data = base64.b64encode(fh.read()).decode("ascii")
    except OSError:
        return f'<p class="fail-cell">figure missing: {html.escape(rel)}</p>'
    mime = "image/svg+xml" if rel.endswith(".svg") else "image/png"
    return f'<img src="data:{mime};base64,{data}" alt="{html.escape(rel)}">'


#: Table cells shown in red: a verdict that is not a pass.
_ALERT = frozenset(("FAIL", "ERROR", "MISSED", "FAILED", "TARGET MISSED", "NOT RUN"))


def _html_table(t: Table) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in t.headers)
    body = []
    for row in t.rows:
        cells = []
        for c in row:
            text = html.escape(format_cell(c))
            cls = ' class="fail-cell"' if text in _ALERT else ""
            cells.append(f"<td{cls}>{text}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{html.escape(t.caption)}</caption>" if t.caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _html_blocks(blocks: Sequence[Block], run_dir: str) -> List[str]:
    out = []
    for b in blocks:
        if isinstance(b, Paragraph):
            out.append(f"<p>{html.escape(b.text)}</p>")
        elif isinstance(b, Table):
            out.append(_html_table(b))
        elif isinstance(b, Figure):
            out.append(
                f"<figure>{_embed(run_dir, b.path)}"
                f"<figcaption>{html.escape(b.caption)}</figcaption></figure>"
            )
        elif isinstance(b, Preformatted):
            out.append(f"<pre>{html.escape(b.text)}</pre>")
    return out


def _badge(r: StudyResult) -> str:
    return f"<span class='status {status_class(r)}'>{html.escape(status_label(r))}</span>"


def to_html(
    title: str, preamble: Sequence[str], results: Sequence[StudyResult], run_dir: str
) -> str:
    """One HTML file with every figure embedded: it opens from disk, no server, no network."""
    parts = [
        "<!doctype html><html lang='en'><head><meta "
        f"charset='utf-8'><title>{html.escape(title)}</title>",
        f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>",
    ]
    parts += [f"<p>{html.escape(p)}</p>" for p in preamble]
    parts.append(
        f"<nav><ul><li><a href='#{SUMMARY_KEY}'>{SUMMARY_TITLE}</a></li>"
        + "".join(
            f"<li><a href='#{r.key}'>{html.escape(r.title)}</a> {_badge(r)}</li>" for r in results
        )
        + "</ul></nav>"
    )
    parts.append(f"<h2 id='{SUMMARY_KEY}'>{SUMMARY_TITLE}</h2>")
    parts += _html_blocks(summary_blocks(results), run_dir)
    for r in results:
        parts.append(f"<h2 id='{r.key}'>{html.escape(r.title)}</h2>")
        reason = f": {html.escape(r.reason)}" if r.reason else ""
        parts.append(f"<p>{_badge(r)}{reason} <small>({r.seconds:.1f} s)</small></p>")
        parts.append(f"<p>Reproduce: <code>{html.escape(r.command)}</code></p>")
        parts += _html_blocks(study_blocks(r), run_dir)
    parts.append("</body></html>")
    return "\n".join(parts)
