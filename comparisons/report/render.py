"""Markdown and self-contained HTML from report sections (figures embedded as data URIs)."""

from __future__ import annotations

import base64
import html
import os
from typing import List, Sequence

from comparisons.blocks import Figure, Paragraph, Preformatted, Section, Table

__all__ = ["to_markdown", "to_html", "format_cell"]

_STATUS_WORD = {"ok": "passed", "failed": "FAILED", "error": "ERROR", "skipped": "skipped", "interrupted": "INTERRUPTED"}


def format_cell(value: object) -> str:
    """Numbers in a table: small and large floats in scientific notation, others plainly."""
    if isinstance(value, bool):
        return "pass" if value else "FAIL"
    if isinstance(value, float):
        if value != value:
            return "nan"
        if value == 0.0:
            return "0"
        if abs(value) < 1e-3 or abs(value) >= 1e5:
            return f"{value:.2e}"
        return f"{value:.4g}"
    return str(value)


def _md_table(t: Table) -> List[str]:
    lines = []
    if t.caption:
        lines.append(f"*{t.caption}*")
        lines.append("")
    lines.append("| " + " | ".join(t.headers) + " |")
    lines.append("|" + "|".join("---" for _ in t.headers) + "|")
    lines.extend("| " + " | ".join(format_cell(c) for c in row) + " |" for row in t.rows)
    return lines


def to_markdown(title: str, preamble: Sequence[str], sections: Sequence[Section]) -> str:
    out = [f"# {title}", ""]
    for p in preamble:
        out += [p, ""]
    for s in sections:
        out += [f"## {s.title}", "", f"**Status: {_STATUS_WORD.get(s.status, s.status)}**"
                + (f": {s.message}" if s.message else "") + f" ({s.seconds:.1f} s)", "", s.summary, "",
                f"Reproduce: `{s.reproduce}`", ""]
        for b in s.blocks:
            if isinstance(b, Paragraph):
                out += [b.text, ""]
            elif isinstance(b, Table):
                out += _md_table(b) + [""]
            elif isinstance(b, Figure):
                out += [f"![{b.caption}]({b.path})", "", f"*{b.caption}*", ""]
            elif isinstance(b, Preformatted):
                out += ["```", b.text.rstrip(), "```", ""]
    return "\n".join(out)


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1{border-bottom:2px solid #444}h2{margin-top:2em;border-bottom:1px solid #bbb}
table{border-collapse:collapse;margin:0.8em 0;font-size:0.88em}td,th{border:1px solid #ccc;padding:2px 7px;text-align:right}
th{background:#f1f1f1}td:first-child,th:first-child{text-align:left}
.status{display:inline-block;padding:1px 8px;border-radius:4px;font-weight:600}
.ok{background:#d9f2d9}.failed,.error,.interrupted{background:#f8d0d0}.skipped{background:#eee}
code,pre{background:#f6f6f6;font-size:0.9em}pre{padding:0.6em;overflow-x:auto}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}figcaption{font-size:0.9em;color:#444}
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


def _html_table(t: Table) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in t.headers)
    body = []
    for row in t.rows:
        cells = []
        for c in row:
            text = html.escape(format_cell(c))
            cls = ' class="fail-cell"' if text in ("FAIL", "ERROR") else ""
            cells.append(f"<td{cls}>{text}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{html.escape(t.caption)}</caption>" if t.caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def to_html(title: str, preamble: Sequence[str], sections: Sequence[Section], run_dir: str) -> str:
    """One HTML file with every figure embedded: it opens from disk, no server, no network."""
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
             f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>"]
    parts += [f"<p>{html.escape(p)}</p>" for p in preamble]
    parts.append("<nav><ul>" + "".join(
        f"<li><a href='#{s.key}'>{html.escape(s.title)}</a> <span class='status {s.status}'>"
        f"{_STATUS_WORD.get(s.status, s.status)}</span></li>" for s in sections) + "</ul></nav>")
    for s in sections:
        parts.append(f"<h2 id='{s.key}'>{html.escape(s.title)}</h2>")
        msg = f": {html.escape(s.message)}" if s.message else ""
        parts.append(f"<p><span class='status {s.status}'>{_STATUS_WORD.get(s.status, s.status)}</span>{msg} "
                     f"<small>({s.seconds:.1f} s)</small></p>")
        parts.append(f"<p>{html.escape(s.summary)}</p><p>Reproduce: <code>{html.escape(s.reproduce)}</code></p>")
        for b in s.blocks:
            if isinstance(b, Paragraph):
                parts.append(f"<p>{html.escape(b.text)}</p>")
            elif isinstance(b, Table):
                parts.append(_html_table(b))
            elif isinstance(b, Figure):
                parts.append(f"<figure>{_embed(run_dir, b.path)}<figcaption>{html.escape(b.caption)}</figcaption></figure>")
            elif isinstance(b, Preformatted):
                parts.append(f"<pre>{html.escape(b.text)}</pre>")
    parts.append("</body></html>")
    return "\n".join(parts)
