"""gmsh ASCII meshes: the legacy format 1.0 ($NOD/$ELM), 2.2 and 4.1, node tags kept.

Legacy 1.0 (gmsh's first format, still what SOFA's example meshes use)::

    $NOD
    number-of-nodes
    node-number x y z            (one line per node)
    $ENDNOD
    $ELM
    number-of-elements
    elm-number elm-type reg-phys reg-elem number-of-nodes node-number-list
    $ENDELM

2.2: ``$Nodes`` as $NOD; ``$Elements`` lines are
``elm-number elm-type number-of-tags tag... node-number-list``.
4.1: node and element blocks per entity: ``$Nodes`` starts with
``numEntityBlocks numNodes minTag maxTag``, then per block ``dim tag parametric numNodes``,
the numNodes tags, then numNodes coordinate lines; ``$Elements`` per block
``dim tag elementType numElements`` then ``elementTag node...`` lines.

Binary files are not read here (``is_ascii`` tells; meshes.io passes them to meshio).
"""

from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np

from meshes.errors import MeshReadError
from meshes.formats.raw import RawMesh

__all__ = ["read_gmsh_ascii", "gmsh_version", "write_gmsh_legacy", "GMSH_TYPES"]

#: gmsh element type -> (meshio name, nodes per element).
GMSH_TYPES: Dict[int, Tuple[str, int]] = {
    1: ("line", 2),
    2: ("triangle", 3),
    3: ("quad", 4),
    4: ("tetra", 4),
    5: ("hexahedron", 8),
    6: ("wedge", 6),
    7: ("pyramid", 5),
    8: ("line3", 3),
    9: ("triangle6", 6),
    10: ("quad9", 9),
    11: ("tetra10", 10),
    12: ("hexahedron27", 27),
    13: ("wedge18", 18),
    14: ("pyramid14", 14),
    15: ("vertex", 1),
    16: ("quad8", 8),
    17: ("hexahedron20", 20),
    18: ("wedge15", 15),
    19: ("pyramid13", 13),
    29: ("tetra20", 20),
}


def _type_name(code: int) -> str:
    return GMSH_TYPES.get(code, (f"gmsh element type {code}", 0))[0]


def gmsh_version(path: Path) -> Tuple[str, bool]:
    """("1.0" | "2.2" | "4.1" | other, is_ascii) from the file's header."""
    with open(path, "rb") as fh:
        first = fh.readline().strip()
        if first == b"$NOD":
            return "1.0", True
        if first != b"$MeshFormat":
            raise MeshReadError(
                f"{path}: cannot be read as a gmsh file (first line {first[:40]!r}, expected "
                "$MeshFormat or $NOD)"
            )
        fields = fh.readline().split()
    if len(fields) < 2:
        raise MeshReadError(f"{path}: unreadable $MeshFormat line")
    return fields[0].decode("ascii", "replace"), fields[1] == b"0"


def _sections(path: Path) -> Dict[str, List[str]]:
    """Section name (without $) -> its lines, for the first occurrence of each."""
    out: Dict[str, List[str]] = {}
    name, body = None, []
    with open(path, "r", encoding="ascii", errors="replace") as fh:
        for raw in fh:
            line = raw.strip()
            if line.startswith("$"):
                tag = line[1:]
                if name is None:
                    name, body = tag, []
                elif tag.upper() in ("END" + name.upper(),):
                    out.setdefault(name.upper(), body)
                    name = None
                continue
            if name is not None:
                body.append(line)
    if name is not None:
        raise MeshReadError(f"{path}: section ${name} is not closed (the file is truncated?)")
    return out


#: Node and element numbers are kept as int64: a larger one is refused by name, not overflowed.
_INT64 = 2**63


def _in_int64(path: Path, values: List[int], what: str) -> List[int]:
    big = [v for v in values if not -_INT64 <= v < _INT64]
    if big:
        raise MeshReadError(
            f"{path}: number {big[0]} in the {what} is too large for a node or element number"
        )
    return values


def _int_rows(path: Path, lines: List[str], what: str) -> List[List[int]]:
    try:
        rows = [[int(v) for v in line.split()] for line in lines if line]
    except ValueError:
        raise MeshReadError(f"{path}: non-integer entry in the {what}") from None
    for row in rows:
        _in_int64(path, row, what)
    return rows


def _count(path: Path, lines: List[str], what: str) -> int:
    if not lines:
        raise MeshReadError(f"{path}: the {what} section is empty")
    try:
        n = int(lines[0].split()[0])
    except (ValueError, IndexError):
        raise MeshReadError(f"{path}: the {what} section does not start with a count") from None
    if n < 0:
        raise MeshReadError(f"{path}: the {what} section announces a negative count ({n})")
    return n


def _flat_nodes(path: Path, lines: List[str], section: str) -> Tuple[np.ndarray, np.ndarray]:
    """Node sections of 1.0 and 2.2: a count, then "id x y z" lines."""
    n = _count(path, lines, section)
    rows = lines[1 : 1 + n]
    if len(rows) != n:
        raise MeshReadError(f"{path}: ${section} announces {n} nodes but holds {len(rows)}")
    try:
        table = np.array([r.split()[:4] for r in rows], dtype=float)
    except ValueError:
        raise MeshReadError(f"{path}: a ${section} line is not 'id x y z'") from None
    if table.shape != (n, 4) or not np.array_equal(table[:, 0], np.round(table[:, 0])):
        raise MeshReadError(f"{path}: a ${section} line is not 'id x y z'")
    if n and not (np.abs(table[:, 0]) < _INT64).all():  # the cast below would wrap silently
        raise MeshReadError(f"{path}: a node id of ${section} is too large for a node number")
    return table[:, 0].astype(np.int64), table[:, 1:4].copy()


def _group(path: Path, entries: List[Tuple[int, List[int]]]) -> List[Tuple[str, np.ndarray]]:
    """(type code, node ids) per element -> blocks of one type, first-appearance order."""
    by_type: Dict[int, List[List[int]]] = {}
    for code, nodes in entries:
        expected = GMSH_TYPES.get(code, (None, len(nodes)))[1]
        if len(nodes) != expected:
            raise MeshReadError(
                f"{path}: an element of type {code} ({_type_name(code)}) has {len(nodes)} nodes, "
                f"expected {expected}"
            )
        by_type.setdefault(code, []).append(nodes)
    return [
        (_type_name(code), np.array(rows, dtype=np.int64).reshape(len(rows), -1))
        for code, rows in by_type.items()
    ]


def _legacy_or_22(path: Path, version: str) -> RawMesh:
    sec = _sections(path)
    node_key, elem_key = ("NOD", "ELM") if version == "1.0" else ("NODES", "ELEMENTS")
    if node_key not in sec or elem_key not in sec:
        raise MeshReadError(f"{path}: gmsh {version} file without its node and element sections")
    ids, points = _flat_nodes(path, sec[node_key], node_key)
    lines = sec[elem_key]
    m = _count(path, lines, elem_key)
    rows = _int_rows(path, lines[1 : 1 + m], f"${elem_key} section")
    if len(rows) != m:
        raise MeshReadError(f"{path}: ${elem_key} announces {m} elements but holds {len(rows)}")
    entries = []
    for k, r in enumerate(rows):
        if version == "1.0":  # number type phys elem n nodes...
            if len(r) < 5 or len(r) != 5 + r[4]:
                raise MeshReadError(
                    f"{path}: element line {k + 1} of $ELM does not match its node count"
                )
            entries.append((r[1], r[5:]))
        else:  # number type ntags tags... nodes...
            if len(r) < 3 or len(r) < 3 + r[2]:
                raise MeshReadError(f"{path}: element line {k + 1} of $Elements is too short")
            entries.append((r[1], r[3 + r[2] :]))
    return RawMesh(points, ids, "gmsh node numbers", _group(path, entries))


def _v41(path: Path) -> RawMesh:
    sec = _sections(path)
    if "NODES" not in sec or "ELEMENTS" not in sec:
        raise MeshReadError(f"{path}: gmsh 4.1 file without $Nodes and $Elements sections")
    lines = [ln for ln in sec["NODES"] if ln]
    try:
        n_blocks = int(lines[0].split()[0])
        pos, ids, coords = 1, [], []
        for _ in range(n_blocks):
            _, _, parametric, count = (int(v) for v in lines[pos].split()[:4])
            if count < 0:
                raise ValueError("negative count")
            ids += _in_int64(path, [int(v) for v in lines[pos + 1 : pos + 1 + count]], "$Nodes")
            coords += [ln.split()[:3] for ln in lines[pos + 1 + count : pos + 1 + 2 * count]]
            pos += 1 + 2 * count
        lines = [ln for ln in sec["ELEMENTS"] if ln]
        n_blocks = int(lines[0].split()[0])
        pos, entries = 1, []
        for _ in range(n_blocks):
            _, _, code, count = (int(v) for v in lines[pos].split()[:4])
            if count < 0:
                raise ValueError("negative count")
            entries += [
                (code, _in_int64(path, [int(v) for v in ln.split()[1:]], "$Elements"))
                for ln in lines[pos + 1 : pos + 1 + count]
            ]
            pos += 1 + count
        points = np.array(coords, dtype=float).reshape(-1, 3)
    except (ValueError, IndexError):
        raise MeshReadError(f"{path}: malformed gmsh 4.1 $Nodes or $Elements section") from None
    return RawMesh(points, np.array(ids, dtype=np.int64), "gmsh node tags", _group(path, entries))


def read_gmsh_ascii(path: Path) -> RawMesh:
    """Nodes (with their tags) and element blocks of an ASCII gmsh 1.0, 2.x or 4.1 file."""
    version, ascii_ = gmsh_version(path)
    if not ascii_:
        raise MeshReadError(f"{path}: binary gmsh file (read through meshio instead)")
    if version == "1.0" or version.startswith("2."):
        return _legacy_or_22(path, version)
    if version.startswith("4.1"):
        return _v41(path)
    raise MeshReadError(f"{path}: gmsh format {version} is not supported (1.0, 2.2 and 4.1 are)")


def write_gmsh_legacy(
    path, points: np.ndarray, cells: np.ndarray, node_ids=None, triangles=None
) -> Path:
    """Write tetrahedra (and optional boundary triangles) in gmsh's legacy 1.0 format.

    points (n, 3); cells (m, 4) and triangles (k, 3) as 0-based indices into points;
    node_ids (n,) the numbers written for the nodes (default 1..n). Coordinates with 17
    significant digits, so that reading back is exact.
    """
    path = Path(path)
    pts = np.asarray(points, dtype=float)
    ids = np.arange(1, len(pts) + 1) if node_ids is None else np.asarray(node_ids, dtype=np.int64)
    blocks = [(2, np.asarray(triangles, dtype=np.int64))] if triangles is not None else []
    blocks.append((4, np.asarray(cells, dtype=np.int64)))
    lines = ["$NOD", str(len(pts))]
    lines += [f"{i} {x!r} {y!r} {z!r}" for i, (x, y, z) in zip(ids.tolist(), pts.tolist())]
    lines += ["$ENDNOD", "$ELM", str(sum(len(b) for _, b in blocks))]
    k = 0
    for code, block in blocks:
        for row in ids[block].tolist():
            k += 1
            lines.append(f"{k} {code} 1 1 {len(row)} " + " ".join(map(str, row)))
    lines.append("$ENDELM")
    path.write_text("\n".join(lines) + "\n")
    return path
