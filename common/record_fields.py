"""Checking a typed record's fields when it is built, with errors that name the record and the key.

The studies' records are frozen dataclasses; each checks its fields in ``__post_init__``
through one :class:`RecordFields`::

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.real("dt", positive=True)
        f.counts("cg_iterations")

A check refuses a bad value with a ValueError naming the record and the key, e.g.
``LiverRun: key 'dt' must be a finite number > 0, got '0.3'`` (``key[i]`` for an entry of a
list), and stores an accepted value in its plain type (float, int, bool, tuple, dict), so a
record built from NumPy values equals, and writes the same JSON as, one built from Python values.
Reading a record back from its JSON is :mod:`common.json_fields`'s job; its ``build`` adds the
source and the key path to these errors.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Iterable, Mapping, Optional, Sequence

import numpy as np

__all__ = ["RecordFields", "is_real", "is_count"]


def is_real(value: Any) -> bool:
    """A real number (Python or NumPy, NaN and infinities included), not a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def is_count(value: Any, minimum: int = 0) -> bool:
    """An integer (Python or NumPy, not a bool) >= ``minimum``."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= minimum


def _same(value: Any) -> Any:
    return value


class RecordFields:
    """The fields of one record under construction, checked and stored by name.

    Args:
        record: the (frozen) dataclass instance, from its ``__post_init__``.
        name: how errors name it (default: its type's name, e.g. "LiverRun").
    """

    def __init__(self, record: Any, name: Optional[str] = None) -> None:
        self.record = record
        self.name = name or type(record).__name__

    def refusal(self, key: str, want: str, got: Any) -> ValueError:
        """``<name>: key '<key>' must be <want>, got <got>`` (got's repr cut to 120 characters)."""
        text = repr(got)
        text = text if len(text) <= 120 else text[:117] + "..."
        return ValueError(f"{self.name}: key {key!r} must be {want}, got {text}")

    def value(self, key: str) -> Any:
        return getattr(self.record, key)

    def store(self, key: str, value: Any) -> None:
        """Set a field of the frozen record (the checked value in its plain type)."""
        object.__setattr__(self.record, key, value)

    # ------------------------------------------------------------------ one value
    def real(self, key: str, *, positive: bool = False, optional: bool = False) -> None:
        """A number (finite and > 0 when ``positive``; None allowed when ``optional``), stored
        as a float.
        """
        v = self.value(key)
        if v is None and optional:
            return
        if not is_real(v) or (positive and not (math.isfinite(v) and v > 0)):
            want = "a finite number > 0" if positive else "a number"
            raise self.refusal(key, want + (" or None" if optional else ""), v)
        self.store(key, float(v))

    def count(self, key: str, *, minimum: int = 0) -> None:
        """An integer >= ``minimum``, stored as an int."""
        v = self.value(key)
        if not is_count(v, minimum):
            raise self.refusal(key, f"an integer >= {minimum}", v)
        self.store(key, int(v))

    def text(self, key: str, *, optional: bool = False) -> None:
        v = self.value(key)
        if not (isinstance(v, str) or (optional and v is None)):
            raise self.refusal(key, "a string" + (" or None" if optional else ""), v)

    def flag(self, key: str) -> None:
        """True or false (a NumPy bool too), stored as a bool."""
        v = self.value(key)
        if not isinstance(v, (bool, np.bool_)):
            raise self.refusal(key, "true or false", v)
        self.store(key, bool(v))

    def one_of(self, key: str, choices: Iterable[Any]) -> None:
        choices = list(choices)
        if self.value(key) not in choices:
            raise self.refusal(key, f"one of {choices}", self.value(key))

    def mapping(self, key: str, want: str = "an object") -> None:
        """A mapping, stored as a dict."""
        v = self.value(key)
        if not isinstance(v, Mapping):
            raise self.refusal(key, want, v)
        self.store(key, dict(v))

    # ------------------------------------------------------------------ collections
    def items(
        self,
        key: str,
        ok: Callable[[Any], bool],
        want: str,
        convert: Callable[[Any], Any] = _same,
        *,
        optional: bool = False,
    ) -> None:
        """A list of items that pass ``ok`` (each ``want``), stored as a tuple of
        ``convert(item)``; None allowed when ``optional``.
        """
        v = self.value(key)
        if v is None and optional:
            return
        if isinstance(v, (str, bytes, Mapping)) or not isinstance(v, (Sequence, np.ndarray)):
            raise self.refusal(key, f"a list of {want}", v)
        for i, item in enumerate(v):
            if not ok(item):
                raise self.refusal(f"{key}[{i}]", want, item)
        self.store(key, tuple(convert(item) for item in v))

    def reals(self, key: str, *, optional: bool = False) -> None:
        self.items(key, is_real, "numbers", float, optional=optional)

    def counts(self, key: str, *, optional: bool = False) -> None:
        self.items(key, is_count, "integers >= 0", int, optional=optional)

    def texts(self, key: str) -> None:
        self.items(key, lambda s: isinstance(s, str), "strings")

    def records(self, key: str, kind: type) -> None:
        """A list of ``kind`` records, stored as a tuple."""
        self.items(key, lambda x: isinstance(x, kind), kind.__name__)

    def reals_by_key(self, key: str, keys: Sequence[str]) -> None:
        """A mapping of each of ``keys`` (exactly those, in that order) to a number, stored as a
        dict of floats.
        """
        v = self.value(key)
        if not isinstance(v, Mapping) or list(v) != list(keys):
            raise self.refusal(key, f"an object with the keys {list(keys)}", v)
        for k, x in v.items():
            if not is_real(x):
                raise self.refusal(f"{key}[{k!r}]", "a number", x)
        self.store(key, {k: float(x) for k, x in v.items()})
