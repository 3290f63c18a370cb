"""Node selection by region, for boundary conditions given on the command line.

Specs (coordinates in the mesh file's own units, before any --units/--scale)::

    box:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX     nodes inside the axis-aligned box (bounds included)
    sphere:CX,CY,CZ,R                     nodes within distance R of the centre
    nodes:FILE                            node ids in the mesh's own numbering, as the file
                                          that defines the mesh writes them: gmsh node
                                          numbers, Abaqus labels, Medit's 1-based order, VTK's
                                          0-based order; for the built-in meshes, 0-based
    index:FILE                            0-based positions in the order the nodes are read,
                                          whatever the format

FILE holds integers separated by whitespace or commas; '#' starts a comment.

Several specs select the union. Every error raises :class:`common.options.InputError`
naming the spec.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Optional

import numpy as np

from common.options import InputError

__all__ = ["select_nodes", "parse_region", "relative_box"]


def _numbers(spec: str, body: str, count: int) -> np.ndarray:
    try:
        values = np.array([float(v) for v in body.split(",")], dtype=float)
    except ValueError:
        raise InputError(f"region {spec!r}: expected {count} comma-separated numbers") from None
    if len(values) != count or not np.all(np.isfinite(values)):
        raise InputError(
            f"region {spec!r}: expected {count} finite comma-separated numbers, got {len(values)}"
        )
    return values


def parse_region(
    spec: str,
    points: np.ndarray,
    node_ids: Optional[np.ndarray] = None,
    numbering: str = "0-based positions",
) -> np.ndarray:
    """Positions (k,) of the nodes of ``points`` (n, 3) that one spec selects (may be empty).

    node_ids: (n,) the id of each node in the mesh's own numbering (default 0..n-1), which
    ``nodes:FILE`` refers to; numbering: what those ids are, for messages.
    """
    kind, sep, body = spec.partition(":")
    kind = kind.strip().lower()
    if not sep or not body.strip():
        raise InputError(f"region {spec!r}: expected box:..., sphere:..., nodes:FILE or index:FILE")
    if kind == "box":
        b = _numbers(spec, body, 6)
        lo, hi = b[:3], b[3:]
        if np.any(lo > hi):
            raise InputError(f"region {spec!r}: each minimum must be <= its maximum")
        return np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
    if kind == "sphere":
        c = _numbers(spec, body, 4)
        if c[3] <= 0:
            raise InputError(f"region {spec!r}: the radius must be > 0")
        return np.flatnonzero(np.linalg.norm(points - c[:3], axis=1) <= c[3])
    if kind in ("nodes", "index"):
        idx = _integers(spec, Path(body.strip()))
        if kind == "index" or node_ids is None:
            bad = idx[(idx < 0) | (idx >= len(points))]
            if bad.size:
                raise InputError(
                    f"region {spec!r}: node index {int(bad[0])} outside [0, {len(points)}) "
                    "(index:FILE takes 0-based positions)"
                )
            return np.unique(idx)
        ids = np.asarray(node_ids, dtype=np.int64)
        order = np.argsort(ids, kind="stable")
        at = np.clip(np.searchsorted(ids[order], idx), 0, len(ids) - 1)
        missing = ids[order][at] != idx
        if missing.any():
            raise InputError(
                f"region {spec!r}: node id {int(idx[missing][0])} is not in the mesh ({numbering}: "
                f"{int(ids.min())} to {int(ids.max())}; index:FILE takes 0-based positions)"
            )
        return np.unique(order[at])
    raise InputError(f"region {spec!r}: unknown kind {kind!r}; use box, sphere, nodes or index")


#: A node-number file larger than this is not a list of node numbers someone wrote.
MAX_NODE_FILE_BYTES = 64 << 20


def _integers(spec: str, path: Path) -> np.ndarray:
    if not path.is_file():
        raise InputError(f"region {spec!r}: no such file {path}")
    if path.stat().st_size > MAX_NODE_FILE_BYTES:
        raise InputError(
            f"region {spec!r}: {path} is {path.stat().st_size} bytes, more than the "
            f"{MAX_NODE_FILE_BYTES} a file of node numbers may hold"
        )
    try:
        raw = path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError) as exc:
        why = "not a text file" if isinstance(exc, UnicodeDecodeError) else exc.strerror or str(exc)
        raise InputError(
            f"region {spec!r}: {path}: {why}; expected node numbers as text, "
            "separated by spaces, commas or new lines ('#' starts a comment)"
        ) from None
    text = " ".join(line.split("#", 1)[0] for line in raw.splitlines())
    try:
        values = [int(t) for t in text.replace(",", " ").split()]
    except ValueError:
        raise InputError(f"region {spec!r}: {path} must hold integer node numbers") from None
    big = [v for v in values if not -(2**63) <= v < 2**63]
    if big:  # would overflow int64 (np.array raises OverflowError without naming the file)
        raise InputError(
            f"region {spec!r}: {path}: node number {big[0]} is too large to be a node of any mesh"
        )
    return np.array(values, dtype=np.int64)


def select_nodes(
    specs: Iterable[str],
    points: np.ndarray,
    *,
    what: str = "fixed",
    node_ids: Optional[np.ndarray] = None,
    numbering: str = "0-based positions",
) -> np.ndarray:
    """The union of the nodes the specs select (positions, sorted); InputError if it is empty."""
    specs = list(specs)
    if not specs:
        raise InputError(f"no {what} region given")
    chosen = np.unique(
        np.concatenate([parse_region(s, points, node_ids, numbering) for s in specs])
    )
    if chosen.size == 0:
        lo, hi = points.min(axis=0), points.max(axis=0)
        raise InputError(
            f"the {what} region(s) {specs} select no node; the mesh spans "
            f"{np.round(lo, 6).tolist()} to {np.round(hi, 6).tolist()}"
        )
    return chosen.astype(np.int64)


def relative_box(points: np.ndarray, lo_fraction, hi_fraction) -> str:
    """A box spec from fractions (3,) of the mesh's bounding box, e.g. (0, 0, 0.9), (1, 1, 1)."""
    pmin, pmax = points.min(axis=0), points.max(axis=0)
    lo = pmin + np.asarray(lo_fraction) * (pmax - pmin)
    hi = pmin + np.asarray(hi_fraction) * (pmax - pmin)
    return "box:" + ",".join(f"{v:.9g}" for v in (*lo, *hi))
