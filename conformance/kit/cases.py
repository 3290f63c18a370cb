"""The conformance kit: cases (model x mesh x state) plus probes, written to and read from a
directory.

Layout of a kit directory (docs/conventions.md, "Exchange format")::

    manifest.json                      the kit manifest: format, format_version, cases
    cases/<case id>/input/             what the engine reads (case.json, case.txt, arrays)
    cases/<case id>/output/            where the engine writes (force.f64, stiffness..., energy.f64)

Each primary case has PROBES probe cases: the same model and mesh at x + eps_k d with
eps_k = eps_0 / 2^k, d a seeded random direction, eps_0 = 1e-4 of the mean edge length at each
node, or of the smallest height of the node's cells if smaller (:func:`probe_lengths`). The check
uses them for a Taylor test of the engine's stiffness against its own forces (and of its forces
against its own energy), which needs no oracle.

The oracle's reference values are not in the kit: ``check`` recomputes them from the manifest
(the diagnosis needs the oracle anyway, to split its stiffness into parts), so the engine's
author has nothing to read but the inputs. The manifest records a SHA-256 of every input file,
and ``check`` refuses a case whose input was changed after export.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from common.frames import with_default_frame
from common.states import apply_state
from common.tolerances import mean_edge_length
from conformance.kit.confine import (
    MAX_CASE_ID,
    ConfinementError,
    check_case_id,
    confined_path,
    read_confined,
)
from conformance.kit.exchange import (
    FORMAT_VERSION,
    KIT_FORMAT,
    MAX_INPUT_ARRAY_BYTES,
    FormatError,
    check_version,
    load_json,
    read_case_input,
    sha256_of,
    write_case_input,
)
from conformance.kit.spec import CaseInput, model_label

__all__ = [
    "KitCase",
    "PROBES",
    "PROBE_STEP",
    "build_cases",
    "write_kit",
    "read_kit",
    "KitManifest",
    "case_id",
]

PROBES = 4
PROBE_STEP = 1e-4  # eps_0 as a fraction of the mean edge length


@dataclass(frozen=True)
class KitCase:
    """A case of the kit: its input, and where it belongs.

    role: "case" (compared with the oracle) or "probe" (a perturbed state of ``probe_of``).
    """

    input: CaseInput
    role: str
    mesh: str
    state: str
    probe_of: Optional[str] = None
    step: int = 0
    # Where a kit read back keeps this case (confined to the kit): the engine is given exactly
    # the input directory whose hashes were checked, and its output is read from output_dir.
    input_dir: Optional[str] = None
    output_dir: Optional[str] = None

    @property
    def case_id(self) -> str:
        return self.input.case_id


def case_id(model: Any, mesh: str, state: str) -> str:
    raw = f"{model_label(model)}.{os.path.splitext(os.path.basename(mesh))[0]}.{state}"
    # one safe path component (conformance.kit.confine.check_case_id): no '..', no leading dot
    safe = re.sub(r"\.{2,}", ".", re.sub(r"[^A-Za-z0-9_.+-]", "_", raw)).lstrip(".")
    return safe[: MAX_CASE_ID - 8]  # room for a probe's "~probeK"


def probe_direction(points: np.ndarray, seed: int) -> np.ndarray:
    """A seeded random nodal direction (n, 3) scaled to eps_0 = PROBE_STEP x mean edge at its
    largest node.
    """
    rng = np.random.default_rng(seed)
    d = rng.standard_normal(points.shape)
    return d / np.linalg.norm(d, axis=1).max()


StateSpec = Union[str, Tuple[str, Callable[[np.ndarray, np.ndarray], np.ndarray]]]


def probe_lengths(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(n,) per node, the length its probe displacement is a fraction of: the mean edge, or the
    smallest height of the cells around the node when smaller. A step of 1e-4 of the mean edge
    is a strain of 10 % in a cap of quality 1e-3, where no fit can resolve the tangent; scaled
    by each node's own cells, every cell is strained by about 1e-4, the large cells of a graded
    mesh as much as its tiny ones. points (n, 3), cells (m, 4) [length unit of points].
    """
    from meshes.hard import heights

    out = np.full(len(points), mean_edge_length(points, cells))
    h = np.repeat(heights(points, cells), 4)
    np.minimum.at(out, np.asarray(cells).ravel(), h)
    return out


def build_cases(
    models: Sequence[Any],
    meshes: Sequence[Tuple[str, np.ndarray, np.ndarray]],
    states: Sequence[StateSpec],
    *,
    probes: int = PROBES,
) -> List[KitCase]:
    """Every model x mesh x state, each followed by its probes (seeded, reproducible).

    A state is a name of :data:`common.states.STATES` or a pair (name, function(X, cells) -> x).

    A model whose energy needs material directions and has none (Costa without a frame, a user
    energy using I4/I5 without a fibre) is given the mesh's helical frame field
    (:func:`common.frames.with_default_frame`), so that the kit carries a frame that varies
    from cell to cell and an engine that ignores or mis-rotates it fails.
    """
    out: List[KitCase] = []
    named = [
        (s, lambda X, c, s=s: apply_state(s, X, c)) if isinstance(s, str) else s for s in states
    ]
    states = [name for name, _ in named]
    for mesh_label, points, cells in meshes:
        h = probe_lengths(np.asarray(points, dtype=float), np.asarray(cells))[:, None]
        xs = {name: fn(np.asarray(points, dtype=float), np.asarray(cells)) for name, fn in named}
        for given in models:
            model = with_default_frame(given, points, cells)
            for k_state, state in enumerate(states):
                cid = case_id(model, mesh_label, state)
                out.append(
                    KitCase(
                        CaseInput(cid, points, cells, xs[state], model), "case", mesh_label, state
                    )
                )
                d = probe_direction(np.asarray(points), seed=1000 + k_state) * (PROBE_STEP * h)
                for k in range(probes):
                    x = xs[state] + d / 2**k
                    out.append(
                        KitCase(
                            CaseInput(f"{cid}~probe{k}", points, cells, x, model),
                            "probe",
                            mesh_label,
                            state,
                            probe_of=cid,
                            step=k,
                        )
                    )
    ids = [c.case_id for c in out]
    for i in ids:
        check_case_id(i, "case id")
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise ValueError(
            f"two cases share an id ({', '.join(dup[:3])}): give the meshes distinct names"
        )
    return out


#: Created first, exclusively, by an export, and removed when its manifest is written: two
#: exports into one folder cannot interleave (the second is refused by name).
EXPORT_LOCK = ".mjed-verify-export-in-progress"


def write_kit(
    folder: str, cases: Sequence[KitCase], *, command: str = "", precision: str = "double"
) -> Dict[str, Any]:
    """Write the kit into ``folder``, which must not exist or be empty (nothing is overwritten).

    precision: the engine's declared precision, "double" or "single" (float32), kept in the
    manifest; ``check`` then holds every case to that precision's tolerances.

    Raises FileExistsError when the folder is not empty or another export is writing into it.
    """
    if precision not in ("double", "single"):
        raise ValueError(f"precision must be 'double' or 'single', not {precision!r}")
    not_empty = f"{folder}: exists and is not an empty directory; export writes only into a new one"
    if os.path.exists(folder) and (not os.path.isdir(folder) or os.listdir(folder)):
        raise FileExistsError(not_empty)
    os.makedirs(folder, exist_ok=True)
    lock = os.path.join(folder, EXPORT_LOCK)
    try:
        os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        raise FileExistsError(
            f"{folder}: another export is writing into it ({EXPORT_LOCK}); "
            "export into a new directory"
        ) from None
    if os.listdir(folder) != [EXPORT_LOCK]:  # an export finished between the check and the claim
        os.remove(lock)
        raise FileExistsError(not_empty)
    manifest = _write_cases(folder, cases, command, precision)
    os.remove(lock)
    return manifest


def _write_cases(
    folder: str, cases: Sequence[KitCase], command: str, precision: str
) -> Dict[str, Any]:
    entries = []
    for c in cases:
        rel_in = f"cases/{c.case_id}/input"
        rel_out = f"cases/{c.case_id}/output"
        write_case_input(
            os.path.join(folder, rel_in),
            c.input,
            extra={"role": c.role, "mesh": c.mesh, "state": c.state},
        )
        entry = {
            "id": c.case_id,
            "role": c.role,
            "model": model_label(c.input.model),
            "mesh": c.mesh,
            "state": c.state,
            "n_nodes": c.input.n_nodes,
            "n_cells": c.input.n_cells,
            "input": rel_in,
            "output": rel_out,
            "input_sha256": _hashes(os.path.join(folder, rel_in)),
        }
        if c.role == "probe":
            entry.update(probe_of=c.probe_of, step=c.step)
        entries.append(entry)
    manifest = {
        "format": KIT_FORMAT,
        "format_version": FORMAT_VERSION,
        "created_by": command,
        "conventions": "docs/conventions.md",
        "precision": precision,
        "cases": entries,
    }
    with open(os.path.join(folder, "manifest.json"), "w") as fh:
        json.dump(manifest, fh, indent=1, allow_nan=False)  # every value is checked finite
    return manifest


def _hashes(folder: str) -> Dict[str, str]:
    return {f: sha256_of(os.path.join(folder, f)) for f in sorted(os.listdir(folder))}


@dataclass(frozen=True)
class KitManifest:
    """A kit read back: its cases (those that could be read) and one error per unreadable case."""

    folder: str
    cases: Tuple[KitCase, ...]
    entries: Mapping[str, Mapping[str, Any]]
    errors: Mapping[str, str]
    precision: str = "auto"  # declared by the manifest ("double" or "single"), else "auto"


#: All the input arrays of a kit together (each case holds its own copy in memory).
MAX_KIT_BYTES = 4 << 30


def read_kit(folder: str) -> KitManifest:
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
    return KitManifest(folder, tuple(cases), entries, errors, precision)


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


def primary_and_probes(cases: Iterable[KitCase]) -> List[Tuple[KitCase, List[KitCase]]]:
    """Each primary case with its probes in step order."""
    cases = list(cases)
    probes: Dict[str, List[KitCase]] = {}
    for c in cases:
        if c.role == "probe":
            probes.setdefault(c.probe_of or "", []).append(c)
    return [
        (c, sorted(probes.get(c.case_id, []), key=lambda p: p.step))
        for c in cases
        if c.role == "case"
    ]
