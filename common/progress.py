"""Progress on stderr for long steps: a bar on a terminal, nothing when piped or in CI."""

from __future__ import annotations

import sys
import time
from typing import Iterable, Iterator, Optional, TextIO, TypeVar

__all__ = ["Progress", "StatusLine", "progress"]

T = TypeVar("T")


class Progress:
    """A one-line progress bar; silent unless the stream is a terminal (or forced)."""

    def __init__(
        self,
        total: int,
        label: str,
        *,
        stream: Optional[TextIO] = None,
        enabled: Optional[bool] = None,
    ):
        self.total = max(int(total), 0)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.done = 0
        self._t0 = time.perf_counter()

    def advance(self, what: str = "") -> None:
        self.done += 1
        if not self.enabled:
            return
        width = 24
        filled = int(width * self.done / self.total) if self.total else width
        elapsed = time.perf_counter() - self._t0
        bar = "#" * filled + "." * (width - filled)
        line = f"\r{self.label} [{bar}] {self.done}/{self.total} {elapsed:5.1f}s {what[:40]:40s}"
        self.stream.write(line)
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def progress(items: Iterable[T], label: str, total: Optional[int] = None, **kwargs) -> Iterator[T]:
    """Iterate over items while drawing a bar (see :class:`Progress`)."""
    items = list(items) if total is None else items
    bar = Progress(len(items) if total is None else total, label, **kwargs)
    try:
        for item in items:
            yield item
            bar.advance()
    finally:
        bar.close()


class StatusLine:
    """One rewritten line of status for steps whose length is not known in advance.

    Call it with a message; silent unless the stream is a terminal (or forced).
    """

    def __init__(
        self, label: str, *, stream: Optional[TextIO] = None, enabled: Optional[bool] = None
    ):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self._t0 = time.perf_counter()
        self._width = 0

    def __call__(self, message: str) -> None:
        if not self.enabled:
            return
        line = f"{self.label} {time.perf_counter() - self._t0:6.1f}s  {message}"[:110]
        self.stream.write("\r" + line.ljust(self._width))
        self.stream.flush()
        self._width = len(line)

    def close(self) -> None:
        if self.enabled and self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
