"""How the timing study repeats its measurements: the protocols and the timed batches.

Two protocols:

- ``budget`` (the default): each measurement is a batch of calls long enough to time
  (at least ``min_batch_s``; the number of calls is fixed after the warm-up call), repeated in
  interleaved rounds (every method and quantity once per round, the method order rotated each
  round, so that machine drift hits them all alike). Rounds stop once every measurement's
  relative spread (max - min) / median over its last three rounds is at most ``spread``, after
  at least ``min_rounds`` rounds, or when ``max_rounds`` or the per-material time budget is
  reached; each measurement records which rule stopped it and its spread.
- ``paper``: the paper's protocol, 100 calls per batch, 3 interleaved rounds, no early stop.

A timed batch runs with the garbage collector off and reports the mean time per call.
"""

from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

__all__ = [
    "Protocol",
    "PROTOCOLS",
    "protocol",
    "time_batch",
    "calls_for",
    "relative_spread",
    "summary",
]


@dataclass(frozen=True)
class Protocol:
    """name; calls: fixed calls per batch (None: enough for min_batch_s); rounds bounds;
    spread: the stopping bound on the relative spread; budget_s: timed seconds per material.
    """

    name: str
    calls: Optional[int]
    min_batch_s: float
    min_rounds: int
    max_rounds: int
    spread: Optional[float]
    budget_s: Optional[float]

    def __post_init__(self):
        if self.min_rounds < 1 or self.max_rounds < self.min_rounds:
            raise ValueError(f"protocol {self.name}: need 1 <= min_rounds <= max_rounds")
        if self.calls is not None and self.calls < 1:
            raise ValueError(f"protocol {self.name}: calls must be >= 1")

    def describe(self) -> str:
        if self.calls is not None:
            return (
                f"{self.name}: {self.calls} calls per measurement (mean), {self.max_rounds} "
                "interleaved rounds, median over the rounds (the paper's protocol)"
            )
        return (
            f"{self.name}: batches of at least {self.min_batch_s * 1e3:.0f} ms (mean per call), "
            "interleaved rounds until every measurement's relative spread (max - min)/median over "
            f"its last 3 rounds is <= {100 * self.spread:.0f} % (at least {self.min_rounds}, at "
            f"most {self.max_rounds} rounds, or {self.budget_s:.0f} s of timed calls per "
            "material); median over the rounds"
        )

    def should_stop(self, rounds: int, spreads: Sequence[float], elapsed_s: float) -> Optional[str]:
        """Why to stop after ``rounds`` rounds, or None to go on."""
        if rounds >= self.max_rounds:
            return "rounds"
        if rounds < self.min_rounds:
            return None
        if self.spread is not None and spreads and max(spreads) <= self.spread:
            return "spread"
        if self.budget_s is not None and elapsed_s >= self.budget_s:
            return "budget"
        return None


PROTOCOLS: Dict[str, Protocol] = {
    "budget": Protocol("budget", None, 0.02, 3, 6, 0.05, 4.0),
    "paper": Protocol("paper", 100, 0.0, 3, 3, None, None),
    # --quick: the budget protocol on small meshes, fewer and shorter rounds
    "quick": Protocol("quick", None, 0.005, 2, 3, 0.10, 1.0),
}


def protocol(name: str) -> Protocol:
    try:
        return PROTOCOLS[name]
    except KeyError:
        raise ValueError(f"unknown protocol {name!r}; known: {', '.join(PROTOCOLS)}") from None


def calls_for(p: Protocol, first_call_s: float) -> int:
    """Calls per batch: the protocol's fixed count, or enough to last min_batch_s."""
    if p.calls is not None:
        return p.calls
    return max(1, int(math.ceil(p.min_batch_s / max(first_call_s, 1e-9))))


#: The generations collected before each timed batch: the young ones, where the previous
#: batch's garbage is (the collector is off during a batch, so all of it is in generation 0).
#: A full collection there cost 0.26 s per batch in a timing run of two materials (the Numba
#: compiler's and dolfinx's objects are traversed every time), a fifth of the run, and it is not
#: needed: nothing is collected while a batch is timed either way.
BATCH_GC_GENERATION = 1


def time_batch(fn: Callable, x: np.ndarray, calls: int) -> float:
    """Mean seconds per call over ``calls`` calls, garbage collection off (the young generations
    collected first).
    """
    gc.collect(BATCH_GC_GENERATION)
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        t0 = time.perf_counter()
        for _ in range(calls):
            fn(x)
        return (time.perf_counter() - t0) / calls
    finally:
        if was_enabled:
            gc.enable()


def relative_spread(values: Sequence[float], last: int = 3) -> float:
    """(max - min) / median of the last ``last`` values (inf with fewer than two)."""
    v = np.asarray(values[-last:], dtype=float)
    if len(v) < 2:
        return math.inf
    return float((v.max() - v.min()) / np.median(v))


def summary(values: List[float]) -> Dict[str, float]:
    v = np.asarray(values, dtype=float)
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max())}
