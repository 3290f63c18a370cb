"""The exchange format: JSON manifests plus raw little-endian arrays (docs/conventions.md).

An array is one file of raw values, C order, no header; its manifest entry says
``{"file": "points.f64", "dtype": "<f8", "shape": [n, 3]}``. Any language reads it with a
plain binary read (C ``fread``, Julia ``read!``, MATLAB ``fread(fid, inf, 'float64', 'l')``).

A case's **input** directory holds ``case.json`` (the manifest), ``case.txt`` (the same
scalars as ``key value`` lines, for languages without a JSON parser) and the arrays
``points.f64`` (n, 3), ``cells.i64`` (m, 4), ``positions.f64`` (n, 3) and, for Costa with a
frame, ``frame.f64`` ((3, 3) or (m, 3, 3)).

The engine writes into the case's **output** directory (file names fixed, float64 and int64
little-endian, dof = 3 * node + component):

- ``force.f64``: 3n values, f = -dW/dx (required);
- the stiffness K = d2W/dx2 (3n x 3n) in one of three layouts (required):
  COO ``stiffness_rows.i64``, ``stiffness_cols.i64``, ``stiffness_values.f64`` (duplicates
  are summed); CSR ``stiffness_indptr.i64`` (3n + 1), ``stiffness_indices.i64``,
  ``stiffness_values.f64``; or dense ``stiffness.f64`` (9 n^2 values, row-major);
- ``energy.f64``: 1 value, the total strain energy (optional).

An engine that computes in single precision may write its values as little-endian float32
instead, in files ending ``.f32`` (``force.f32``, ``stiffness_values.f32`` or ``stiffness.f32``,
``energy.f32``); the output is then marked single precision and judged as such
(:mod:`conformance.judge.precision`). Arrays written in the wrong byte order, or float32 values in a
``.f64`` file, are refused with the likely cause named.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.kit.confine import ConfinementError, confined_path, read_confined
from conformance.kit.spec import (
    CaseInput,
    SpecError,
    model_frame,
    model_from_manifest,
    model_to_manifest,
)

__all__ = [
    "FORMAT_VERSION",
    "CASE_FORMAT",
    "KIT_FORMAT",
    "FormatError",
    "CaseError",
    "EngineOutput",
    "write_array",
    "read_array",
    "write_case_input",
    "read_case_input",
    "load_json",
    "write_output",
    "read_output",
    "sha256_of",
]

FORMAT_VERSION = 1
CASE_FORMAT = "mjed-verify case"
KIT_FORMAT = "mjed-verify conformance kit"

#: Bounds on what is read from a kit or an engine's output, checked on the file's size before any
#: byte is read (a hostile file must not be able to exhaust memory).
MAX_INPUT_ARRAY_BYTES = 1 << 30  # one input array: 1 GiB, 40 million nodes
MAX_JSON_BYTES = 64 << 20  # a case.json or a kit manifest (about 100 000 cases)
MAX_DENSE_DOFS = 6000  # a dense stiffness of (3n)^2 values: 288 MB at this size; COO or CSR above
#: COO or CSR entries allowed per cell: a cell's 12 x 12 element matrix written up to four times
#: (an engine may write several contributions per cell unassembled; duplicates are summed).
ENTRIES_PER_CELL = 4 * 144

_DTYPES = {"<f8": np.dtype("<f8"), "<i8": np.dtype("<i8"), "<i4": np.dtype("<i4")}
_STIFFNESS_LAYOUTS = {
    "coo": ("stiffness_rows.i64", "stiffness_cols.i64", "stiffness_values.f64"),
    "csr": ("stiffness_indptr.i64", "stiffness_indices.i64", "stiffness_values.f64"),
    "dense": ("stiffness.f64",),
}


class FormatError(ValueError):
    """A file that does not follow the format; the message names the case and the file."""


class CaseError(FormatError):
    """One case could not be evaluated: bad output, a crash or a time limit (message names the
    case).
    """


@dataclass(frozen=True)
class EngineOutput:
    """What an engine returned for one case: force (n, 3), stiffness CSR (3n, 3n), energy or
    None.
    """

    force: np.ndarray
    stiffness: sp.csr_matrix
    energy: Optional[float] = None
    precision: str = "double"  # "single" when the engine wrote float32 (.f32) values


def sha256_of(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_array(folder: str, filename: str, array: np.ndarray, dtype: str) -> Dict[str, Any]:
    """Write ``array`` as raw ``dtype`` (one of '<f8', '<i8', '<i4') and return its entry."""
    a = np.ascontiguousarray(array, dtype=_DTYPES[dtype])
    a.tofile(os.path.join(folder, filename))
    return {"file": filename, "dtype": dtype, "shape": list(a.shape)}


def read_array(
    folder: str, entry: Any, *, what: str, case: str, digests: Optional[Mapping[str, str]] = None
) -> np.ndarray:
    """Read the array of a manifest entry, checking its dtype, shape and file size.

    The file must lie inside ``folder``; its size is compared with the declared shape before a
    byte is read. digests: file name -> SHA-256, when given every file read must be listed and
    match (the kit's ``input_sha256``).
    """
    where = f"case {case}: {os.path.join(folder, 'case.json')}"  # the file that declares it
    if not isinstance(entry, Mapping) or not {"file", "dtype", "shape"} <= set(entry):
        raise FormatError(f"{where}: array entry {what!r} needs 'file', 'dtype' and 'shape'")
    code = entry["dtype"]
    dtype = _DTYPES.get(code) if isinstance(code, str) else None
    if dtype is None:
        raise FormatError(f"{where}: {what}: dtype {code!r} is not one of {', '.join(_DTYPES)}")
    shape = _shape(entry["shape"], what, where)
    count = math.prod(shape)  # Python ints: no silent overflow
    nbytes = count * dtype.itemsize
    if nbytes > MAX_INPUT_ARRAY_BYTES:
        raise FormatError(
            f"{where}: {what}: shape {list(shape)} needs {nbytes} bytes, more "
            f"than the {MAX_INPUT_ARRAY_BYTES} an input array may hold"
        )
    detail = f" ({count} values of {dtype.str} for shape {list(shape)})"
    data = _read_file(
        folder,
        entry["file"],
        f"case {case}",
        expected=nbytes,
        limit=nbytes,
        digests=digests,
        detail=detail,
    )
    return np.frombuffer(data, dtype=dtype).reshape(shape)


def _shape(raw: Any, what: str, where: str) -> Tuple[int, ...]:
    """A declared shape: a list of 1 to 3 non-negative integers (where: the case and its file)."""

    def extent(s: Any) -> bool:
        return isinstance(s, int) and not isinstance(s, bool) and 0 <= s <= 2**40

    if not isinstance(raw, list) or not 1 <= len(raw) <= 3 or not all(extent(s) for s in raw):
        shown = repr(raw) if len(repr(raw)) <= 60 else repr(raw)[:57] + "..."
        raise FormatError(
            f"{where}: {what}: shape must be a list of 1 to 3 non-negative integers, got {shown}"
        )
    return tuple(raw)


def _read_file(
    folder: str,
    name: Any,
    where: str,
    *,
    limit: int,
    expected: Optional[int] = None,
    digests: Optional[Mapping[str, str]] = None,
    detail: str = "",
    missing: str = "",
) -> bytearray:
    """The bytes of ``folder/name``, confined to ``folder``, regular, size-checked before reading;
    with ``digests`` the file must be listed there and its bytes must match.
    """
    digest = None
    if digests is not None:
        if not isinstance(name, str) or name not in digests:
            raise FormatError(
                f"{where}: {os.path.join(folder, str(name))}: not listed in the "
                "kit's input_sha256; every input file read must be hashed"
            )
        digest = digests[name]
    try:
        return read_confined(
            folder, name, where, limit=limit, expected=expected, sha256=digest, missing=missing
        )
    except ConfinementError as exc:
        text = str(exc)
        if expected is not None and text.endswith(f"bytes, expected {expected}"):
            text += detail
        raise FormatError(text) from None


# ------------------------------------------------------------------ case input
def write_case_input(
    folder: str, case: CaseInput, *, extra: Optional[Mapping[str, Any]] = None
) -> Dict[str, Any]:
    """Write a case's input directory (created, must not exist) and return its manifest."""
    os.makedirs(folder)
    arrays = {
        "points": write_array(folder, "points.f64", case.points, "<f8"),
        "cells": write_array(folder, "cells.i64", case.cells, "<i8"),
        "positions": write_array(folder, "positions.f64", case.positions, "<f8"),
    }
    frame = model_frame(case.model)
    if frame is not None:
        arrays["frame"] = write_array(folder, "frame.f64", frame, "<f8")
    manifest = {
        "format": CASE_FORMAT,
        "format_version": FORMAT_VERSION,
        "case": case.case_id,
        "n_nodes": case.n_nodes,
        "n_cells": case.n_cells,
        "model": model_to_manifest(case.model),
        "arrays": arrays,
        **(dict(extra) if extra else {}),
    }
    with open(os.path.join(folder, "case.json"), "w") as fh:
        json.dump(manifest, fh, indent=1, allow_nan=False)  # every value is checked finite
    with open(os.path.join(folder, "case.txt"), "w") as fh:
        fh.write(_case_text(manifest))
    return manifest


def _case_text(manifest: Mapping[str, Any]) -> str:
    """``key value`` lines: everything a C engine needs, no JSON parser required."""
    model = manifest["model"]
    lines = [
        f"format_version {manifest['format_version']}",
        f"case {manifest['case']}",
        f"n_nodes {manifest['n_nodes']}",
        f"n_cells {manifest['n_cells']}",
        f"kind {model['kind']}",
        f"name {model['name']}",
    ]
    if model["kind"] == "energy":
        lines.append(f"expression {model['expression']}")
        if model.get("fibre") is not None:
            lines.append("fibre " + " ".join(repr(float(v)) for v in model["fibre"]))
    lines += [f"parameter {k} {float(v)!r}" for k, v in model["parameters"].items()]
    for name, entry in manifest["arrays"].items():
        lines.append(
            f"array {name} {entry['file']} {entry['dtype']} "
            + " ".join(str(s) for s in entry["shape"])
        )
    return "\n".join(lines) + "\n"


def load_json(
    folder: str,
    name: str,
    case: Optional[str] = None,
    hint: str = "",
    *,
    digests: Optional[Mapping[str, str]] = None,
    limit: int = MAX_JSON_BYTES,
) -> Dict[str, Any]:
    """A JSON object from ``folder/name`` (confined, bounded, strict: no NaN or Infinity, no nesting
    deeper than Python can parse); FormatError naming the case (if any) and the file otherwise.
    """
    path = os.path.join(folder, name)
    where = f"case {case}" if case else "kit"
    raw = _read_file(folder, name, where, limit=limit, digests=digests, missing=hint)
    prefix = (f"case {case}: " if case else "") + path
    try:
        data = json.loads(raw.decode("utf-8"), parse_constant=_no_constant)
    except (json.JSONDecodeError, UnicodeDecodeError, ValueError) as exc:
        raise FormatError(f"{prefix}: malformed JSON ({exc})") from None
    except RecursionError:
        raise FormatError(f"{prefix}: malformed JSON (nested too deeply)") from None
    if not isinstance(data, dict):
        raise FormatError(f"{prefix}: expected a JSON object")
    return data


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON value")


def check_version(data: Mapping[str, Any], path: str, case: str, expected_format: str) -> None:
    if data.get("format") != expected_format:
        raise FormatError(
            f"case {case}: {path}: 'format' must be {expected_format!r}, got {data.get('format')!r}"
        )
    if data.get("format_version") != FORMAT_VERSION:
        raise FormatError(
            f"case {case}: {path}: format_version {data.get('format_version')!r} is not supported "
            f"(this mjed-verify reads version {FORMAT_VERSION})"
        )


def read_case_input(
    folder: str, case: str = "?", *, digests: Optional[Mapping[str, str]] = None
) -> CaseInput:
    """Read back a case input directory (validated).

    digests: the kit's ``input_sha256`` for this case; when given, case.json and every array
    must be listed there, and the bytes read are the bytes hashed.
    """
    path = os.path.join(folder, "case.json")
    data = load_json(folder, "case.json", case, digests=digests)
    check_version(data, path, case, CASE_FORMAT)
    arrays = data.get("arrays")
    if not isinstance(arrays, Mapping):
        raise FormatError(f"case {case}: {path}: 'arrays' missing")
    try:
        for key in ("points", "cells", "positions"):
            if key not in arrays:
                raise FormatError(f"case {case}: {path}: array {key!r} missing")
        pts, cells, x = (
            read_array(folder, arrays[k], what=k, case=case, digests=digests)
            for k in ("points", "cells", "positions")
        )
        frame = (
            read_array(folder, arrays["frame"], what="frame", case=case, digests=digests)
            if "frame" in arrays
            else None
        )
        _check_mesh_arrays(pts, cells, x, path, case)
        model = model_from_manifest(data.get("model"), frame, where=f"case {case}: {path}")
        name = data.get("case", case)
        return CaseInput(name if isinstance(name, str) else repr(name), pts, cells, x, model)
    except (SpecError, ValueError, TypeError, OverflowError, RecursionError) as exc:
        # TypeError and OverflowError: a field of the wrong JSON type or an absurd number
        # reached a constructor; still bad input of this case, not a traceback.
        if isinstance(exc, FormatError):
            raise
        kind = f"{type(exc).__name__}: " if isinstance(exc, (TypeError, RecursionError)) else ""
        raise FormatError(f"case {case}: {path}: {kind}{exc}") from None


def _check_mesh_arrays(
    pts: np.ndarray, cells: np.ndarray, x: np.ndarray, path: str, case: str
) -> None:
    """Node indices within range and finite coordinates, before anything indexes with them."""
    n = pts.shape[0] if pts.ndim == 2 else 0
    if cells.size and (cells.min() < 0 or cells.max() >= n):
        raise FormatError(
            f"case {case}: {path}: cell node indices must lie in [0, {n}), "
            f"found {int(cells.min())}..{int(cells.max())}"
        )
    for name, arr in (("points", pts), ("positions", x)):
        if not np.all(np.isfinite(arr)):
            raise FormatError(f"case {case}: {path}: {name} holds non-finite values (NaN or inf)")


# ------------------------------------------------------------------ engine output
def write_output(
    folder: str,
    force: np.ndarray,
    stiffness,
    energy: Optional[float] = None,
    *,
    layout: str = "coo",
    precision: str = "double",
) -> None:
    """Write an engine's result in the format (for Python engines and the tests); precision
    "single" writes the floating-point arrays as float32 ``.f32`` files.
    """
    if precision not in ("double", "single"):
        raise ValueError(f"precision must be 'double' or 'single', not {precision!r}")
    os.makedirs(folder, exist_ok=True)
    write_array(folder, "force.f64", np.asarray(force).reshape(-1), "<f8")
    if layout == "dense":
        write_array(
            folder,
            "stiffness.f64",
            np.asarray(stiffness.toarray() if sp.issparse(stiffness) else stiffness),
            "<f8",
        )
    elif layout == "coo":
        K = sp.coo_matrix(stiffness)
        for name, arr, dt in (
            ("stiffness_rows.i64", K.row, "<i8"),
            ("stiffness_cols.i64", K.col, "<i8"),
            ("stiffness_values.f64", K.data, "<f8"),
        ):
            write_array(folder, name, arr, dt)
    elif layout == "csr":
        K = sp.csr_matrix(stiffness)
        for name, arr, dt in (
            ("stiffness_indptr.i64", K.indptr, "<i8"),
            ("stiffness_indices.i64", K.indices, "<i8"),
            ("stiffness_values.f64", K.data, "<f8"),
        ):
            write_array(folder, name, arr, dt)
    else:
        raise ValueError(f"unknown stiffness layout {layout!r}; use coo, csr or dense")
    if energy is not None:
        write_array(folder, "energy.f64", np.array([float(energy)]), "<f8")
    if precision == "single":  # the same arrays rounded to float32, under their .f32 names
        for name in sorted(os.listdir(folder)):
            if name.endswith(".f64"):
                path = os.path.join(folder, name)
                np.fromfile(path, dtype="<f8").astype("<f4").tofile(path[:-4] + ".f32")
                os.remove(path)


def read_output(
    folder: str,
    n_nodes: int,
    case: str,
    *,
    n_cells: Optional[int] = None,
    within: Optional[str] = None,
) -> EngineOutput:
    """Read and validate an engine's output for a mesh of ``n_nodes`` nodes (``n_cells`` cells).

    Only regular files inside ``folder`` are read, and each file's size is compared with what the
    mesh allows before it is read: 3n values of force, (3n)^2 of a dense stiffness (for at most
    MAX_DENSE_DOFS dofs), at most ENTRIES_PER_CELL x n_cells COO or CSR entries (without
    ``n_cells``: (3n)^2 entries). within: a directory ``folder`` must lie in once links are
    followed (an engine could replace its output directory by a link elsewhere).

    Raises:
        FormatError naming the case and the file: missing or extra files, a wrong size
        (shape or node count), indices out of range, NaN or infinite values.
    """
    where = f"case {case}"
    if within is not None:
        try:
            confined_path(within, os.path.relpath(folder, within), f"{where}: output directory")
        except ConfinementError as exc:
            raise FormatError(str(exc)) from None
    if not os.path.isdir(folder):
        raise FormatError(f"{where}: {folder}: output directory missing (the engine wrote nothing)")
    N = 3 * n_nodes
    precision = output_precision(folder)
    f64, i64 = np.dtype("<f8" if precision == "double" else "<f4"), np.dtype("<i8")
    fsize = f64.itemsize
    force_name = _value_file("force.f64", precision)
    fpath = os.path.join(folder, force_name)
    # the limit leaves room for a wrong node count, which the message below names
    raw = _read_file(
        folder,
        force_name,
        where,
        limit=2 * fsize * N + 4096,
        missing=f" (force, 3n = {N} {f64.name} values)",
    )
    n_force = _values(raw, fsize, fpath, case)
    if n_force != N:
        hint = f" ({n_force // 3} nodes)" if n_force % 3 == 0 else ""
        if 2 * n_force == N and precision == "double":
            hint += (
                "; that is exactly 3n float32 values: a single-precision engine writes force.f32"
            )
        raise FormatError(
            f"{where}: {fpath}: {n_force} values{hint}, expected 3n = {N} for {n_nodes} nodes"
        )
    force = np.frombuffer(raw, dtype=f64).reshape(n_nodes, 3)
    _require_finite(force, fpath, case)
    force = force.astype(np.float64)

    # lexists: a link or special file in place of a stiffness is named for what it is
    present = [
        k
        for k, files in _STIFFNESS_LAYOUTS.items()
        if os.path.lexists(os.path.join(folder, _value_file(files[0], precision)))
    ]
    if not present:
        raise FormatError(
            f"{where}: {folder}: no stiffness: write stiffness_rows.i64/"
            "stiffness_cols.i64/stiffness_values.f64 (COO), stiffness_indptr.i64/"
            "stiffness_indices.i64/stiffness_values.f64 (CSR) or stiffness.f64 "
            "(dense)"
        )
    if len(present) > 1:
        raise FormatError(
            f"{where}: {folder}: several stiffness layouts present "
            f"({', '.join(present)}); write one"
        )
    layout = present[0]
    names = [_value_file(f, precision) for f in _STIFFNESS_LAYOUTS[layout]]
    paths = [os.path.join(folder, f) for f in names]
    need = f" ({layout} stiffness needs {', '.join(names)})"
    if layout == "dense":
        if N > MAX_DENSE_DOFS:
            raise FormatError(
                f"{where}: {paths[0]}: a dense stiffness of {N} dofs is too large "
                f"to read (at most {MAX_DENSE_DOFS}); write it as COO or CSR"
            )
        raw = _read_file(folder, names[0], where, limit=2 * fsize * N * N + 4096, missing=need)
        count = _values(raw, fsize, paths[0], case)
        if count != N * N:
            raise FormatError(
                f"{where}: {paths[0]}: {count} values, expected (3n)^2 = {N * N} "
                f"for {n_nodes} nodes"
            )
        dense = np.frombuffer(raw, dtype=f64).reshape(N, N)
        _require_finite(dense, paths[0], case)
        K = sp.csr_matrix(dense.astype(np.float64))
    else:
        max_nnz = N * N if n_cells is None else min(4 * N * N, ENTRIES_PER_CELL * max(n_cells, 1))
        limits = (8 * (N + 1) if layout == "csr" else 8 * max_nnz, 8 * max_nnz, fsize * max_nnz)
        arrays = []
        for name, path, limit, dt in zip(names, paths, limits, (i64, i64, f64)):
            raw = _sparse_file(folder, name, where, limit, max_nnz, layout, need)
            _values(raw, dt.itemsize, path, case)
            arrays.append(np.frombuffer(raw, dtype=dt))
        a, b, vals = arrays
        _require_finite(vals, paths[2], case)
        vals = vals.astype(np.float64)
        if layout == "coo":
            if not (a.size == b.size == vals.size):
                raise FormatError(
                    f"{where}: {folder}: COO arrays differ in length (rows {a.size}, "
                    f"cols {b.size}, values {vals.size})"
                )
            for arr, p in ((a, paths[0]), (b, paths[1])):
                _require_indices(arr, N, p, case)
            K = sp.coo_matrix((vals, (a, b)), shape=(N, N)).tocsr()
        else:
            if (
                a.size != N + 1
                or a[0] != 0
                or np.any(np.diff(a) < 0)
                or a[-1] != b.size
                or b.size != vals.size
            ):
                raise FormatError(
                    f"{where}: {paths[0]}: not a CSR row pointer of {N} rows for "
                    f"{b.size} column indices and {vals.size} values"
                )
            _require_indices(b, N, paths[1], case)
            K = sp.csr_matrix((vals, b, a), shape=(N, N))
            K.sum_duplicates()
    energy = None
    energy_name = _value_file("energy.f64", precision)
    epath = os.path.join(folder, energy_name)
    if os.path.lexists(epath):
        raw = _read_file(folder, energy_name, where, limit=64)
        if _values(raw, fsize, epath, case) != 1:
            raise FormatError(f"{where}: {epath}: expected exactly one {f64.name} value")
        e = np.frombuffer(raw, dtype=f64)
        _require_finite(e, epath, case)
        energy = float(e[0])
    return EngineOutput(force, sp.csr_matrix(K), energy, precision)


def _sparse_file(
    folder: str, name: str, where: str, limit: int, max_nnz: int, layout: str, need: str
) -> bytearray:
    try:
        return _read_file(folder, name, where, limit=limit, missing=need)
    except FormatError as exc:
        if "more than the" in str(exc):  # say where the limit comes from
            raise FormatError(
                f"{exc}: at most {max_nnz} {layout} entries are read for this mesh "
                f"({ENTRIES_PER_CELL} per cell)"
            ) from None
        raise


def _values(raw, itemsize: int, path: str, case: str) -> int:
    size = len(raw)
    if size % itemsize:
        raise FormatError(
            f"case {case}: {path}: {size} bytes is not a whole number of {itemsize}-byte values"
        )
    return size // itemsize


def _require_finite(a: np.ndarray, path: str, case: str) -> None:
    swapped = byte_order_problem(a, path)
    if swapped:
        raise FormatError(f"case {case}: {swapped}")
    bad = ~np.isfinite(a)
    if bad.any():
        first = int(np.flatnonzero(bad.ravel())[0])
        raise FormatError(
            f"case {case}: {path}: {int(bad.sum())} non-finite value(s) (NaN or inf), first at "
            f"flat index {first}"
        )


def _require_indices(idx: np.ndarray, N: int, path: str, case: str) -> None:
    if idx.size and (idx.min() < 0 or idx.max() >= N):
        swapped = idx.byteswap()
        if swapped.min() >= 0 and swapped.max() < N:
            raise FormatError(
                f"case {case}: {path}: indices out of range as little-endian int64 but all in "
                f"[0, {N}) with their bytes reversed: written big-endian (the format is "
                "little-endian '<i8'; e.g. a big-endian machine, Java's DataOutputStream or "
                "NumPy '>i8')"
            )
        raise FormatError(
            f"case {case}: {path}: indices must lie in [0, {N}) (0-based dofs 3*node+component), "
            f"found {int(idx.min())}..{int(idx.max())}"
        )


def output_precision(folder: str) -> str:
    """The output's precision: "single" when the engine wrote its force as float32 (``force.f32``),
    else "double".
    """
    return (
        "single"
        if os.path.lexists(os.path.join(folder, "force.f32"))
        and not os.path.lexists(os.path.join(folder, "force.f64"))
        else "double"
    )


def _value_file(name: str, precision: str) -> str:
    """The file of a floating-point array at the output's precision (index files keep .i64)."""
    return name[:-4] + ".f32" if precision == "single" and name.endswith(".f64") else name


def _plausible(a: np.ndarray) -> float:
    """Fraction of the non-zero values that are finite and within 1e-100..1e100 in magnitude."""
    nz = a[a != 0]
    if nz.size == 0:
        return 1.0
    with np.errstate(all="ignore"):
        m = np.abs(nz)
        return float(np.mean(np.isfinite(m) & (m > 1e-100) & (m < 1e100)))


def byte_order_problem(a: np.ndarray, path: str) -> str:
    """Words naming a byte-order mistake when ``a`` (read little-endian) looks like big-endian
    floats: implausible as read (NaN, inf, 1e-300 or 1e300 magnitudes), plausible with its bytes
    reversed. "" otherwise. a: any float array as read from ``path``.
    """
    if a.size == 0 or _plausible(a) > 0.9:
        return ""
    if _plausible(a.byteswap()) < 0.999:
        return ""
    return (
        f"{path}: the values are implausible as little-endian {a.dtype.name} (NaN, inf or "
        "magnitudes beyond 1e+-100) and plausible with their bytes reversed: written big-endian "
        "(the format is little-endian; e.g. a big-endian machine, Java's DataOutputStream, "
        "MATLAB fwrite with 'b', or NumPy '>f8')"
    )
