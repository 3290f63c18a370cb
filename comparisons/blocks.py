"""The content of a report section, independent of the output format.

A section body is a list of blocks: Paragraph, Table, Figure, Preformatted. Renderers in
:mod:`comparisons.report.render` turn them into Markdown and self-contained HTML.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Sequence, Union

__all__ = ["Paragraph", "Table", "Figure", "Preformatted", "Block", "Section"]


@dataclass(frozen=True)
class Paragraph:
    text: str


@dataclass(frozen=True)
class Table:
    headers: Sequence[str]
    rows: Sequence[Sequence[object]]
    caption: str = ""


@dataclass(frozen=True)
class Figure:
    path: str  # relative to the run directory
    caption: str


@dataclass(frozen=True)
class Preformatted:
    text: str


Block = Union[Paragraph, Table, Figure, Preformatted]


@dataclass
class Section:
    """One study's part of the report.

    status: "ok", "failed" (a check did not pass), "error" (the study could not run),
    "skipped" or "interrupted". ``message`` says why when it is not ok.
    """

    key: str
    title: str
    summary: str
    reproduce: str
    status: str = "ok"
    message: str = ""
    headline: str = ""
    blocks: List[Block] = field(default_factory=list)
    seconds: float = 0.0
