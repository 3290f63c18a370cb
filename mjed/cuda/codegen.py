"""The CUDA target of the MJED kernel generator: one GPU thread per cell, FP64 or FP32.

The cell body (kinematics, every term, the group aggregates, the gradient, the six edge
blocks) is written by the same generator as the CPU kernels (:mod:`mjed.compiled.codegen`);
this target only says how a cell's results leave it and writes the module around the body:

- energy: each thread writes its cell's V0 W into E_out[e] (summed afterwards);
- force: ``cuda.atomic.add`` of -V0 dW/dx_a into the nodal force (cells sharing a node run
  at the same time);
- two kernels: ``mjed_cells`` (everything) and ``mjed_force`` (the same without the
  stiffness code, for calls that want no stiffness: a kernel is given the registers of its
  largest path, and the stiffness path needs 1.3 to 3.3 times those of the force path);
- stiffness: each block goes straight into the CSR data array, at positions read from the
  per-cell block map ``blk`` (m, 16) computed once per mesh (block (a, b) of cell e starts at
  blk[e, 4 a + b], its row r at r * rowlen[node a] further; :func:`block_map`): the edge
  block K_ab, its transpose K_ba and the node blocks K_aa = -sum_b K_ab, 144 atomic adds per
  cell. No pass over mesh edges, no per-edge scratch. That is the default
  (:attr:`Assembly.ATOMIC`); with :attr:`Assembly.ELEMENT`, chosen when the kernel is
  generated, each cell instead stores its 144 entries with plain stores into a per-cell
  array ``data`` (144, m), entry 9 (4 a + b) + 3 r + c of block (a, b) at [entry, e] (one
  row per entry, so that consecutive threads write consecutive addresses), and a second,
  fixed kernel (:mod:`mjed.cuda.kernels`, ``gather_blocks``) sums them into the CSR values,
  one thread per 3x3 block of the pattern, from the incidence of :func:`element_incidence`.
  With :attr:`Assembly.EDGE`, each cell stores only its six edge blocks K_ab (a < b, in the
  order of EDGES), 54 values, into ``data`` (54, m), entry (r, c) of edge k at row
  9 k + 3 r + c, column e; the gather (``gather_edge_blocks``) rebuilds the rest from the
  incidence of :func:`edge_incidence`: block (b, a) is K_ab^T and the node blocks
  K_aa = -sum_b K_ab. The force stays atomic in all three (12 adds per cell).

The compiled helpers of the CPU kernels (the Jacobi eigen-decomposition of C, the divided
differences of Ogden's tangent: :data:`mjed.compiled.kernels.DEVICE_HELPERS`) are compiled
again from their own Python source as device functions, so both targets run one
implementation.

FP32: every floating literal of the generated source becomes ``f32(literal)`` and every
``math.*`` call a device function that rounds to float32, so that no operation is promoted
to double (Numba types a Python float literal as float64). On a GPU these casts are no-ops
(libdevice's single-precision functions already return float32); under Numba's CUDA
simulator, which runs the kernel as Python on NumPy scalars, they make the arithmetic
float32 too, so the simulator's FP32 errors are those of single precision.

Pure Python; the generated module imports numba.cuda when it is loaded.
"""

from __future__ import annotations

import ast
import enum
import inspect
import re
import textwrap
from dataclasses import dataclass

import numpy as np

from mjed.compiled.codegen import CELL_INPUTS, EDGES, PAIRS6, Source, Target, node_block_sum

__all__ = [
    "Assembly",
    "BLOCK_ENTRIES",
    "CudaTarget",
    "EDGE_ENTRIES",
    "EdgeIncidence",
    "ElementIncidence",
    "CUDA_ASSEMBLY_ARGS",
    "CUDA_SIGNATURE",
    "add_block",
    "block_map",
    "edge_incidence",
    "element_incidence",
    "store_block",
    "store_edge_block",
    "fp32_source",
    "row_lengths",
    "write_cuda_module",
]

#: What every CUDA cell kernel (MJED's and the classical element's) takes after its own
#: inputs, in the launch order of mjed.cuda.launch.CellLauncher: the block map, the row
#: lengths, the outputs (force, CSR values) and the per-cell J and energy.
CUDA_ASSEMBLY_ARGS = ("blk", "rowlen", "force", "data", "J_out", "E_out")

#: The arguments of the generated CUDA ``mjed_cells``, in order.
CUDA_SIGNATURE = CELL_INPUTS + CUDA_ASSEMBLY_ARGS + ("stress_out",)

#: Stiffness entries one cell forms: 16 node blocks of 3 x 3.
BLOCK_ENTRIES = 144

#: Stiffness entries one cell stores with :attr:`Assembly.EDGE`: six edge blocks of 3 x 3.
EDGE_ENTRIES = 54


class Assembly(enum.Enum):
    """How a cell's stiffness leaves it, chosen when the CUDA kernel is generated:

    ATOMIC: each entry added by ``cuda.atomic.add`` into the CSR values (144 per cell);
    ELEMENT: each entry stored into the per-cell array ``data`` (144, m), gathered into the
    CSR values by a second kernel (see the module docstring);
    EDGE: only the six edge blocks stored, into ``data`` (54, m), the transposes and node
    blocks formed by the gather kernel.
    """

    ATOMIC = "atomic"
    ELEMENT = "element"
    EDGE = "edge"

    @property
    def entries(self) -> int:
        """Values a cell stores per cell (the rows of ``data``); 0 for ATOMIC."""
        return {"atomic": 0, "element": BLOCK_ENTRIES, "edge": EDGE_ENTRIES}[self.value]

    @classmethod
    def of(cls, value) -> "Assembly":
        """``value`` (an Assembly or its name: "atomic", "element", "edge") as an Assembly;
        ValueError naming the choices otherwise.
        """
        if isinstance(value, cls):
            return value
        try:
            return cls(value)
        except ValueError:
            raise ValueError(
                f"assembly must be one of {', '.join(a.value for a in cls)}, not {value!r}"
            ) from None


_MATH = ("sqrt", "log", "exp", "expm1", "log1p")
# math.nan / math.inf: a float64 constant in one branch of a conditional makes it float64.
_CONSTANT = re.compile(r"(?<![\w.])(math\.(?:nan|inf))(?![\w.])")
_FLOAT = re.compile(r"(?<![\w.])((?:\d+\.\d*|\.\d+)(?:[eE][+-]?\d+)?|\d+[eE][+-]?\d+)(?![\w.])")


def fp32_source(code: str) -> str:
    """``code`` with every floating literal wrapped in f32(...) and math.f( calls turned into
    f32_f( (see the module docstring).
    """
    code = _FLOAT.sub(r"f32(\1)", code)
    code = _CONSTANT.sub(r"f32(\1)", code)
    for name in _MATH:
        code = code.replace(f"math.{name}(", f"f32_{name}(")
    return code


def _helper_source(fn) -> str:
    """The Python source of a compiled helper without its decorators and docstring."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(getattr(fn, "py_func", fn))))
    func = tree.body[0]
    func.decorator_list = []
    if (
        func.body
        and isinstance(func.body[0], ast.Expr)
        and isinstance(func.body[0].value, ast.Constant)
    ):
        func.body = func.body[1:]
    return ast.unparse(func)


class CudaTarget(Target):
    """The generated CUDA kernel ``mjed_cells`` of :data:`CUDA_SIGNATURE`, in ``dtype``
    (np.float64 or np.float32).
    """

    def __init__(self, dtype=np.float64, assembly=Assembly.ATOMIC):
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.dtype(np.float64), np.dtype(np.float32)):
            raise ValueError(f"dtype must be float64 or float32, got {self.dtype}")
        self.assembly = Assembly.of(assembly)

    @property
    def title_note(self) -> str:
        """What the module's title adds for a non-default assembly (none for the atomic one,
        whose source, hence its kernel cache, stays that of before the option).
        """
        return "" if self.assembly is Assembly.ATOMIC else f", {self.assembly.value} stiffness"

    def before_blocks(self, s: Source) -> None:
        """What the blocks of the cell need first (the row lengths, for the atomic adds)."""
        if self.assembly is Assembly.ATOMIC:
            row_lengths(s)

    def block(self, s: Source, a: int, b: int, entry) -> None:
        """Block (node a, node b) of cell e out of the cell, as :attr:`assembly` says:
        :func:`add_block` or :func:`store_block`.
        """
        _BLOCK_WRITERS[self.assembly](s, a, b, entry)

    def add_energy(self, s: Source, expr: str) -> None:
        s(f"E_out[e] = {expr}")

    def add_force(self, s: Source, a: int, i: int, expr: str) -> None:
        s(f"cuda.atomic.add(force, (n{a}, {i}), -({expr}))")

    def scatter(self, s: Source) -> None:
        """Every block of the cell out of it (see the module docstring): edge blocks, their
        transposes and the node blocks; with :attr:`Assembly.EDGE`, the edge blocks alone
        (:func:`store_edge_block`).
        """
        if self.assembly is Assembly.EDGE:
            for k in range(len(EDGES)):
                store_edge_block(s, k, lambda r, c, k=k: f"K{k}_{r}{c}")
            return
        self.before_blocks(s)
        for k, (a, b) in enumerate(EDGES):
            self.block(s, a, b, lambda r, c, k=k: f"K{k}_{r}{c}")
            self.block(s, b, a, lambda r, c, k=k: f"K{k}_{c}{r}")
        for a in range(4):
            for r, c in PAIRS6:
                s(f"N{r}{c} = " + node_block_sum(a, r, c))
            self.block(s, a, a, lambda r, c: f"-N{min(r, c)}{max(r, c)}")

    def module(self, kernel) -> None:
        write_cuda_module(
            kernel,
            f"MJED CUDA kernel ({self.dtype.name}{self.title_note}) generated by "
            "mjed.cuda.codegen for one kernel shape; do not edit.",
            ("mjed_cells", "mjed_force"),
            CUDA_SIGNATURE,
            self.dtype,
        )


def row_lengths(s: Source) -> None:
    """Write L0 ... L3, the CSR row length of each node of cell e (read by :func:`add_block`)."""
    for a in range(4):
        s(f"L{a} = rowlen[n{a}]")


def add_block(s: Source, a: int, b: int, entry) -> None:
    """Write the atomic addition of a 3x3 block into the CSR data at block (node a, node b)
    of cell e: entry(r, c) is the expression of entry (r, c); positions from the block map
    ``blk`` and the row lengths L{a} (:func:`row_lengths`, :func:`block_map`).
    """
    s(f"p = blk[e, {4 * a + b}]")
    for r in range(3):
        for c in range(3):
            s(f"cuda.atomic.add(data, p + {r} * L{a} + {c}, {entry(r, c)})")


def store_block(s: Source, a: int, b: int, entry) -> None:
    """Write the plain stores of a 3x3 block of cell e into the per-cell array ``data``
    (144, m): entry (r, c) of block (node a, node b) at row 9 (4 a + b) + 3 r + c, column e
    (:attr:`Assembly.ELEMENT`).
    """
    for r in range(3):
        for c in range(3):
            s(f"data[{9 * (4 * a + b) + 3 * r + c}, e] = {entry(r, c)}")


def store_edge_block(s: Source, k: int, entry) -> None:
    """Write the plain stores of edge block k (nodes EDGES[k] = (a, b), a < b: the block that
    goes to (node a, node b)) of cell e into the per-cell array ``data`` (54, m): entry (r, c)
    at row 9 k + 3 r + c, column e (:attr:`Assembly.EDGE`).
    """
    for r in range(3):
        for c in range(3):
            s(f"data[{9 * k + 3 * r + c}, e] = {entry(r, c)}")


_BLOCK_WRITERS = {Assembly.ATOMIC: add_block, Assembly.ELEMENT: store_block}


def write_cuda_module(writer, title: str, names, signature, dtype) -> None:
    """Write a CUDA kernel module into ``writer.src``: the compiled helpers of the CPU
    kernels as device functions, then two kernels of ``signature``, each a grid-stride loop
    over the cells e (one cell a thread on a GPU; :mod:`mjed.cuda.threads`):
    ``names[0]`` (everything) and ``names[1]`` (the same with ``want_stiffness = False``, so
    that the compiler removes the stiffness code and the force runs at a higher occupancy).
    Their bodies are written by ``writer.parameters()`` and ``writer.cell()`` (which write
    into ``writer.src``); in FP32 the body is rewritten by :func:`fp32_source`. Also used by
    reference_fem.classical_codegen.
    """
    from mjed.compiled.kernels import DEVICE_HELPERS

    s = writer.src
    fp32 = np.dtype(dtype) == np.dtype(np.float32)
    body = Source()
    writer.src = body
    for fn in DEVICE_HELPERS:
        body("@cuda.jit(device=True)")
        for line in _helper_source(fn).splitlines():
            body(line)
        body("")
        body("")
    for name, force_only in zip(names, (False, True)):
        body("@cuda.jit(cache=True)")  # the device code kept beside the source, as the CPU's
        with body.block(f"def {name}({', '.join(signature)}):"):
            if force_only:
                # A kernel's registers are those of its largest path: the force pass
                # alone gets its own kernel, without the stiffness code (the branch is
                # removed by the compiler), so that it runs at a higher occupancy.
                body("want_stiffness = False")
            # a grid-stride loop over the cells (mjed.cuda.threads: the simulator caps the grid)
            body("start, stride = cuda.grid(1), cuda.gridsize(1)")
            with body.block("for e in range(start, cells.shape[0], stride):"):
                writer.parameters()
                writer.cell()
        body("")
        body("")
    writer.src = s
    s(f'"""{title}')
    s("")
    s(f"shape: {writer.shape!r}")
    s('"""')
    s("import math")
    s("")
    s("from numba import cuda")
    s("from numba import float32 as f32")
    s("")
    s("")
    if fp32:
        for name in _MATH:
            s("@cuda.jit(device=True)")
            with s.block(f"def f32_{name}(v):"):
                s(f"return f32(math.{name}(v))")
            s("")
            s("")
    code = body.text()
    s.lines.extend((fp32_source(code) if fp32 else code).rstrip("\n").splitlines())


def _block_starts(indptr: np.ndarray, n_nodes: int):
    """(first, rows, rowlen) of a node-block pattern: the position of entry (0, 0) of each
    3x3 block in CSR order (ascending), the node of its rows, and the row length per node.
    """
    indptr = np.asarray(indptr, dtype=np.int64)
    row0 = indptr[0 : 3 * n_nodes : 3]
    rowlen = indptr[1 : 3 * n_nodes + 1 : 3] - row0
    deg = rowlen // 3
    rows = np.repeat(np.arange(n_nodes), deg)
    first = row0[rows] + 3 * (
        np.arange(len(rows)) - np.repeat(np.cumsum(deg) - deg, deg)
    )  # (0, 0) of each block
    return first, rows, rowlen


def block_map(cells: np.ndarray, indptr: np.ndarray, indices: np.ndarray, n_nodes: int):
    """Where each cell's 16 node blocks start in the CSR data of a node-block pattern
    (mjed.sparse.CSRPattern: rows 3 i + r hold, for each neighbour k of node i in order, the
    three columns 3 k + c). Returns blk (m, 16), entry 4 a + b the position of entry (0, 0)
    of block (node a, node b) of the cell, and rowlen (n,), the length of node i's rows:
    entry (r, c) of the block is at blk + r * rowlen[node a] + c. Vectorised, once per mesh.
    """
    cells = np.asarray(cells, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    first, rows, rowlen = _block_starts(indptr, n_nodes)
    keys = rows * n_nodes + indices[first] // 3  # sorted: rows in order, columns sorted in a row
    a = np.repeat(cells, 4, axis=1)  # (m, 16): node a of block 4 a + b
    b = np.tile(cells, (1, 4))
    pos = np.searchsorted(keys, a * n_nodes + b)
    if len(keys) and not np.array_equal(keys[np.minimum(pos, len(keys) - 1)], a * n_nodes + b):
        raise ValueError("block_map: a cell's node pair is missing from the pattern")
    return first[pos], rowlen


@dataclass(frozen=True)
class ElementIncidence:
    """Which per-cell entries make up each 3x3 block of the CSR values
    (:attr:`Assembly.ELEMENT`), built once per mesh by :func:`element_incidence`.

    first (nb,): the CSR position of entry (0, 0) of each block, in CSR order; rowlen (nb,):
    the length of its rows (entry (r, c) at first + r * rowlen + c); offsets (nb + 1,) and
    contributions (16 m,): block t is the sum over k in offsets[t]:offsets[t + 1] of the
    3x3 blocks whose entry (r, c) is, in the per-cell array ``data`` (144, m) read flat,
    at contributions[k] + (3 r + c) m (contributions[k] = 9 (4 a + b) m + e: block (a, b) of
    cell e). Integer arrays of int64.
    """

    first: np.ndarray
    rowlen: np.ndarray
    offsets: np.ndarray
    contributions: np.ndarray
    cells: int

    @property
    def blocks(self) -> int:
        return len(self.first)

    def gather(self, data: np.ndarray, nnz: int) -> np.ndarray:
        """The CSR values (nnz,) from the per-cell entries ``data`` (144, m) on the host, in
        NumPy: the reference of the device's gather kernel.
        """
        flat = np.asarray(data).reshape(-1)
        out = np.zeros(nnz, dtype=np.asarray(data).dtype)
        owner = np.repeat(np.arange(self.blocks), np.diff(self.offsets))
        for r in range(3):
            for c in range(3):
                sums = np.bincount(owner, weights=self._entries(flat, r, c), minlength=self.blocks)
                out[self.first + r * self.rowlen + c] = self._signed(sums)
        return out

    def _entries(self, flat: np.ndarray, r: int, c: int) -> np.ndarray:
        """Entry (r, c) of every contribution, from the per-cell entries read flat."""
        return flat[self.contributions + (3 * r + c) * self.cells]

    def _signed(self, sums: np.ndarray) -> np.ndarray:
        return sums


def element_incidence(blk: np.ndarray, indptr: np.ndarray, n_nodes: int) -> ElementIncidence:
    """The :class:`ElementIncidence` of a mesh from its block map ``blk`` (m, 16)
    (:func:`block_map`) and its pattern's indptr: each cell block's CSR block found by a
    search among the block starts, then the 16 m contributions sorted by block (stable, so
    in cell order within a block). Vectorised, once per mesh.
    """
    blk = np.asarray(blk, dtype=np.int64).reshape(-1, 16)
    m = len(blk)
    first, rows, rowlen = _block_starts(indptr, n_nodes)
    block = np.searchsorted(first, blk)  # (m, 16): the CSR block of each cell block
    if blk.size and not np.array_equal(first[np.minimum(block, len(first) - 1)], blk):
        raise ValueError("element_incidence: the block map is not of this pattern")
    order = np.argsort(block.T.reshape(-1), kind="stable")  # slot-major: 4 a + b, then e
    slot, e = np.divmod(order, max(m, 1))
    offsets = np.zeros(len(first) + 1, dtype=np.int64)
    np.cumsum(np.bincount(block.reshape(-1), minlength=len(first)), out=offsets[1:])
    return ElementIncidence(first, rowlen[rows], offsets, 9 * slot * m + e, m)


@dataclass(frozen=True)
class EdgeIncidence(ElementIncidence):
    """Which stored edge blocks make up each 3x3 block of the CSR values
    (:attr:`Assembly.EDGE`), built once per mesh by :func:`edge_incidence`.

    first, rowlen, offsets: as :class:`ElementIncidence`. contributions (24 m,): each a code
    2 q + t, q = 9 k m + e the position of entry (0, 0) of edge block k of cell e in the
    per-cell array ``data`` (54, m) read flat (entry (r, c) at q + (3 r + c) m), t = 1 when the
    block enters transposed (entry (r, c) at q + (3 c + r) m). An off-diagonal CSR block
    (p, q) holds every cell edge joining p and q: as stored when p is the edge's first node
    a, transposed when it is b. diagonal (nb,): 1 for a diagonal block (p, p), which is minus
    the sum of the (p, other) blocks of every cell edge touching p (K_pp = -sum K_p.), 0
    otherwise.
    """

    diagonal: np.ndarray

    def _entries(self, flat: np.ndarray, r: int, c: int) -> np.ndarray:
        q, t = self.contributions >> 1, (self.contributions & 1).astype(bool)
        m = self.cells
        return flat[q + np.where(t, (3 * c + r) * m, (3 * r + c) * m)]

    def _signed(self, sums: np.ndarray) -> np.ndarray:
        return np.where(self.diagonal.astype(bool), -sums, sums)


def _slot_edges(m: int) -> np.ndarray:
    """Per cell block slot 4 a + b, the stored edge blocks that make it, as codes less 2 e
    (:class:`EdgeIncidence`), (16, 3): column 0 the edge block of {a, b} for a != b (transposed
    when a > b), columns 0 to 2 the three edge blocks of a for a node block a == b
    (transposed where a is the edge's second node); -1 where unused.
    """
    table = np.full((16, 3), -1, dtype=np.int64)
    for a in range(4):
        for b in range(4):
            for j, c in enumerate([b] if a != b else [c for c in range(4) if c != a]):
                k = EDGES.index((min(a, c), max(a, c)))
                table[4 * a + b, j] = 2 * 9 * k * m + int(a > c)
    return table


def edge_incidence(element: ElementIncidence) -> EdgeIncidence:
    """The :class:`EdgeIncidence` of a mesh from its :class:`ElementIncidence`
    (:func:`element_incidence`, the same CSR blocks): each cell block (a, b), a != b, becomes
    its edge block, as stored or transposed, and each node block (a, a) the three edge blocks
    of a, in place; the grouping by CSR block is kept, so nothing is sorted again. Vectorised.
    """
    m = element.cells
    table = _slot_edges(m)
    slot, e = np.divmod(element.contributions, 9 * max(m, 1))
    node = slot % 5 == 0  # slots 0, 5, 10, 15: the node blocks (a, a)
    reps = np.where(node, 3, 1)
    pos = np.cumsum(reps) - reps  # where each cell block's first edge block goes
    code = np.empty(int(reps.sum()), dtype=np.int64)
    code[pos] = table[slot, 0] + 2 * e
    pos, slot, e = pos[node], slot[node], e[node]
    for j in (1, 2):
        code[pos + j] = table[slot, j] + 2 * e
    diagonal = node[element.offsets[:-1]].astype(np.int8)  # a block's cell blocks: all alike
    offsets = np.zeros(element.blocks + 1, dtype=np.int64)
    np.cumsum(np.diff(element.offsets) * np.where(diagonal, 3, 1), out=offsets[1:])
    return EdgeIncidence(element.first, element.rowlen, offsets, code, m, diagonal)
