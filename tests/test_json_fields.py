"""Reading a study's JSON back: every refusal names the source and the key path."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest

from common.json_fields import JSONFields, JSONRecord, RecordError, json_keys

PAYLOAD = {
    "n": 3,
    "x": 1.5,
    "nan": None,
    "flag": True,
    "name": "a",
    "pair": [1, 2.5],
    "rows": [{"label": "a"}, {"other": 1}],
    "versions": {"dolfinx": "0.5.2"},
    "non_finite": [{"path": "nan", "value": "nan"}],
}


def test_fields_read_with_their_types():
    f = JSONFields(PAYLOAD, "xr.json")
    assert f.integer("n") == 3 and f.number("x") == 1.5 and f.number("n") == 3.0
    assert math.isnan(f.number("nan"))  # write_json writes NaN as null
    assert f.flag("flag") is True and f.text("name") == "a" and f.optional_text("nan") is None
    assert f.numbers("pair", length=2) == [1.0, 2.5]
    assert f.objects("rows")[0].text("label") == "a"
    assert f.mapping("versions") == {"dolfinx": "0.5.2"}


@pytest.mark.parametrize(
    "read, message",
    [
        (lambda f: f.get("absent"), "xr.json: missing key 'absent'"),
        (lambda f: f.integer("x"), "xr.json: x: expected an integer, got 1.5"),
        (lambda f: f.integer("flag"), "xr.json: flag: expected an integer, got True"),
        (lambda f: f.number("name"), "xr.json: name: expected a number, got 'a'"),
        (lambda f: f.flag("n"), "xr.json: n: expected true or false, got 3"),
        (lambda f: f.numbers("pair", length=3), "xr.json: pair: expected 3 numbers, got 2"),
        (lambda f: f.objects("rows")[1].text("label"), "xr.json: rows/1: missing key 'label'"),
        (lambda f: f.object("versions").text("ufl"), "xr.json: versions: missing key 'ufl'"),
        (lambda f: f.texts("pair"), "xr.json: pair/0: expected a string, got 1"),
        (lambda f: f.object("name"), "xr.json: name: expected a JSON object, got str"),
    ],
)
def test_refusals_name_the_source_and_the_key(read, message):
    with pytest.raises(RecordError) as info:
        read(JSONFields(PAYLOAD, "xr.json"))
    assert str(info.value) == message


def test_a_record_s_own_validation_is_named_too():
    def record(value):
        if value < 0:
            raise ValueError("value must be >= 0")
        return value

    rows = JSONFields(PAYLOAD, "xr.json").objects("rows")
    with pytest.raises(RecordError, match=r"^xr.json: rows/1: value must be >= 0$"):
        rows[1].build(record, value=-1)
    assert rows[1].build(record, value=2) == 2
    with pytest.raises(RecordError, match="^xr.json: expected a JSON object, got list$"):
        JSONFields([], "xr.json")


@dataclasses.dataclass(frozen=True)
class Row(JSONRecord):
    label: str
    x: float = 0.0
    cache: Any = dataclasses.field(default=None, metadata={"json": False})

    def __post_init__(self) -> None:
        if not isinstance(self.label, str):
            raise ValueError(f"Row: key 'label' must be a string, got {self.label!r}")

    _DERIVED = ("twice",)


def test_a_dataclass_reads_its_fields_and_refuses_any_other_key():
    assert json_keys(Row) == ("label", "x")
    rows = JSONFields({"rows": [{"label": "a", "x": 2.0, "twice": 4.0}]}, "t.json").records(
        "rows", Row
    )
    assert rows == (Row("a", 2.0),)
    assert Row.from_dict({"label": "b", "twice": 0.0}) == Row("b")  # x has a default

    def refusal(payload):
        with pytest.raises(RecordError) as info:
            JSONFields({"rows": payload}, "t.json").records("rows", Row)
        return str(info.value)

    assert refusal([{"x": 1.0, "twice": 2.0}]) == "t.json: rows/0: Row: missing key 'label'"
    assert refusal([{"label": "a"}]) == "t.json: rows/0: Row: missing key 'twice'"
    assert (
        refusal([{"label": "a", "twice": 0, "cache": 1}])
        == "t.json: rows/0: Row: unexpected key 'cache'"
    )
    assert refusal([{"label": 1, "twice": 0}]) == (
        "t.json: rows/0: Row: key 'label' must be a string, got 1"
    )
    assert refusal([[]]) == "t.json: rows/0: Row: expected a JSON object, got list"
    assert refusal("a") == "t.json: rows: expected a list, got str"
    with pytest.raises(RecordError, match="^<dict>: Row: expected a JSON object, got list$"):
        Row.from_dict([])
