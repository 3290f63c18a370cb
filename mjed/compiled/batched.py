"""The cell-batched CPU kernel: the generated cell body run over a batch of B cells at once, in
a loop the compiler turns into SIMD (one cell per vector lane).

Why a batch: the serial kernel computes one cell per loop iteration in scalar registers, so
its arithmetic runs one lane of the vector units (LLVM packs only a few neighbouring scalar
expressions). Across cells the body is the same straight-line arithmetic, so a loop over
cells whose every load and store is contiguous in the cell index is what LLVM's loop
vectoriser turns into packed instructions, one cell per lane. The loads of a cell are
gathers through the connectivity and its results are scattered into shared sums, which the
vectoriser cannot do (or only by gather instructions); so each batch runs in three passes:

1. a scalar *gather* pass copies each cell's inputs (positions of its nodes, rest shape
   vectors, rest volume, per-cell frames) into ``sin``, one row of B lanes per quantity
   (structure of arrays), and computes there what is not plain arithmetic (Ogden's
   eigen-decomposition of C, the powers of its eigenvalues and their divided differences:
   loops, branches and calls into libm that would stop the vectoriser);
2. the *lanes* function: the generated cell body, unchanged (the same generator and the same
   terms as every other target), in a loop over the B lanes that reads only ``sin[l + k B]``
   and writes only ``sout[l + k B]``: energy, J, the gradient, the stress, the six edge blocks
   and the four node blocks (their six sums). What to compute is a constant of each lanes
   function (one with the stiffness, one force only, one stress only) so no flag tested per
   cell is left in the loop; ``regularize`` stays an argument (LLVM if-converts its branch);
   the edge blocks leave the lanes in the orientation of their mesh edge (a select per lane),
   so the scatter pass adds them without the one-cell kernel's branch per edge;
   ln J, J^p, e^u are ``llvm.log``/``llvm.pow``/``llvm.exp`` intrinsics, which the vectoriser
   keeps inside the vector loop as one scalar libm call per lane (Numba 0.56 as Debian ships
   it has no SVML, so there is no vector version);
3. a scalar *scatter* pass adds the batch's results into the nodal force, the mesh-edge sums U
   and the node sums Dg in cell order, exactly as the serial kernel does (the same additions
   in the same order, so without ``fastmath`` the batched kernel gives the serial kernel's
   results bit for bit, and its parallel form those of the parallel kernel).

The last batch of a range is padded with copies of its last cell (computed, never scattered).
The per-batch scratch is ``(rows in + rows out) B`` doubles, about 130 rows: 17 KB for the
default B = 16, in L1 cache with the vectoriser's spills. Measured (docs/studies/timing.md):
the lanes functions are packed AVX-512 arithmetic, and force + stiffness is 1.04x
(Neo-Hookean) to 1.78x (Costa) faster than one cell at a time on cube-paper; the additions
into the shared sums, scalar in both kernels, are then most of the time.
"""

from __future__ import annotations

import re
from contextlib import contextmanager
from typing import Dict, Iterator, Sequence, Tuple

from mjed.compiled.codegen import (
    EDGES,
    KERNEL_SIGNATURE,
    PAIRS6,
    RANGE_ARGS,
    Source,
    Target,
    deformation_gradient,
    gather_cell,
    kernel_source,
    node_block_sum,
    write_parallel_driver,
)
from mjed.compiled.shape import KernelShape

__all__ = ["BatchTarget", "batched_source", "DEFAULT_BATCH"]

#: Cells per batch (lanes) by default: see docs/studies/timing.md for the measured choice.
DEFAULT_BATCH = 16

#: The lanes functions: (name suffix, want_force, want_stiffness, want_stress).
_VARIANTS = (("k", True, True, False), ("f", True, False, False), ("s", False, False, True))
_LANE_ARGS = ("buf", "jpar", "gpar", "gmat", "group_coef", "slot_M", "regularize")


class BatchTarget(Target):
    """The cell body over a batch of ``batch`` lanes (see the module docstring); serial, or
    each chunk of the parallel schedule batched (``parallel``).

    ``fma`` (off, and not offered by CompiledForceField): compile the lanes functions with
    ``fastmath={"contract"}``, so that LLVM fuses a * b + c. Measured on cube-paper (one
    thread, 31 interleaved rounds): force + stiffness 1.10x (Neo-Hookean) and 1.13x (Costa)
    faster, results within 7e-14 of the NumPy engine's; but the three lanes functions are
    then contracted differently, so ``force(x)`` and ``force_and_stiffness(x)[0]`` differ in
    the last bits, which the compiled fields guarantee they do not (tests/test_compiled.py).
    """

    def __init__(self, batch: int = DEFAULT_BATCH, parallel: bool = False, fma: bool = False):
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch}")
        self.B = int(batch)
        self.parallel = bool(parallel)
        self.fma = bool(fma)
        self.out = "cell_id[e]" if parallel else "e"
        self._in: Dict[str, Tuple[int, str]] = {}  # key -> (row, value in the gather pass)
        self._out: Dict[str, int] = {}  # key -> row
        self._hoisted: Dict[Tuple[str, ...], None] = {}
        self._pre = Source()  # the gather pass's hoisted computations

    # ---- rows of the scratch arrays
    def _lane(self, array: str, row: int) -> str:
        return f"{array}[l + {row * self.B}]" if row else f"{array}[l]"

    def _input(self, key: str, value: str) -> str:
        if key not in self._in:
            self._in[key] = (len(self._in), value)
        return self._lane("sin", self._in[key][0])

    def _output(self, key: str) -> str:
        if key not in self._out:
            self._out[key] = len(self._out)
        return self._lane("sout", self._out[key])

    # ---- how a cell's data enter and leave the lanes
    def gather(self, s: Source) -> None:
        for a in range(4):
            for i in range(3):
                s(f"D{a}{i} = {self._input(f'D[e, {a}, {i}]', f'D{a}{i}')}")
                s(f"X{a}{i} = {self._input(f'x[n{a}, {i}]', f'X{a}{i}')}")
        deformation_gradient(s)

    def cell_input(self, expr: str) -> str:
        return self._input(expr, expr)

    def cell_output(self, s: Source, array: str, index: str, expr: str) -> None:
        s(f"{self._output(array + index)} = {expr}")

    def add_energy(self, s: Source, expr: str) -> None:
        s(f"{self._output('energy')} = {expr}")

    def add_force(self, s: Source, a: int, i: int, expr: str) -> None:
        s(f"{self._output(f'force{a}{i}')} = {expr}")

    def scatter(self, s: Source) -> None:
        """The edge blocks in the orientation of their mesh edge (transposed by a select per
        lane, so the scatter pass adds them without a branch) and the node blocks' six sums.
        """
        for k in range(len(EDGES)):
            flip = self._input(f"cell_flip[e, {k}]", f"1.0 * cell_flip[e, {k}]")
            s(f"flip = {flip} != 0.0")
            for r in range(3):
                for c in range(3):
                    value = f"K{k}_{r}{c}" if r == c else f"K{k}_{c}{r} if flip else K{k}_{r}{c}"
                    s(f"{self._output(f'U{k}_{r}{c}')} = {value}")
        for a in range(4):
            for r, c in PAIRS6:
                s(f"{self._output(f'N{a}_{r}{c}')} = " + node_block_sum(a, r, c))

    @contextmanager
    def hoisted(self, s: Source, names: Sequence[str], condition: str = "") -> Iterator[Source]:
        """Written once into the gather pass (every lanes function writes the same body),
        stored to ``sin``; the lanes read the results.
        """
        key = tuple(names)
        h = Source()
        yield h
        rows = [self._input(f"hoisted {n}", n) for n in names]
        if key not in self._hoisted:
            self._hoisted[key] = None
            pre = self._pre
            depth = pre.depth
            if condition:
                pre(f"if {condition}:")
                pre.depth += 1
            for line in h.lines:
                pre(line)
            for n, row in zip(names, rows):
                pre(f"{row} = {n}")
            pre.depth = depth
        for n, row in zip(names, rows):
            s(f"{n} = {row}")

    # ---- the module
    def module(self, kernel) -> None:
        s, lanes = kernel.src, Source()
        for suffix, force, stiffness, stress in _VARIANTS:
            self._lanes_function(kernel, lanes, suffix, force, stiffness, stress)
        kernel.src = s
        s(
            f'"""MJED kernel generated by mjed.compiled.codegen and mjed.compiled.batched for one '
            f"kernel shape, {self.B} cells per batch"
            + (", parallel over cells" if self.parallel else "")
            + "; do not edit."
        )
        s("")
        s(f"shape: {kernel.shape!r}")
        s('"""')
        for line in (
            "import math",
            "",
            "import numpy as np",
            "from numba import njit, prange",
            "",
            "from mjed.compiled.kernels import JIT_OPTIONS, divided_differences_sym, eigh3_sym, "
            "write_csr, write_csr_parallel, zero_sums_parallel",
            "",
            "",
        ):
            s(line)
        s.lines.extend(self._one_buffer(lanes.lines))
        body = kernel.src = Source()
        self._range_function(kernel)
        kernel.src = s
        s.lines.extend(self._one_buffer(body.lines, view=True))
        if self.parallel:
            write_parallel_driver(s)
            return
        s("")
        s("")
        s("@njit(**JIT_OPTIONS)")
        with s.block(f"def mjed_cells({', '.join(KERNEL_SIGNATURE)}):"):
            s('"""See mjed.compiled.codegen: the serial kernel\'s arguments and results."""')
            with s.block("if want_stiffness:"):
                s("U[:] = 0.0")
                s("Dg[:] = 0.0")
            s(f"energy = mjed_cell_range(0, cells.shape[0], {', '.join(self._range_args())})")
            with s.block("if want_stiffness:"):
                s("write_csr(U, Dg, src, blkptr, indptr, data)")
            s("return energy")

    def _one_buffer(self, lines, view: bool = False):
        """The lines with sin and sout as rows of one array ``buf`` (inputs, then results);
        with ``view``, indexed through ``bl = buf[l:]`` (the scalar passes, see below).

        Why one array: the vectoriser must know that the stores of results never overwrite
        the inputs that later lanes read. In two arrays that is a run-time check of their
        overlap, which LLVM does not emit for a loop of this many accesses ("cannot prove
        it is safe to reorder memory operations", loop left scalar); in one array every
        access is at a constant distance (a multiple of B) from every other, which it proves.

        Why a view in the scalar passes: there LLVM does not prove l + k B >= 0 (Numba's
        range loop hides the induction variable from it), keeps Numba's test for a negative
        index on every access, and the SLP vectoriser then packs those tests and extracts
        each index again, four to five instructions per value; bl[k B] has a constant index.
        """
        shift = len(self._in) * self.B

        def lane(match, base=0):
            k = int(match.group(1) or 0) + base
            return f"bl[{k}]" if view else (f"buf[l + {k}]" if k else "buf[l]")

        out = []
        for line in lines:
            line = re.sub(r"\bsout\[l(?: \+ (\d+))?\]", lambda m: lane(m, shift), line)
            out.append(re.sub(r"\bsin\[l(?: \+ (\d+))?\]", lane, line))
            if view and re.match(r"\s*e = b0 \+ l", line):  # first line of a lane's pass
                out.append(line[: len(line) - len(line.lstrip())] + "bl = buf[l:]")
        return out

    def _range_args(self) -> Tuple[str, ...]:
        return RANGE_ARGS if self.parallel else RANGE_ARGS[:-1]

    def _lanes_function(
        self, kernel, lanes: Source, suffix: str, force: bool, stiffness: bool, stress: bool
    ) -> None:
        kernel.src = lanes
        lanes("@njit(fastmath={'contract'}, **JIT_OPTIONS)" if self.fma else "@njit(**JIT_OPTIONS)")
        with lanes.block(f"def mjed_lanes_{suffix}({', '.join(_LANE_ARGS)}):"):
            lanes(f'"""The cell body on {self.B} lanes: sin (inputs) to sout (results)."""')
            lanes(f"want_force = {force}")
            lanes(f"want_stiffness = {stiffness}")
            lanes(f"want_stress = {stress}")
            kernel.parameters()
            lanes("l = 0")
            with lanes.block(f"while l < {self.B}:"):
                kernel.cell()
                lanes("l += 1")
        lanes("")
        lanes("")

    def _range_function(self, kernel) -> None:
        s = kernel.src
        B, n_in, n_out = self.B, len(self._in), len(self._out)
        s("@njit(**JIT_OPTIONS)")
        with s.block(f"def mjed_cell_range(lo, hi, {', '.join(self._range_args())}):"):
            s('"""The cells lo to hi - 1, batch by batch; returns their energy."""')
            kernel.parameters()  # what the hoisted computations read
            s(f"buf = np.empty({(n_in + n_out) * B})")
            s("energy_k = 0.0")
            lane_args = ", ".join(_LANE_ARGS)
            with s.block(f"for b0 in range(lo, hi, {B}):"):
                s(f"nb = min({B}, hi - b0)")
                with s.block(f"for l in range({B}):"):
                    s("e = b0 + l if l < nb else hi - 1")
                    self._gather_pass(s)
                with s.block("if want_stiffness:"):
                    s(f"mjed_lanes_k({lane_args})")
                with s.block("elif want_force:"):
                    s(f"mjed_lanes_f({lane_args})")
                with s.block("if want_stress or not (want_force or want_stiffness):"):
                    s(f"mjed_lanes_s({lane_args})")
                with s.block("for l in range(nb):"):
                    s("e = b0 + l")
                    self._scatter_pass(s)
            s("return energy_k")

    def _gather_pass(self, s: Source) -> None:
        if self._hoisted:  # the hoisted computations read F and C
            gather_cell(s)
            for i, j in PAIRS6:
                s(f"C{i}{j} = F0{i} * F0{j} + F1{i} * F1{j} + F2{i} * F2{j}")
        else:
            s("n0, n1, n2, n3 = cells[e, 0], cells[e, 1], cells[e, 2], cells[e, 3]")
            for a in range(4):
                s(f"D{a}0, D{a}1, D{a}2 = D[e, {a}, 0], D[e, {a}, 1], D[e, {a}, 2]")
                s(f"X{a}0, X{a}1, X{a}2 = x[n{a}, 0], x[n{a}, 1], x[n{a}, 2]")
        for key, (row, value) in self._in.items():
            if not key.startswith("hoisted "):
                s(f"{self._lane('sin', row)} = {value}")
        s.lines.extend("    " * s.depth + line for line in self._pre.lines)

    def _scatter_pass(self, s: Source) -> None:
        out = self._out
        row = lambda key: self._lane("sout", out[key])  # noqa: E731
        s("n0, n1, n2, n3 = cells[e, 0], cells[e, 1], cells[e, 2], cells[e, 3]")
        s(f"J_out[{self.out}] = {row('J_out')}")
        s(f"energy_k += {row('energy')}")
        stress = [key for key in out if key.startswith("stress_out")]
        if stress:
            with s.block("if want_stress:"):
                for key in stress:
                    s(f"stress_out[{self.out}{key[len('stress_out') :]}] = {row(key)}")
        forces = [key for key in out if key.startswith("force")]
        if forces:
            with s.block("if want_force:"):
                for key in forces:
                    s(f"force[n{key[5]}, {key[6]}] -= {row(key)}")
        if "U0_00" not in out:
            return
        with s.block("if want_stiffness:"):
            for k in range(len(EDGES)):
                s(f"ge = cell_edges[e, {k}]")
                for r in range(3):
                    for c in range(3):
                        s(f"K{r}{c} = {row(f'U{k}_{r}{c}')}")
                for r in range(3):
                    for c in range(3):
                        s(f"U[ge, {r}, {c}] += K{r}{c}")
            for a in range(4):
                for r, c in PAIRS6:
                    s(f"N{r}{c} = {row(f'N{a}_{r}{c}')}")
                for r in range(3):
                    for c in range(3):
                        s(f"Dg[n{a}, {r}, {c}] -= N{min(r, c)}{max(r, c)}")


def batched_source(
    shape: KernelShape, batch: int = DEFAULT_BATCH, parallel: bool = False, fma: bool = False
) -> str:
    """The source of the batched kernel module of ``shape`` (``mjed_cells`` with the serial
    kernel's arguments, or the parallel kernel's when ``parallel``); ``fma``: the lanes may
    contract a * b + c into fused multiply-adds (see BatchTarget).
    """
    return kernel_source(shape, BatchTarget(batch, parallel, fma))
