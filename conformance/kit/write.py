"""Writing a kit: its cases' inputs and the manifest that lists them, hashed.

Layout of a kit directory (docs/conventions.md, "Exchange format")::

    manifest.json                      the kit manifest: format, format_version, cases
    cases/<case id>/input/             what the engine reads (case.json, case.txt, arrays)
    cases/<case id>/output/            where the engine writes (force.f64, stiffness..., energy.f64)

The oracle's reference values are not in the kit: ``check`` recomputes them from the manifest
(the diagnosis needs the oracle anyway, to split its stiffness into parts), so the engine's
author has nothing to read but the inputs. The manifest records a SHA-256 of every input file,
and ``check`` refuses a case whose input was changed after export.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Sequence

from conformance.kit.cases import KitCase
from conformance.kit.exchange import FORMAT_VERSION, KIT_FORMAT, sha256_of, write_case_input
from conformance.kit.spec import model_label

__all__ = ["EXPORT_LOCK", "write_kit"]


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
