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

from common.states import apply_state
from common.tolerances import mean_edge_length
from conformance.exchange import (
    FORMAT_VERSION,
    KIT_FORMAT,
    FormatError,
    check_version,
    load_json,
    read_case_input,
    sha256_of,
    write_case_input,
)
from conformance.spec import CaseInput, model_label

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

    @property
    def case_id(self) -> str:
        return self.input.case_id


def case_id(model: Any, mesh: str, state: str) -> str:
    raw = f"{model_label(model)}.{os.path.splitext(os.path.basename(mesh))[0]}.{state}"
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", raw)


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
    """
    out: List[KitCase] = []
    named = [
        (s, lambda X, c, s=s: apply_state(s, X, c)) if isinstance(s, str) else s for s in states
    ]
    states = [name for name, _ in named]
    for mesh_label, points, cells in meshes:
        h = probe_lengths(np.asarray(points, dtype=float), np.asarray(cells))[:, None]
        xs = {name: fn(np.asarray(points, dtype=float), np.asarray(cells)) for name, fn in named}
        for model in models:
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
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise ValueError(
            f"two cases share an id ({', '.join(dup[:3])}): give the meshes distinct names"
        )
    return out


def write_kit(
    folder: str, cases: Sequence[KitCase], *, command: str = "", precision: str = "double"
) -> Dict[str, Any]:
    """Write the kit into ``folder``, which must not exist or be empty (nothing is overwritten).

    precision: the engine's declared precision, "double" or "single" (float32), kept in the
    manifest; ``check`` then holds every case to that precision's tolerances.
    """
    if precision not in ("double", "single"):
        raise ValueError(f"precision must be 'double' or 'single', not {precision!r}")
    if os.path.exists(folder) and (not os.path.isdir(folder) or os.listdir(folder)):
        raise FileExistsError(
            f"{folder}: exists and is not an empty directory; export writes only into a new one"
        )
    os.makedirs(folder, exist_ok=True)
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
        json.dump(manifest, fh, indent=1)
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


def read_kit(folder: str) -> KitManifest:
    """Read a kit; a bad case becomes an entry of ``errors`` (case id -> message), the others are
    kept.

    Raises:
        FormatError: the kit manifest itself is missing or malformed (then nothing can run).
    """
    path = os.path.join(folder, "manifest.json")
    data = load_json(path, hint=f" (is {folder} a kit written by mjed-verify export?)")
    check_version(data, path, "(kit)", KIT_FORMAT)
    raw = data.get("cases")
    if not isinstance(raw, list) or not raw:
        raise FormatError(f"{path}: 'cases' must be a non-empty list")
    cases, entries, errors = [], {}, {}
    for i, e in enumerate(raw):
        if not isinstance(e, dict) or not isinstance(e.get("id"), str):
            errors[f"#{i}"] = f"case #{i} of {path}: entry without an 'id'"
            continue
        cid = e["id"]
        entries[cid] = e
        try:
            cases.append(_read_entry(folder, e, path))
        except FormatError as exc:
            errors[cid] = str(exc)
    precision = data.get("precision", "auto")
    if precision not in ("double", "single", "auto"):
        raise FormatError(f"{path}: 'precision' must be 'double' or 'single', not {precision!r}")
    return KitManifest(folder, tuple(cases), entries, errors, precision)


def _read_entry(folder: str, e: Mapping[str, Any], manifest_path: str) -> KitCase:
    cid = e["id"]
    for key in ("role", "input", "output", "mesh", "state"):
        if not isinstance(e.get(key), str):
            raise FormatError(f"case {cid}: {manifest_path}: field {key!r} missing or not a string")
    if e["role"] not in ("case", "probe"):
        raise FormatError(
            f"case {cid}: {manifest_path}: role must be 'case' or 'probe', not {e['role']!r}"
        )
    in_dir = os.path.join(folder, e["input"])
    for name, digest in dict(e.get("input_sha256") or {}).items():
        p = os.path.join(in_dir, name)
        if not os.path.isfile(p):
            raise FormatError(f"case {cid}: {p}: file missing")
        if sha256_of(p) != digest:
            raise FormatError(
                f"case {cid}: {p}: changed since export (SHA-256 differs); re-export the kit"
            )
    case = read_case_input(in_dir, cid)
    if case.case_id != cid:
        raise FormatError(
            f"case {cid}: {os.path.join(in_dir, 'case.json')}: names case {case.case_id!r}"
        )
    return KitCase(
        case,
        e["role"],
        e["mesh"],
        e["state"],
        probe_of=e.get("probe_of"),
        step=int(e.get("step", 0)),
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
