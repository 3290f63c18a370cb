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
  cell. No pass over mesh edges, no per-edge scratch.

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
import inspect
import re
import textwrap

import numpy as np

from mjed.compiled.codegen import CELL_INPUTS, EDGES, PAIRS6, Source, Target, node_block_sum

__all__ = [
    "CudaTarget",
    "CUDA_ASSEMBLY_ARGS",
    "CUDA_SIGNATURE",
    "add_block",
    "block_map",
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

    def __init__(self, dtype=np.float64):
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.dtype(np.float64), np.dtype(np.float32)):
            raise ValueError(f"dtype must be float64 or float32, got {self.dtype}")

    def add_energy(self, s: Source, expr: str) -> None:
        s(f"E_out[e] = {expr}")

    def add_force(self, s: Source, a: int, i: int, expr: str) -> None:
        s(f"cuda.atomic.add(force, (n{a}, {i}), -({expr}))")

    def scatter(self, s: Source) -> None:
        """Every block of the cell added straight into the CSR data (see the module docstring)."""
        row_lengths(s)
        for k, (a, b) in enumerate(EDGES):
            add_block(s, a, b, lambda r, c, k=k: f"K{k}_{r}{c}")
            add_block(s, b, a, lambda r, c, k=k: f"K{k}_{c}{r}")
        for a in range(4):
            for r, c in PAIRS6:
                s(f"N{r}{c} = " + node_block_sum(a, r, c))
            add_block(s, a, a, lambda r, c: f"-N{min(r, c)}{max(r, c)}")

    def module(self, kernel) -> None:
        write_cuda_module(
            kernel,
            f"MJED CUDA kernel ({self.dtype.name}) generated by mjed.cuda.codegen for one "
            "kernel shape; do not edit.",
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


def write_cuda_module(writer, title: str, names, signature, dtype) -> None:
    """Write a CUDA kernel module into ``writer.src``: the compiled helpers of the CPU
    kernels as device functions, then two kernels of ``signature``, one thread per cell e:
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
            body("e = cuda.grid(1)")
            with body.block("if e < cells.shape[0]:"):
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


def block_map(cells: np.ndarray, indptr: np.ndarray, indices: np.ndarray, n_nodes: int):
    """Where each cell's 16 node blocks start in the CSR data of a node-block pattern
    (mjed.sparse.CSRPattern: rows 3 i + r hold, for each neighbour k of node i in order, the
    three columns 3 k + c). Returns blk (m, 16), entry 4 a + b the position of entry (0, 0)
    of block (node a, node b) of the cell, and rowlen (n,), the length of node i's rows:
    entry (r, c) of the block is at blk + r * rowlen[node a] + c. Vectorised, once per mesh.
    """
    cells = np.asarray(cells, dtype=np.int64)
    indptr = np.asarray(indptr, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    row0 = indptr[0 : 3 * n_nodes : 3]
    rowlen = indptr[1 : 3 * n_nodes + 1 : 3] - row0
    deg = rowlen // 3
    rows = np.repeat(np.arange(n_nodes), deg)
    first = row0[rows] + 3 * (
        np.arange(len(rows)) - np.repeat(np.cumsum(deg) - deg, deg)
    )  # (0, 0) of each block
    keys = rows * n_nodes + indices[first] // 3  # sorted: rows in order, columns sorted in a row
    a = np.repeat(cells, 4, axis=1)  # (m, 16): node a of block 4 a + b
    b = np.tile(cells, (1, 4))
    pos = np.searchsorted(keys, a * n_nodes + b)
    if len(keys) and not np.array_equal(keys[np.minimum(pos, len(keys) - 1)], a * n_nodes + b):
        raise ValueError("block_map: a cell's node pair is missing from the pattern")
    return first[pos], rowlen
