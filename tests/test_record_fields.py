"""Checking a typed record's fields on construction (common.record_fields): each check names
the record and the key, and stores the value in its plain type.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from common.record_fields import RecordFields, is_count, is_real


@dataclasses.dataclass(frozen=True)
class Probe:
    """One field, checked by the RecordFields method ``check`` with ``options``."""

    value: Any
    check: str = "real"
    options: tuple = ()

    def __post_init__(self) -> None:
        getattr(RecordFields(self), self.check)("value", **dict(self.options))


def probe(value, check="real", **options):
    return Probe(value, check, tuple(options.items())).value


def test_accepted_values_are_stored_in_their_plain_type():
    assert type(probe(np.float64(0.5))) is float and probe(np.int64(3)) == 3.0
    assert probe(None, optional=True) is None and np.isnan(probe(float("nan")))
    assert type(probe(np.int32(4), "count", minimum=1)) is int
    assert probe(np.bool_(True), "flag") is True
    assert probe(np.array([1, 2]), "reals") == (1.0, 2.0)
    assert probe([np.int64(0), 2], "counts") == (0, 2)
    assert probe(["a"], "texts") == ("a",) and probe(None, "counts", optional=True) is None
    assert probe({"a": np.float32(1)}, "reals_by_key", keys=("a",)) == {"a": 1.0}
    assert probe({"x": 1}, "mapping") == {"x": 1}
    assert probe("numpy", "one_of", choices=("numpy", "numba")) == "numpy"


@pytest.mark.parametrize(
    "value, check, options, message",
    [
        ("0.3", "real", {"positive": True}, "key 'value' must be a finite number > 0, got '0.3'"),
        (float("inf"), "real", {"positive": True}, "must be a finite number > 0, got inf"),
        (True, "real", {}, "key 'value' must be a number, got True"),
        (None, "real", {}, "key 'value' must be a number, got None"),
        ("x", "real", {"optional": True}, "must be a number or None, got 'x'"),
        (3.0, "count", {}, "key 'value' must be an integer >= 0, got 3.0"),
        (0, "count", {"minimum": 1}, "key 'value' must be an integer >= 1, got 0"),
        (1, "text", {}, "key 'value' must be a string, got 1"),
        ("yes", "flag", {}, "key 'value' must be true or false, got 'yes'"),
        ("elastic", "one_of", {"choices": ("a", "b")}, "must be one of ['a', 'b'], got 'elastic'"),
        ("12", "reals", {}, "key 'value' must be a list of numbers, got '12'"),
        ([4, -1], "counts", {}, "key 'value[1]' must be integers >= 0, got -1"),
        ({"b": 1.0}, "reals_by_key", {"keys": ("a",)}, "must be an object with the keys ['a']"),
        ({"a": "1"}, "reals_by_key", {"keys": ("a",)}, "key \"value['a']\" must be a number"),
        ([1], "mapping", {}, "key 'value' must be an object, got [1]"),
        pytest.param("x" * 200, "count", {}, "got '" + "x" * 116 + "...", id="cut to 120"),
    ],
)
def test_refusals_name_the_record_and_the_key(value, check, options, message):
    with pytest.raises(ValueError) as info:
        probe(value, check, **options)
    assert str(info.value).startswith("Probe: ") and message in str(info.value)


def test_a_record_may_be_named_otherwise_and_refuse_with_its_own_words():
    @dataclasses.dataclass(frozen=True)
    class Stack:
        label: str
        ranks: int

        def __post_init__(self) -> None:
            f = RecordFields(self, name=f"Stack {self.label!r}")
            f.count("ranks", minimum=1)
            if self.ranks > 64:
                raise f.refusal("ranks", "at most 64", self.ranks)

    with pytest.raises(ValueError, match=r"^Stack 'mpi': key 'ranks' must be an integer >= 1"):
        Stack("mpi", 0)
    with pytest.raises(ValueError, match=r"^Stack 'mpi': key 'ranks' must be at most 64, got 65$"):
        Stack("mpi", 65)


def test_records_are_checked_by_type():
    @dataclasses.dataclass(frozen=True)
    class Holder:
        probes: Any

        def __post_init__(self) -> None:
            RecordFields(self).records("probes", Probe)

    assert Holder([Probe(1.0)]).probes == (Probe(1.0),)
    with pytest.raises(ValueError, match=r"^Holder: key 'probes\[0\]' must be Probe, got \{"):
        Holder([{"value": 1.0}])


def test_the_predicates():
    assert is_real(np.float32(1)) and is_real(float("nan")) and not is_real(True)
    assert is_count(np.uint8(0)) and not is_count(-1) and not is_count(2.0)
    assert is_count(2, minimum=2) and not is_count(1, minimum=2) and not is_count(False)
