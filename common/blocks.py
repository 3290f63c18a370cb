"""The content of a report section, independent of the output format.

A section body is a list of blocks: Paragraph, Table, Figure, Preformatted. Renderers in
:mod:`common.render` turn them into Markdown and self-contained HTML,
:mod:`common.terminal` into text.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence, Union

__all__ = ["Paragraph", "Table", "Figure", "Preformatted", "Block"]


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
