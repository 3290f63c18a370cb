"""Reading a study's JSON back into its typed record, field by field, with errors that say where.

The studies write their records with ``to_dict()`` through :func:`common.options.write_json`;
a record's ``from_dict()`` reads one back through :class:`JSONFields`, which checks each field's
presence and type and names the source (a file, or a label) and the key path on any error, e.g.
``reports/cross_release.json: stacks/1: missing key 'ranks'``. Keys a record does not read
(``non_finite``, which ``write_json`` adds) are ignored, except by :meth:`JSONFields.dataclass`,
which reads every field of a dataclass as it is (its construction checks the values, see
:mod:`common.record_fields`) and refuses any other key; a record read that way gets its
``from_dict`` and ``from_fields`` from :class:`JSONRecord`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Type, TypeVar

__all__ = ["RecordError", "JSONFields", "JSONRecord", "json_keys"]

T = TypeVar("T")
R = TypeVar("R", bound="JSONRecord")


class RecordError(ValueError):
    """A JSON payload that is not the record it should be (the message names source and key)."""


class JSONFields:
    """One JSON object, the source it was read from and its key path in that source.

    Args:
        obj: the parsed JSON object (a dict).
        source: where the payload came from (a file name, or a label such as "<dict>").
        path: the key path of ``obj`` in the payload ("" at the top, "stacks/0" below).
        record: the name of the record it is read into, when messages about the object itself
            (not a JSON object, a key missing or unexpected) should say it ("LiverRun").

    Raises:
        RecordError: ``obj`` is not a JSON object.
    """

    def __init__(self, obj: Any, source: str, path: str = "", record: Optional[str] = None) -> None:
        self.obj: Dict[str, Any] = obj
        self.source = source
        self.path = path
        self.record = record
        if not isinstance(obj, dict):
            raise self._refusal(f"expected a JSON object, got {type(obj).__name__}")

    @property
    def where(self) -> str:
        """The source and the key path, for messages ("xr.json: stacks/0")."""
        return f"{self.source}: {self.path}" if self.path else self.source

    def _path(self, key: str) -> str:
        return f"{self.path}/{key}" if self.path else key

    def _refusal(self, what: str) -> RecordError:
        """An error about the object itself, naming its place and, when known, its record."""
        return RecordError(
            f"{self.where}: {self.record}: {what}" if self.record else f"{self.where}: {what}"
        )

    def error(self, key: str, what: str) -> RecordError:
        """An error about ``key`` of this object, naming the source and the key path."""
        return RecordError(f"{self.source}: {self._path(key)}: {what}")

    def get(self, key: str) -> Any:
        """The value at ``key``, which must be present."""
        if key not in self.obj:
            raise self._refusal(f"missing key {key!r}")
        return self.obj[key]

    def number(self, key: str) -> float:
        """A float; null reads as NaN (``write_json`` writes NaN and infinities as null)."""
        return _number(self.get(key), lambda what: self.error(key, what))

    def integer(self, key: str) -> int:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"expected an integer, got {value!r}")
        return value

    def text(self, key: str) -> str:
        value = self.get(key)
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {value!r}")
        return value

    def optional_text(self, key: str) -> Optional[str]:
        return None if self.get(key) is None else self.text(key)

    def flag(self, key: str) -> bool:
        value = self.get(key)
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {value!r}")
        return value

    def array(self, key: str) -> list:
        value = self.get(key)
        if not isinstance(value, list):
            raise self.error(key, f"expected a list, got {type(value).__name__}")
        return value

    def numbers(self, key: str, length: Optional[int] = None) -> List[float]:
        """A list of floats (of ``length`` entries when given); null entries read as NaN."""
        values = self.array(key)
        if length is not None and len(values) != length:
            raise self.error(key, f"expected {length} numbers, got {len(values)}")
        return [
            _number(v, lambda what, i=i: self.error(f"{key}/{i}", what))
            for i, v in enumerate(values)
        ]

    def integers(self, key: str) -> List[int]:
        values = self.array(key)
        for i, v in enumerate(values):
            if isinstance(v, bool) or not isinstance(v, int):
                raise self.error(f"{key}/{i}", f"expected an integer, got {v!r}")
        return values

    def texts(self, key: str) -> List[str]:
        values = self.array(key)
        for i, v in enumerate(values):
            if not isinstance(v, str):
                raise self.error(f"{key}/{i}", f"expected a string, got {v!r}")
        return values

    def mapping(self, key: str) -> Dict[str, Any]:
        """A JSON object taken as it is (a copy), for free-form fields such as versions."""
        return dict(self.object(key).obj)

    def build(self, record_type: Callable[..., T], **fields: Any) -> T:
        """``record_type(**fields)``, a refusal by its validation naming this object's place."""
        try:
            return record_type(**fields)
        except RecordError:
            raise
        except (TypeError, ValueError) as exc:
            raise RecordError(f"{self.where}: {exc}") from None

    def dataclass(self, record_type: Callable[..., T], derived: Sequence[str] = (), **parsed) -> T:
        """``record_type`` (a dataclass) from this object, every field as it is in the JSON, its
        construction checking the values (a refusal named as by :meth:`build`).

        Every key of :func:`json_keys` must be present (those of fields with a default may be
        left out), the ``derived`` keys too (values the record computes: checked for presence,
        not read), and no other key. ``parsed`` gives the values of fields already read (nested
        records).
        """
        fields = dataclasses.fields(record_type)
        has_default = {
            f.name
            for f in fields
            if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
        }
        keys = json_keys(record_type)
        for key in (*keys, *derived):
            if key not in self.obj and key not in has_default:
                self.get(key)  # refused: missing
        unexpected = [k for k in self.obj if k not in keys and k not in derived]
        if unexpected:
            raise self._refusal(f"unexpected key {unexpected[0]!r}")
        values = {k: self.obj[k] for k in keys if k in self.obj}
        values.update(parsed)
        return self.build(record_type, **values)

    def object(self, key: str, record: Optional[str] = None) -> "JSONFields":
        """The JSON object at ``key`` (read into ``record``, when given: see the class)."""
        return JSONFields(self.get(key), self.source, self._path(key), record)

    def objects(self, key: str, record: Optional[str] = None) -> List["JSONFields"]:
        """The list at ``key``, each entry a JSON object (read into ``record``, when given)."""
        return [
            JSONFields(v, self.source, self._path(f"{key}/{i}"), record)
            for i, v in enumerate(self.array(key))
        ]

    def records(self, key: str, record_type: Any) -> tuple:
        """The list at ``key`` read into ``record_type`` records, each by its ``from_fields``
        (messages about an entry name its place and the record, ``runs/1: LiverRun: ...``).
        """
        return tuple(
            record_type.from_fields(item) for item in self.objects(key, record_type.__name__)
        )


class JSONRecord:
    """The reading back of a dataclass record whose JSON holds its fields as they are (a base
    of the record's class; it adds no field).

    ``from_fields`` is :meth:`JSONFields.dataclass` with the record's ``_DERIVED`` keys (the
    values its JSON adds and it computes); a record holding nested records overrides it and
    reads them with :meth:`JSONFields.records`.
    """

    _DERIVED: Tuple[str, ...] = ()

    @classmethod
    def from_dict(cls: Type[R], payload: Any, source: str = "<dict>") -> R:
        """The record from its JSON object, read from ``source`` (a file name or a label).

        Raises:
            RecordError: (a ValueError) a key missing, unexpected or bad, named with the source,
                the key path and the record (``<dict>: runs/1: LiverRun: missing key 'dt'``).
        """
        return cls.from_fields(JSONFields(payload, source, record=cls.__name__))

    @classmethod
    def from_fields(cls: Type[R], f: JSONFields) -> R:
        return f.dataclass(cls, derived=cls._DERIVED)


def json_keys(record_type: Any) -> Tuple[str, ...]:
    """The fields of a dataclass that its JSON holds: all but those marked
    ``field(metadata={"json": False})``.
    """
    return tuple(f.name for f in dataclasses.fields(record_type) if f.metadata.get("json", True))


def _number(value: Any, error) -> float:
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise error(f"expected a number, got {value!r}")
    return float(value)
