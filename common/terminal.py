"""A study result on the terminal: the common ending of every study command.

A command parses its options, calls its study and hands the :class:`StudyResult` to
:func:`finish`, which prints it, writes ``--json`` (``result.to_dict()``) and returns the exit
code of the written policy (:data:`common.verdict.EXIT_POLICY`).
"""

from __future__ import annotations

import sys
import textwrap
from typing import List, Sequence, TextIO

from common.blocks import Block, Figure, Paragraph, Preformatted, Table
from common.result import StudyResult, exit_code
from common.verdict import status_label

__all__ = ["format_cell", "format_blocks", "format_result", "finish"]


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
    return "" if value is None else str(value)


def _text_table(table: Table) -> List[str]:
    rows = [[str(h) for h in table.headers]] + [[format_cell(c) for c in row] for row in table.rows]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    lines.insert(1, "-" * len(lines[0]))
    return ([table.caption] if table.caption else []) + lines


def format_blocks(blocks: Sequence[Block], width: int = 100) -> List[str]:
    out: List[str] = []
    for b in blocks:
        if isinstance(b, Paragraph):
            out += textwrap.wrap(b.text, width) or [""]
        elif isinstance(b, Table):
            out += _text_table(b)
        elif isinstance(b, Figure):
            out.append(f"figure: {b.path} ({b.caption})")
        elif isinstance(b, Preformatted):
            out += b.text.rstrip().splitlines()
        out.append("")
    return out


def format_result(result: StudyResult, *, details: bool = True) -> str:
    """The result as text: blocks (if ``details``), checks, what was left out, the verdict line."""
    lines: List[str] = format_blocks(result.blocks) if details else []
    if result.checks:
        lines += _text_table(
            Table(
                ("check", "kind", "measured", "required", "verdict"),
                [
                    (
                        c.name,
                        c.kind,
                        c.measured if c.measured is not None else "not measured",
                        f"{c.relation} {c.limit:g}",
                        "not measured" if c.passed is None else ("met" if c.passed else "NOT MET"),
                    )
                    for c in result.checks
                ],
            )
        )
        lines.append("")
    if result.protocol:
        lines.append(f"protocol: {result.protocol}")
    lines += [f"not covered: {item}" for item in result.not_covered]
    lines.append(f"{result.title}: {status_label(result)}: {result.headline}")
    if result.reason:
        lines.append(f"  why: {result.reason}")
    lines.append(f"reproduce: {result.command}")
    return "\n".join(lines)


def finish(result: StudyResult, args, *, stream: TextIO = None, details: bool = True) -> int:
    """Print ``result``, write ``args.json`` if given, return the exit code (policy of --help)."""
    from common.options import write_json

    print(format_result(result, details=details), file=stream if stream is not None else sys.stdout)
    if getattr(args, "json", None):
        write_json(args.json, result.to_dict())
    return exit_code([result], allow_incomplete=getattr(args, "allow_incomplete", False))
