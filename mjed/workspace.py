"""Named work arrays kept from one evaluation to the next."""

from __future__ import annotations

from typing import Dict, Tuple

import numpy as np

__all__ = ["Workspace"]


class Workspace:
    """Float64 work arrays by name, allocated on first request and reused.

    Fresh NumPy temporaries of a few MB cost page faults on every call (the allocator hands
    large blocks back to the OS when they are freed), which on a 20k-cell mesh was about as
    expensive as the arithmetic. The engine therefore writes intermediates into these
    buffers; what an evaluation returns is never one of them. One workspace per engine: an
    engine must not evaluate from two threads at once.

    ``ws(name, shape)`` returns the array of that name, reallocated only when the shape
    changes. Two names never share memory, so an intermediate stays valid until its own name
    is requested again.
    """

    def __init__(self):
        self._arrays: Dict[str, np.ndarray] = {}

    def __call__(self, name: str, shape: Tuple[int, ...]) -> np.ndarray:
        a = self._arrays.get(name)
        if a is None or a.shape != shape:
            a = self._arrays[name] = np.empty(shape)
        return a

    def __len__(self) -> int:
        return len(self._arrays)

    @property
    def nbytes(self) -> int:
        """Bytes held by all the work arrays."""
        return sum(a.nbytes for a in self._arrays.values())
