"""Node selection by region, for boundary conditions given on the command line.

Specs (coordinates in the mesh's units):

    box:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX     nodes inside the axis-aligned box (bounds included)
    sphere:CX,CY,CZ,R                     nodes within distance R of the centre
    nodes:FILE                            0-based node indices in a text file (whitespace or
                                          comma separated, '#' starts a comment)

Several specs select the union. Every error raises :class:`comparisons.options.InputError`
naming the spec.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from comparisons.options import InputError

__all__ = ["select_nodes", "parse_region", "relative_box"]


def _numbers(spec: str, body: str, count: int) -> np.ndarray:
    try:
        values = np.array([float(v) for v in body.split(",")], dtype=float)
    except ValueError:
        raise InputError(f"region {spec!r}: expected {count} comma-separated numbers") from None
    if len(values) != count or not np.all(np.isfinite(values)):
        raise InputError(f"region {spec!r}: expected {count} finite comma-separated numbers, got {len(values)}")
    return values


def parse_region(spec: str, points: np.ndarray) -> np.ndarray:
    """Indices (k,) of the nodes of ``points`` (n, 3) that one spec selects (may be empty)."""
    kind, sep, body = spec.partition(":")
    kind = kind.strip().lower()
    if not sep or not body.strip():
        raise InputError(f"region {spec!r}: expected box:..., sphere:... or nodes:FILE")
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
    if kind == "nodes":
        path = Path(body.strip())
        if not path.is_file():
            raise InputError(f"region {spec!r}: no such file {path}")
        text = " ".join(line.split("#", 1)[0] for line in path.read_text().splitlines())
        tokens = text.replace(",", " ").split()
        try:
            idx = np.array([int(t) for t in tokens], dtype=np.int64)
        except ValueError:
            raise InputError(f"region {spec!r}: {path} must hold integer node indices") from None
        bad = idx[(idx < 0) | (idx >= len(points))]
        if bad.size:
            raise InputError(f"region {spec!r}: node index {int(bad[0])} outside [0, {len(points)})")
        return np.unique(idx)
    raise InputError(f"region {spec!r}: unknown kind {kind!r}; use box, sphere or nodes")


def select_nodes(specs: Iterable[str], points: np.ndarray, *, what: str = "fixed") -> np.ndarray:
    """The union of the nodes the specs select, sorted; InputError if it is empty."""
    specs = list(specs)
    if not specs:
        raise InputError(f"no {what} region given")
    chosen = np.unique(np.concatenate([parse_region(s, points) for s in specs]))
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
