"""Reading a kit: the one place a kit's files are opened.

Layout of a kit directory (docs/conventions.md, "Exchange format")::

    manifest.json                      the kit manifest: format, format_version, cases
    cases/<case id>/input/             what the engine reads (case.json, case.txt, arrays)
    cases/<case id>/output/            where the engine writes (force.f64, stiffness..., energy.f64)

:func:`read_kit` hands the rest of the checker a :class:`Kit`: the manifest validated, every
path confined to the kit (:mod:`conformance.kit.confine`), every file read hashed and checked
against the manifest's SHA-256, sizes checked before reading. Nothing else opens a kit file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Tuple

from conformance.kit.cases import KitCase
from conformance.kit.confine import ConfinementError, check_case_id, confined_path, read_confined
from conformance.kit.exchange import (
    KIT_FORMAT,
    MAX_INPUT_ARRAY_BYTES,
    FormatError,
    check_version,
    load_json,
    read_case_input,
)

__all__ = ["Kit", "KitManifest", "MAX_KIT_BYTES", "read_kit"]


@dataclass(frozen=True)
class Kit:
    """A kit read back, the only way the rest of the checker sees one: its cases (those that
    could be read: validated, confined to the kit's folder, every input byte hashed against the
    manifest) and one error per unreadable case.
    """

    folder: str
    cases: Tuple[KitCase, ...]
    entries: Mapping[str, Mapping[str, Any]]
    errors: Mapping[str, str]
    precision: str = "auto"  # declared by the manifest ("double" or "single"), else "auto"


#: All the input arrays of a kit together (each case holds its own copy in memory).
MAX_KIT_BYTES = 4 << 30


def read_kit(folder: str) -> Kit:
    """Read a kit; a bad case becomes an entry of ``errors`` (case id -> message), the others are
    kept.

    Every path is confined to ``folder``, every file read is listed in the case's
    ``input_sha256`` and hashed on the bytes read, and sizes are checked before reading.

    Raises:
        FormatError: the kit manifest itself is missing or malformed (then nothing can run).
    """
    path = os.path.join(folder, "manifest.json")
    data = load_json(
        folder, "manifest.json", hint=f" (is {folder} a kit written by mjed-verify export?)"
    )
    check_version(data, path, "(kit)", KIT_FORMAT)
    raw = data.get("cases")
    if not isinstance(raw, list) or not raw:
        raise FormatError(f"{path}: 'cases' must be a non-empty list")
    ids = [e.get("id") if isinstance(e, dict) else None for e in raw]
    counts: Dict[str, int] = {}
    for cid in ids:
        if isinstance(cid, str):
            counts[cid] = counts.get(cid, 0) + 1
    cases, entries, errors = [], {}, {}
    total = 0
    for i, e in enumerate(raw):
        cid = ids[i]
        if not isinstance(cid, str):
            errors[f"#{i}"] = f"case #{i} of {path}: entry without an 'id'"
            continue
        try:
            check_case_id(cid, f"case #{i} of {path}")
        except ConfinementError as exc:
            errors[f"#{i}"] = str(exc)
            continue
        if counts[cid] > 1:  # neither entry can be trusted to be the one meant; both are refused
            errors[cid] = (
                f"case {cid}: {path}: the id appears {counts[cid]} times; case ids must be unique"
            )
            continue
        entries[cid] = e
        if total > MAX_KIT_BYTES:
            errors[cid] = (
                f"case {cid}: {path}: not read, the kit's input arrays already exceed "
                f"{MAX_KIT_BYTES} bytes"
            )
            continue
        try:
            case = _read_entry(folder, e, path)
        except FormatError as exc:
            errors[cid] = str(exc)
            continue
        except (TypeError, ValueError, OverflowError, RecursionError) as exc:
            # a field of an unexpected JSON type deep in the entry: bad input of this case only
            errors[cid] = f"case {cid}: {path}: {type(exc).__name__}: {exc}"
            continue
        total += sum(a.nbytes for a in (case.input.points, case.input.cells, case.input.positions))
        cases.append(case)
    precision = data.get("precision", "auto")
    if precision not in ("double", "single", "auto"):
        raise FormatError(f"{path}: 'precision' must be 'double' or 'single', not {precision!r}")
    return Kit(folder, tuple(cases), entries, errors, precision)


class _Recording(dict):
    """The digests of a case, noting which files the reader looked up (and so hashed as read)."""

    def __init__(self, digests: Mapping[str, str]) -> None:
        super().__init__(digests)
        self.looked_up: set = set()

    def __getitem__(self, name: str) -> str:
        self.looked_up.add(name)
        return super().__getitem__(name)


def _read_entry(folder: str, e: Mapping[str, Any], manifest_path: str) -> KitCase:
    cid = e["id"]
    where = f"case {cid}: {manifest_path}"
    for key in ("role", "input", "output", "mesh", "state"):
        if not isinstance(e.get(key), str):
            raise FormatError(f"{where}: field {key!r} missing or not a string")
    if e["role"] not in ("case", "probe"):
        raise FormatError(f"{where}: role must be 'case' or 'probe', not {e['role']!r}")
    probe_of, step = e.get("probe_of"), e.get("step", 0)
    if e["role"] == "probe" and not isinstance(probe_of, str):
        raise FormatError(f"{where}: a probe needs 'probe_of', the id of its case")
    if isinstance(step, bool) or not isinstance(step, int) or not 0 <= step < 64:
        raise FormatError(f"{where}: 'step' must be an integer in [0, 64), got {step!r}")
    try:
        in_dir = confined_path(folder, e["input"], f"{where}: field 'input'")
        out_dir = confined_path(folder, e["output"], f"{where}: field 'output'")
    except ConfinementError as exc:
        raise FormatError(str(exc)) from None
    digests = e.get("input_sha256")
    if (
        not isinstance(digests, dict)
        or not digests
        or not all(isinstance(k, str) and isinstance(v, str) for k, v in digests.items())
    ):
        raise FormatError(f"{where}: 'input_sha256' must map each input file to its SHA-256")
    used = _Recording(digests)
    case = read_case_input(in_dir, cid, digests=used)
    for name in sorted(set(digests) - used.looked_up):
        # listed but not parsed (case.txt): still verified, confined and bounded, so that a
        # changed kit is refused whole
        try:
            read_confined(
                in_dir, name, f"case {cid}", limit=MAX_INPUT_ARRAY_BYTES, sha256=digests[name]
            )
        except ConfinementError as exc:
            raise FormatError(str(exc)) from None
    if case.case_id != cid:
        raise FormatError(
            f"case {cid}: {os.path.join(in_dir, 'case.json')}: names case {case.case_id!r}"
        )
    return KitCase(
        case,
        e["role"],
        e["mesh"],
        e["state"],
        probe_of=probe_of,
        step=step,
        input_dir=in_dir,
        output_dir=out_dir,
    )


#: The name :class:`Kit` had before it had its own module.
KitManifest = Kit
