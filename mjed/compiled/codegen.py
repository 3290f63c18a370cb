"""Python source of an MJED kernel specialised to one :class:`mjed.compiled.shape.KernelShape`.

Why generate source: a kernel that reads term codes at run time keeps every 3x3 quantity in
small arrays, loops over terms, slots and groups with run-time bounds and branches on codes
per term and per cell; the compiler can then neither keep those quantities in registers nor
drop the arithmetic a material does not have. The generated kernel spells every quantity of
one cell as a scalar local (F00 ... F22, the stress, the six 3x3 edge blocks) and contains
only the terms of its shape; a quantity that is structurally zero (f' of a constant f(J),
S of g = 1, ...) is dropped while the source is written, since the compiler may not drop
``x * 0.0`` itself (x may be NaN or inf).

The algebra is the NumPy engine's (mjed/engine.py, mjed/edge_blocks.py), per cell:

- kinematics: F = sum_a x_a (x) D_a, cof(F), J, C = F^T F, I1, I2, ln J, eigen-pairs of C;
- each term: f, f', f'' and g, S = 2 dg/dC, the tangent coefficients (or theta);
- each group: u, h_g, g2_g, S_g, S-hat_g, theta_g and the slot weights, folded in with weight
  c (plain) or c phi'(u) for a function phi of the sum (e^u, ln(a + u), (a + u)^p; then also
  the rank-one c phi''(u) du_a (x) du_b, du_a = (F S_g + h_g cof) D_a);
- force: -V0 (F S-bar D_a + h d_a), d_a = cof D_a;
- the six edge blocks (D_a . S-bar D_b) Id + first-kind 2 w (F A D_a)(x)(F A D_b) +
  second-kind w ((F B D_b)(x)(F B D_a) + (D_a . B D_b) F B F^T) + spectral outers +
  d_a (x) (F S-hat D_b + g2 d_b) + F S-hat D_a (x) d_b + c phi'' du_a (x) du_b
  + h [F (D_a x D_b)]_x,
  all scaled by V0, and the node blocks by translation invariance (K_aa = -sum_b K_ab);
  the blocks are added into the mesh-edge sums U and node sums Dg, then every CSR entry is
  written once, in order (:func:`mjed.compiled.kernels.write_csr`): half the scattered
  updates of adding 16 blocks per cell into the CSR array (writing straight into the CSR
  data from per-cell positions measured 3.5 ms against 2.4 ms for NeoHookean).

Rewrites of that algebra, exact in real arithmetic, save operations: F (D_a x D_b) is
(x_d - x_c) / (6 V0) on a P1 cell (see ``stiffness``); D_a . B D_b is formed from D in
registers rather than read from a per-cell array; V0 scales a few per-cell factors instead
of every block entry; K_aa, a diagonal block of a Hessian, is formed as its upper triangle;
the regularised part of the diagonal is formed only when asked for.

The generated module defines ``mjed_cells`` with the arguments of :data:`KERNEL_SIGNATURE`
(documented in its docstring). The cell body is written for a :class:`Target`, which says how
a cell's inputs reach it and its energy, force and blocks leave it and writes the module
around the body: the serial kernel (the default), the parallel driver over coloured slabs
(:data:`PARALLEL`, :data:`PARALLEL_SIGNATURE`), the cell-batched kernel
(mjed.compiled.batched.BatchTarget) and the CUDA kernel (mjed.cuda.codegen.CudaTarget) share
it, so a new kind of term is written once for the four. Pure Python; no Numba.
"""

from __future__ import annotations

import re
from contextlib import contextmanager
from typing import Callable, Dict, Iterator, List, Optional, Sequence, Tuple

from mjed.compiled.shape import KernelShape, TermShape

__all__ = [
    "kernel_source",
    "KERNEL_SIGNATURE",
    "CELL_INPUTS",
    "ASSEMBLY_ARGS",
    "PARALLEL_SIGNATURE",
    "Target",
    "SERIAL",
    "PARALLEL",
    "gather_cell",
    "scatter_edge_block",
    "node_block_sum",
    "write_kernel_module",
    "write_parallel_driver",
    "RANGE_ARGS",
]

#: The arguments every generated cell loop starts with: positions, mesh, rest geometry, the
#: material's term tables, and what to compute (the targets add their own outputs after them).
CELL_INPUTS = (
    "x",
    "cells",
    "D",
    "V0",
    "jpar",
    "gpar",
    "gmat",
    "group_coef",
    "slot_M",
    "regularize",
    "want_force",
    "want_stiffness",
    "want_stress",
)

#: The arguments through which a serial kernel assembles: the cells' edges and their
#: orientation, the per-edge and per-node block sums, the CSR scatter map, and the outputs
#: (force, CSR values, J per cell). The classical kernel assembles through the same ones.
ASSEMBLY_ARGS = (
    "cell_edges",
    "cell_flip",
    "U",
    "Dg",
    "src",
    "blkptr",
    "indptr",
    "force",
    "data",
    "J_out",
)

#: The arguments of the generated ``mjed_cells``, in order (see its docstring).
KERNEL_SIGNATURE = CELL_INPUTS + ASSEMBLY_ARGS + ("stress_out",)

_KERNEL_DOC = '''"""Energy, forces, stiffness and stress of every cell by MJED, for one term shape.

x (n, 3) positions; cells (m, 4); D (m, 4, 3) rest shape vectors; V0 (m,) rest volumes;
jpar, gpar, gmat, group_coef, slot_M: the numbers of mjed.compiled.lowering.TermTable;
regularize: paper section 2.3; want_force / want_stiffness / want_stress: what to form;
cell_edges (m, 6), cell_flip (m, 6): mesh edge of each cell edge and whether it runs against
it (mjed.sparse.CSRPattern); U (E, 3, 3), Dg (n, 3, 3): scratch for the edge and node sums;
src, blkptr, indptr: where each CSR block comes from (mjed.compiled.kernels.block_sources).
Adds -dW/dx into force (n, 3), writes d2W/dx2 into data (nnz,), J per cell into J_out (m,)
and S = 2 dW/dC per cell into stress_out (m, 3, 3) (when wanted). Returns the total energy.
"""'''
_PARALLEL_DOC = (
    _KERNEL_DOC[:-3]
    + '''Parallel: the per-cell arguments (cells, D, V0, per-cell frames and slot matrices,
cell_edges, cell_flip) come in schedule order; cell_id (m,) is the caller's index of each
(J_out and stress_out are written there); cells of chunk (slab) k are chunk_ptr[k] to
chunk_ptr[k + 1] - 1, chunks of colour c are colour_ptr[c] to colour_ptr[c + 1] - 1
(mjed.compiled.schedule.CellSchedule).
"""'''
)
EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))  # mjed.sparse.EDGES
# The opposite edge (c, d) of each edge (a, b), ordered so that (a, b, c, d) is an even permutation.
_OPPOSITE = {
    (0, 1): (2, 3),
    (0, 2): (3, 1),
    (0, 3): (1, 2),
    (1, 2): (0, 3),
    (1, 3): (2, 0),
    (2, 3): (0, 1),
}
ONE = "1.0"  # an expression known to be exactly one (dropped from products)
Expr = Optional[str]  # None: structurally zero


# ------------------------------------------------------------------ expressions
_SIMPLE = re.compile(r"^-?([A-Za-z_][A-Za-z0-9_]*|[0-9.]+)$")


def _factor(e: str) -> str:
    """``e`` as a factor of a product: parenthesised unless it is a name or a number."""
    return e if _SIMPLE.match(e) else f"({e})"


def mul(*factors: Expr) -> Expr:
    """The product, None if a factor is structurally zero; factors equal to ONE are dropped."""
    if any(f is None for f in factors):
        return None
    kept = [_factor(f) for f in factors if f != ONE]
    return " * ".join(kept) if kept else ONE


def add(*terms: Expr) -> Expr:
    """The sum of the terms that are not structurally zero (None if none is left)."""
    kept = [t for t in terms if t is not None]
    return " + ".join(kept) if kept else None


def sym(i: int, j: int) -> Tuple[int, int]:
    """The stored entry of a symmetric 3x3 quantity (upper triangle)."""
    return (i, j) if i <= j else (j, i)


class Source:
    """Lines of Python with indentation; ``let`` names a non-trivial expression."""

    def __init__(self) -> None:
        self.lines: List[str] = []
        self.depth = 0

    def __call__(self, line: str) -> None:
        self.lines.append("    " * self.depth + line)

    @contextmanager
    def block(self, header: str) -> Iterator[None]:
        self(header)
        self.depth += 1
        yield
        self.depth -= 1

    def let(self, name: str, expr: Expr) -> Expr:
        """Assign ``expr`` to ``name`` and return the name; structural zero and one pass through."""
        if expr is None or expr == ONE:
            return expr
        self(f"{name} = {expr}")
        return name

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


Sym = Dict[Tuple[int, int], Expr]  # a symmetric 3x3 quantity by its upper-triangle entries
PAIRS6 = [(i, j) for i in range(3) for j in range(i, 3)]


def _sym_let(src: Source, prefix: str, entries: Sym) -> Sym:
    return {ij: src.let(f"{prefix}{ij[0]}{ij[1]}", entries.get(ij)) for ij in PAIRS6}


def _sym_zero() -> Sym:
    return {ij: None for ij in PAIRS6}


def _is_zero(s: Sym) -> bool:
    return all(v is None for v in s.values())


# ------------------------------------------------------------------ pieces shared with other
# generators
def gather_cell(s: Source) -> None:
    """Write the loads of cell e (node numbers n_a, rest shape vectors D_a, positions X_a) and
    F = sum_a x_a (x) D_a as scalar locals (also used by reference_fem.classical_codegen).
    """
    s("n0, n1, n2, n3 = cells[e, 0], cells[e, 1], cells[e, 2], cells[e, 3]")
    for a in range(4):
        s(f"D{a}0, D{a}1, D{a}2 = D[e, {a}, 0], D[e, {a}, 1], D[e, {a}, 2]")
        s(f"X{a}0, X{a}1, X{a}2 = x[n{a}, 0], x[n{a}, 1], x[n{a}, 2]")
    deformation_gradient(s)


def deformation_gradient(s: Source) -> None:
    """Write F = sum_a X_a (x) D_a (F00 .. F22) from the scalar locals X_ai and D_aj."""
    for i in range(3):
        for j in range(3):
            s(f"F{i}{j} = " + " + ".join(f"X{a}{i} * D{a}{j}" for a in range(4)))


def scatter_edge_block(s: Source, k: int, block: str) -> None:
    """Write the addition of the 3x3 block of cell edge k (locals ``{block}{r}{c}``) into its
    mesh-edge sum U, transposed when the cell edge runs against the mesh edge (the orientation
    is decided once per block, not per entry).
    """
    s(f"ge = cell_edges[e, {k}]")
    with s.block(f"if cell_flip[e, {k}]:"):
        for r in range(3):
            for c in range(3):
                s(f"U[ge, {c}, {r}] += {block}{r}{c}")
    with s.block("else:"):
        for r in range(3):
            for c in range(3):
                s(f"U[ge, {r}, {c}] += {block}{r}{c}")


# ------------------------------------------------------------------ the generator
class _Kernel:
    """Writes the kernel of one shape for one target; each method writes one part of the cell
    loop.
    """

    def __init__(self, shape: KernelShape, target: "Target" = None):
        self.shape = shape
        self.target = SERIAL if target is None else target
        self.src = Source()
        self.I1_powers: Dict[int, str] = {}

    # ---- parameters, read once before the loop
    def parameters(self) -> None:
        s = self.src
        for t, term in enumerate(self.shape.terms):
            if term.j == "power":
                s(f"q_{t} = jpar[{t}, 0]")
                s(f"qm2_{t} = q_{t} - 2.0")
                s(f"qq1_{t} = q_{t} * (q_{t} - 1.0)")
            elif term.j == "logpoly":
                s(f"a2_{t}, a1_{t}, a0_{t} = jpar[{t}, 0], jpar[{t}, 1], jpar[{t}, 2]")
            elif term.j == "jlogj":
                s(f"k_{t}, kc_{t} = jpar[{t}, 0], jpar[{t}, 1]")
            if term.g in ("i1power", "linear_i2", "eigen"):
                s(f"c_{t} = gpar[{t}, 0]")
            if term.g == "i1power":
                s(f"c2n_{t} = 2.0 * c_{t} * {float(term.n)!r}")
                if term.n >= 2:
                    s(f"c2nn_{t} = 2.0 * c_{t} * {float(term.n)!r} * {float(term.n - 1)!r}")
            elif term.g == "linear_i2":
                s(f"tc_{t} = 2.0 * c_{t}")
                s(f"mtc_{t} = -2.0 * c_{t}")
            elif term.g == "green_lagrange":
                s(f"mu_{t}, lm_{t} = gpar[{t}, 0], gpar[{t}, 1]")
                s(f"hl_{t} = 0.5 * lm_{t}")
                s(f"tmu_{t} = 2.0 * mu_{t}")
            elif term.g == "fibre":
                for i in range(3):
                    s(
                        ", ".join(f"B{t}_{i}{j}" for j in range(3))
                        + " = "
                        + ", ".join(f"gpar[{t}, {3 * i + j}]" for j in range(3))
                    )
                for p in range(len(term.slots)):
                    s(f"sg{t}_{p} = gpar[{t}, {9 + p}]")
                if not self.shape.per_cell_R:
                    self._load3(f"R{t}_", f"gmat[{t}, 0")
            elif term.g == "eigen":
                s(f"qe_{t} = gpar[{t}, 1]")
                s(f"qm1_{t} = qe_{t} - 1.0")
                s(f"c2q_{t} = 2.0 * c_{t} * qe_{t}")
                if term.coaxial:
                    s(f"hp_{t} = 0.5 * (qm1_{t} - 1.0)")
        for g, (_, _, function) in enumerate(self.shape.groups):
            s(f"gc_{g} = group_coef[{g}, 0]")
            if function in ("log", "power"):
                s(f"ga_{g} = group_coef[{g}, 1]")
            if function == "power":
                s(f"gp_{g} = group_coef[{g}, 2]")
                s(f"gpm2_{g} = gp_{g} - 2.0")
                s(f"gcp_{g} = gc_{g} * gp_{g}")
                s(f"gcpp_{g} = gcp_{g} * (gp_{g} - 1.0)")
        for sl, (kind, ident) in enumerate(self.shape.slots):
            if kind != "spectral" and not ident and not self.shape.per_cell_M:
                self._load3(f"M{sl}_", f"slot_M[{sl}, 0")

    def _load3(self, prefix: str, base: str) -> None:
        """prefix{i}{j} = base, i, j] (a per-cell base, one indexed by e, is read through the
        target's ``cell_input``).
        """
        read = self.target.cell_input if base.endswith(", e") else str
        for i in range(3):
            self.src(
                ", ".join(f"{prefix}{i}{j}" for j in range(3))
                + " = "
                + ", ".join(read(f"{base}, {i}, {j}]") for j in range(3))
            )

    # ---- kinematics
    def kinematics(self) -> None:
        s = self.src
        self.target.gather(s)
        for i in range(3):
            i1, i2 = (i + 1) % 3, (i + 2) % 3
            for j in range(3):
                j1, j2 = (j + 1) % 3, (j + 2) % 3
                s(f"cf{i}{j} = F{i1}{j1} * F{i2}{j2} - F{i1}{j2} * F{i2}{j1}")
        s("J = F00 * cf00 + F10 * cf10 + F20 * cf20")
        self.target.cell_output(s, "J_out", "", "J")
        for i, j in PAIRS6:
            s(f"C{i}{j} = F0{i} * F0{j} + F1{i} * F1{j} + F2{i} * F2{j}")
        s("I1 = C00 + C11 + C22")
        terms = self.shape.terms
        if any(t.g == "linear_i2" for t in terms):
            s(
                "I2 = 0.5 * (I1 * I1 - (C00 * C00 + C11 * C11 + C22 * C22 + 2.0 * (C01 * C01 + C02 "
                "* C02 + C12 * C12)))"
            )
        if any(t.j in ("logpoly", "jlogj") for t in terms):
            s("L = math.log(J)")
        if any(t.g in ("green_lagrange", "fibre") for t in terms):
            for i, j in PAIRS6:
                s(f"E{i}{j} = 0.5 * (C{i}{j} - 1.0)" if i == j else f"E{i}{j} = 0.5 * C{i}{j}")
        if self.shape.need_eig:
            names = ["lam0", "lam1", "lam2"] + [f"V{i}{n}" for i in range(3) for n in range(3)]
            with self.target.hoisted(s, names) as h:
                h("eig = eigh3_sym(C00, C01, C02, C11, C12, C22)")
                h("lam0, lam1, lam2 = eig[0], eig[1], eig[2]")
                for i in range(3):
                    h(
                        ", ".join(f"V{i}{n}" for n in range(3))
                        + f" = eig[{3 + 3 * i}], eig[{4 + 3 * i}], eig[{5 + 3 * i}]"
                    )

    def I1_power(self, n: int) -> str:
        """I1^n by products, formed once per cell."""
        if n == 1:
            return "I1"
        if n not in self.I1_powers:
            self.src(f"I1p{n} = {self.I1_power(n - 1)} * I1")
            self.I1_powers[n] = f"I1p{n}"
        return self.I1_powers[n]

    # ---- one term: (f, f', f''), (g, S, coefficients, theta)
    def j_function(self, t: int, term: TermShape) -> Tuple[Expr, Expr, Expr]:
        s = self.src
        if term.j == "one":
            return ONE, None, None
        if term.j == "power":
            s(f"Jq_{t} = J ** qm2_{t}")
            return (
                s.let(f"f_{t}", f"Jq_{t} * J * J"),
                s.let(f"df_{t}", f"q_{t} * Jq_{t} * J"),
                s.let(f"d2f_{t}", f"qq1_{t} * Jq_{t}"),
            )
        if term.j == "logpoly":
            return (
                s.let(f"f_{t}", f"(a2_{t} * L + a1_{t}) * L + a0_{t}"),
                s.let(f"df_{t}", f"(2.0 * a2_{t} * L + a1_{t}) / J"),
                s.let(f"d2f_{t}", f"(2.0 * a2_{t} * (1.0 - L) - a1_{t}) / (J * J)"),
            )
        return (
            s.let(f"f_{t}", f"k_{t} * (J * L - J + 1.0) + kc_{t}"),
            s.let(f"df_{t}", f"k_{t} * L"),
            s.let(f"d2f_{t}", f"k_{t} / J"),
        )

    def g_function(self, t: int, term: TermShape) -> Tuple[Expr, Sym, List[Expr], Sym]:
        """g, S, the coefficient of each tangent pair, theta (spectral; else zero)."""
        s = self.src
        g = term.g
        if g == "unity":
            return ONE, _sym_zero(), [], _sym_zero()
        if g == "i1power":
            n = term.n
            if n == 1:
                value = s.let(f"g_{t}", f"c_{t} * I1")
                d = s.let(f"s_{t}", f"2.0 * c_{t}")
                return (
                    value,
                    {ij: (d if ij[0] == ij[1] else None) for ij in PAIRS6},
                    [],
                    _sym_zero(),
                )
            value = s.let(f"g_{t}", f"c_{t} * {self.I1_power(n)}")
            d = s.let(f"s_{t}", f"c2n_{t} * {self.I1_power(n - 1)}")
            coef = s.let(f"b_{t}", f"c2nn_{t}" + (f" * {self.I1_power(n - 2)}" if n > 2 else ""))
            return (
                value,
                {ij: (d if ij[0] == ij[1] else None) for ij in PAIRS6},
                [coef],
                _sym_zero(),
            )
        if g == "linear_i2":
            S = {
                (i, j): (f"tc_{t} * (I1 - C{i}{j})" if i == j else f"mtc_{t} * C{i}{j}")
                for i, j in PAIRS6
            }
            return (
                s.let(f"g_{t}", f"c_{t} * I2"),
                _sym_let(s, f"S{t}_", S),
                [f"tc_{t}", f"mtc_{t}"],
                _sym_zero(),
            )
        if g == "green_lagrange":
            s(f"trE_{t} = 0.5 * I1 - 1.5")
            EE = "E00 * E00 + E11 * E11 + E22 * E22 + 2.0 * (E01 * E01 + E02 * E02 + E12 * E12)"
            value = s.let(f"g_{t}", f"hl_{t} * trE_{t} * trE_{t} + mu_{t} * ({EE})")
            S = {
                (i, j): (
                    f"tmu_{t} * E{i}{j} + lm_{t} * trE_{t}" if i == j else f"tmu_{t} * E{i}{j}"
                )
                for i, j in PAIRS6
            }
            return value, _sym_let(s, f"S{t}_", S), [f"hl_{t}", f"mu_{t}"], _sym_zero()
        if g == "fibre":
            return self._fibre(t, term)
        return self._eigen(t, term)

    def _fibre(self, t: int, term: TermShape) -> Tuple[Expr, Sym, List[Expr], Sym]:
        """G = sum B_ij (R^T E R)_ij^2, S = 2 R (B o R^T E R) R^T (mjed/fibre.py)."""
        s = self.src
        R = f"R{t}_"
        if self.shape.per_cell_R:
            self._load3(R, f"gmat[{t}, e")
        for i in range(3):  # W = E R
            for j in range(3):
                s(
                    f"W{t}_{i}{j} = "
                    + " + ".join(f"E{''.join(map(str, sym(i, k)))} * {R}{k}{j}" for k in range(3))
                )
        terms = []
        for i in range(3):  # Ef = R^T W; P = B o Ef; g = sum P o Ef
            for j in range(3):
                s(f"Ef{t}_{i}{j} = " + " + ".join(f"{R}{k}{i} * W{t}_{k}{j}" for k in range(3)))
                s(f"P{t}_{i}{j} = B{t}_{i}{j} * Ef{t}_{i}{j}")
                terms.append(f"P{t}_{i}{j} * Ef{t}_{i}{j}")
        value = s.let(f"g_{t}", " + ".join(terms))
        for i in range(3):  # Q = P R^T
            for j in range(3):
                s(f"Q{t}_{i}{j} = " + " + ".join(f"P{t}_{i}{k} * {R}{j}{k}" for k in range(3)))
        S = {
            (i, j): "2.0 * (" + " + ".join(f"{R}{i}{k} * Q{t}_{k}{j}" for k in range(3)) + ")"
            for i, j in PAIRS6
        }
        coefs = [f"sg{t}_{p}" for p in range(len(term.slots))]
        return value, _sym_let(s, f"S{t}_", S), coefs, _sym_zero()

    def _eigen(self, t: int, term: TermShape) -> Tuple[Expr, Sym, List[Expr], Sym]:
        """G = c sum lam_n^q (mjed/spectral.py); theta only when the stiffness is wanted."""
        s = self.src
        with self.target.hoisted(s, [f"lp{t}_{n}" for n in range(3)]) as h:
            for n in range(3):
                h(f"lp{t}_{n} = lam{n} ** qm1_{t}")
        value = s.let(f"g_{t}", f"c_{t} * (lp{t}_0 * lam0 + lp{t}_1 * lam1 + lp{t}_2 * lam2)")
        S = {
            (i, j): f"c2q_{t} * ("
            + " + ".join(f"V{i}{n} * lp{t}_{n} * V{j}{n}" for n in range(3))
            + ")"
            for i, j in PAIRS6
        }
        S = _sym_let(s, f"S{t}_", S)
        theta = {ij: f"th{t}_{ij[0]}{ij[1]}" for ij in PAIRS6}
        for ij in PAIRS6:  # defined on every path (the force-only pass leaves them at zero)
            s(f"{theta[ij]} = 0.0")
        with s.block("if want_stiffness:"):
            if term.coaxial:  # SOFA's approximation: (q-1) lam_n^((q-2)/2) lam_l^((q-2)/2)
                for n in range(3):
                    s(f"rc{t}_{n} = lam{n} ** hp_{t}")
                for n, l in PAIRS6:
                    s(f"{theta[n, l]} = c2q_{t} * (qm1_{t} * rc{t}_{n} * rc{t}_{l})")
            else:
                dd = [f"dd{t}_{n}{l}" for n, l in PAIRS6]
                with self.target.hoisted(s, dd, condition="want_stiffness") as h:
                    h(
                        f"{', '.join(dd)} = divided_differences_sym(lam0, lam1, lam2, lp{t}_0, "
                        f"lp{t}_1, lp{t}_2, qm1_{t})"
                    )
                for (n, l), name in zip(PAIRS6, dd):
                    s(f"{theta[n, l]} = c2q_{t} * {name}")
        return value, S, [], theta

    # ---- groups and their totals
    def terms_and_groups(self) -> dict:
        s = self.src
        shape = self.shape
        n_slots = len(shape.slots)
        tot = {
            "h": [],
            "g2": [],
            "St": {ij: [] for ij in PAIRS6},
            "Sh": {ij: [] for ij in PAIRS6},
            "th": {ij: [] for ij in PAIRS6},
            "w": [[] for _ in range(n_slots)],
            "energy": [],
            "exp": [],
        }
        for gi, (start, stop, function) in enumerate(shape.groups):
            u, hg, g2g = [], [], []
            Sg = {ij: [] for ij in PAIRS6}
            Shg = {ij: [] for ij in PAIRS6}
            thg = {ij: [] for ij in PAIRS6}
            wg: List[List[Expr]] = [[] for _ in range(n_slots)]
            for t in range(start, stop):
                term = shape.terms[t]
                f, df, d2f = self.j_function(t, term)
                g, S, coefs, theta = self.g_function(t, term)
                u.append(mul(f, g))
                hg.append(mul(df, g))
                g2g.append(mul(d2f, g))
                for ij in PAIRS6:
                    Sg[ij].append(mul(f, S[ij]))
                    Shg[ij].append(mul(df, S[ij]))
                    thg[ij].append(mul(f, theta[ij]))
                for slot, coef in zip(term.slots, coefs):
                    wg[slot].append(mul(f, coef))
            u_g = s.let(f"u_{gi}", add(*u))
            sc, rank_one = self._group_function(gi, function, u_g or "0.0", tot["energy"])
            hg_e = s.let(f"hg_{gi}", add(*hg))
            tot["h"].append(mul(sc, hg_e))
            tot["g2"].append(mul(sc, s.let(f"g2g_{gi}", add(*g2g))))
            Sg_n = _sym_let(s, f"Sg{gi}_", {ij: add(*Sg[ij]) for ij in PAIRS6})
            for ij in PAIRS6:
                tot["St"][ij].append(mul(sc, Sg_n[ij]))
                tot["Sh"][ij].append(mul(sc, s.let(f"Shg{gi}_{ij[0]}{ij[1]}", add(*Shg[ij]))))
                tot["th"][ij].append(mul(sc, s.let(f"thg{gi}_{ij[0]}{ij[1]}", add(*thg[ij]))))
            for sl in range(n_slots):
                tot["w"][sl].append(mul(sc, s.let(f"wg{gi}_{sl}", add(*wg[sl]))))
            if rank_one is not None:
                tot["exp"].append((gi, rank_one, Sg_n, hg_e))
        out = {
            "h": s.let("h", add(*tot["h"])),
            "g2": s.let("g2", add(*tot["g2"])),
            "St": _sym_let(s, "St", {ij: add(*tot["St"][ij]) for ij in PAIRS6}),
            "Sh": _sym_let(s, "Sh", {ij: add(*tot["Sh"][ij]) for ij in PAIRS6}),
            "th": _sym_let(s, "th", {ij: add(*tot["th"][ij]) for ij in PAIRS6}),
            "w": [s.let(f"w_{sl}", add(*tot["w"][sl])) for sl in range(n_slots)],
            "exp": tot["exp"],
        }
        self.target.add_energy(
            s, f"{self.target.cell_input('V0[e]')} * ({add(*tot['energy']) or '0.0'})"
        )
        return out

    def _group_function(
        self, gi: int, function: str, u: str, energy: List[Expr]
    ) -> Tuple[str, Expr]:
        """Append c phi(u) to ``energy``; return the names of c phi'(u) (the weight of the
        group's linear sums) and c phi''(u) (its rank-one term; None for a plain group).
        """
        s = self.src
        if function == "plain":
            energy.append(mul(f"gc_{gi}", u))
            return f"gc_{gi}", None
        if function == "exp":  # phi = phi' = phi''
            sc = s.let(f"sc_{gi}", f"gc_{gi} * math.exp({u})")
            energy.append(sc)
            return sc, sc
        if function == "log":  # ln(a + u): 1 / (a + u), -1 / (a + u)^2; NaN where a + u <= 0
            s(f"ag_{gi} = ga_{gi} + {u}")
            s(f"ia_{gi} = 1.0 / ag_{gi} if ag_{gi} > 0.0 else math.nan")
            energy.append(f"gc_{gi} * math.log(ag_{gi})")
            sc = s.let(f"sc_{gi}", f"gc_{gi} * ia_{gi}")
            return sc, s.let(f"rc_{gi}", f"-sc_{gi} * ia_{gi}")
        if function == "power":  # (a + u)^p: p (a + u)^(p-1), p (p-1) (a + u)^(p-2)
            s(f"pa_{gi} = ga_{gi} + {u}")
            s(f"pb_{gi} = pa_{gi} ** gpm2_{gi}")
            energy.append(f"gc_{gi} * pb_{gi} * pa_{gi} * pa_{gi}")
            sc = s.let(f"sc_{gi}", f"gcp_{gi} * pb_{gi} * pa_{gi}")
            return sc, s.let(f"rc_{gi}", f"gcpp_{gi} * pb_{gi}")
        raise ValueError(f"no code for a group function {function!r}")

    # ---- helpers on per-cell matrices
    def _apply(self, prefix: str, M, node_vec: str = "D") -> Dict[Tuple[int, int], str]:
        """prefix{a}{i} = (M v_a)_i for the four nodes; M(i, k) gives an entry (or None)."""
        out = {}
        for a in range(4):
            for i in range(3):
                expr = add(*[mul(M(i, k), f"{node_vec}{a}{k}") for k in range(3)])
                out[a, i] = self.src.let(f"{prefix}{a}{i}", expr) or "0.0"
        return out

    def _F_times_sym(self, prefix: str, S: Sym) -> Dict[Tuple[int, int], Expr]:
        """prefix{i}{j} = (F S)_ij for a symmetric S."""
        out = {}
        for i in range(3):
            for j in range(3):
                out[i, j] = self.src.let(
                    f"{prefix}{i}{j}", add(*[mul(f"F{i}{k}", S[sym(k, j)]) for k in range(3)])
                )
        return out

    def force_and_stress(self, q: dict) -> None:
        s = self.src
        h, St = q["h"], q["St"]
        with s.block("if want_stress:"):
            hJ = s.let("hJ", f"{h} / J" if h else None)
            for i in range(3):
                for j in range(3):
                    jcof = mul(hJ, f"(cf0{i} * cf0{j} + cf1{i} * cf1{j} + cf2{i} * cf2{j})")
                    self.target.cell_output(
                        s, "stress_out", f", {i}, {j}", add(St[sym(i, j)], jcof) or "0.0"
                    )
        with s.block("if want_force:"):
            FS = self._F_times_sym("FS", St)
            for a in range(4):
                for i in range(3):
                    grad = add(mul(h, f"dJ{a}{i}"), *[mul(FS[i, j], f"D{a}{j}") for j in range(3)])
                    if grad is not None:
                        v0 = self.target.cell_input("V0[e]")
                        self.target.add_force(s, a, i, f"{v0} * ({grad})")

    # ---- stiffness: per-cell vectors, six edge blocks, node blocks, scatter
    def stiffness(self, q: dict) -> None:
        s = self.src
        # Every edge-block term is scaled by V0 through one of its per-cell factors (a few
        # multiplications per cell instead of one per block entry).
        s(f"vol = {self.target.cell_input('V0[e]')}")
        s.let("hv", mul(q["h"], "vol"))
        g2 = s.let("g2v", mul(q["g2"], "vol"))
        St = _sym_let(s, "Stv", {ij: mul(q["St"][ij], "vol") for ij in PAIRS6})
        Sh = _sym_let(s, "Shv", {ij: mul(q["Sh"][ij], "vol") for ij in PAIRS6})
        th = _sym_let(s, "thv", {ij: mul(q["th"][ij], "vol") for ij in PAIRS6})
        w = [s.let(f"wv_{sl}", mul(ws, "vol")) for sl, ws in enumerate(q["w"])]
        exp = [(gi, s.let(f"scv{gi}", mul(sc, "vol")), Sg, hg) for gi, sc, Sg, hg in q["exp"]]
        regularised = g2 is not None or bool(exp)
        if regularised:
            s("breg = min(max(1.0 - J, 0.0), 1.0) if regularize else 0.0")
            s("keep = 1.0 - breg")
        SD = self._apply("SD", lambda i, k: St[sym(i, k)]) if not _is_zero(St) else None
        FSh = None
        if not _is_zero(Sh):
            FShm = self._F_times_sym("FSh", Sh)
            FSh = self._apply("FShD", lambda i, k: FShm[i, k])
        vb = {}
        if FSh is not None or g2 is not None:  # v_b = F S-hat D_b + g2 keep d_b
            g2k = s.let("g2k", mul(g2, "keep"))
            for b in range(4):
                for c in range(3):
                    vb[b, c] = s.let(
                        f"vb{b}{c}", add(FSh[b, c] if FSh else None, mul(g2k, f"dJ{b}{c}"))
                    )
        slot_terms = self._slots(w)
        spectral = self._spectral_cell(th) if not _is_zero(th) else None
        exp_terms = self._exp_groups(exp)
        if regularised:  # the regularised part of the diagonal (paper section 2.3), only when asked
            for k in range(6):
                s(f"rg{k} = 0.0")
            with s.block("if regularize:"):
                for k, (a, b) in enumerate(EDGES):
                    reg = [
                        mul(g2, "breg", f"(dJ{a}0 * dJ{b}0 + dJ{a}1 * dJ{b}1 + dJ{a}2 * dJ{b}2)")
                    ]
                    for gi, sc, _, _ in exp:
                        reg.append(
                            mul(
                                sc,
                                "breg",
                                f"(du{gi}_{a}0 * du{gi}_{b}0 + du{gi}_{a}1 * du{gi}_{b}1"
                                f" + du{gi}_{a}2 * du{gi}_{b}2)",
                            )
                        )
                    s(f"rg{k} = {add(*reg)}")
        # h d2J/dx_a dx_b = h V0 [F (D_a x D_b)]_x, and on a P1 cell D_a x D_b = (X_d - X_c) / (6
        # V0)
        # for (a, b, c, d) an even permutation, so F (D_a x D_b) = (x_d - x_c) / (6 V0): the term
        # is (h / 6) [x_d - x_c]_x, six operations per edge instead of 24 (V0 cancels).
        h6 = s.let("h6", f"{q['h']} * (1.0 / 6.0)" if q["h"] else None)
        for k, (a, b) in enumerate(EDGES):
            diag = (
                add(mul(f"D{a}0", SD[b, 0]), mul(f"D{a}1", SD[b, 1]), mul(f"D{a}2", SD[b, 2]))
                if SD
                else None
            )
            diag = s.let(f"dg{k}", add(diag, f"rg{k}" if regularised else None))
            skew = None
            if h6 is not None:
                c_, d_ = _OPPOSITE[a, b]
                for i in range(3):
                    s(f"qk{i} = h6 * (X{d_}{i} - X{c_}{i})")
                skew = {
                    (0, 1): "qk2",
                    (1, 0): "-qk2",
                    (0, 2): "-qk1",
                    (2, 0): "qk1",
                    (1, 2): "qk0",
                    (2, 1): "-qk0",
                }
            sp = spectral(k, a, b) if spectral else None
            for r in range(3):
                for c in range(3):
                    parts: List[Expr] = [diag if r == c else None]
                    parts += [fn(k, a, b, r, c) for fn in slot_terms]
                    if vb:
                        parts.append(mul(f"dJ{a}{r}", vb[b, c]))
                    if FSh is not None:
                        parts.append(mul(FSh[a, r], f"dJ{b}{c}"))
                    parts += [fn(a, b, r, c) for fn in exp_terms]
                    if skew and (r, c) in skew:
                        parts.append(skew[r, c])
                    if sp:
                        parts.append(sp[r, c])
                    s(f"K{k}_{r}{c} = {add(*parts) or '0.0'}")
        self.target.scatter(s)

    def _slots(self, w: Sequence[Expr]) -> list:
        """Per-cell vectors of the first- and second-kind slots; returns one function per
        slot giving its term of entry (r, c) of edge k = (a, b).
        """
        s = self.src
        fns = []
        for sl, (kind, ident) in enumerate(self.shape.slots):
            if kind == "spectral" or w[sl] is None:
                continue
            if ident:
                MD = {(a, i): f"D{a}{i}" for a in range(4) for i in range(3)}
                M = lambda i, k: ONE if i == k else None  # noqa: E731
            else:
                if self.shape.per_cell_M:
                    self._load3(f"M{sl}_", f"slot_M[{sl}, e")
                M = (lambda p: lambda i, k: f"{p}{i}{k}")(f"M{sl}_")
                MD = self._apply(f"MD{sl}_", M)
            G = (
                self._apply(f"G{sl}_", lambda i, k: f"F{i}{k}", node_vec=f"MD{sl}_")
                if not ident
                else self._apply(f"G{sl}_", lambda i, k: f"F{i}{k}")
            )
            if kind == "first":  # 2 w G_a (x) G_b
                tw = s.let(f"tw{sl}", f"2.0 * {w[sl]}")
                for a in range(4):
                    for i in range(3):
                        s(f"tG{sl}_{a}{i} = {tw} * {G[a, i]}")
                fns.append((lambda sl: lambda k, a, b, r, c: f"tG{sl}_{a}{r} * G{sl}_{b}{c}")(sl))
            else:  # w (G_b (x) G_a + (D_a . M D_b) F M F^T)
                FM = {
                    (i, j): s.let(
                        f"FM{sl}_{i}{j}", add(*[mul(f"F{i}{k}", M(k, j)) for k in range(3)])
                    )
                    for i in range(3)
                    for j in range(3)
                }
                for i, j in PAIRS6:
                    s(f"FMF{sl}_{i}{j} = " + " + ".join(f"{FM[i, k]} * F{j}{k}" for k in range(3)))
                for a in range(4):
                    for i in range(3):
                        s(f"wG{sl}_{a}{i} = {w[sl]} * {G[a, i]}")
                for k, (a, b) in enumerate(EDGES):
                    dmd = " + ".join(f"D{a}{i} * {MD[b, i]}" for i in range(3))
                    s(f"wd{sl}_{k} = {w[sl]} * ({dmd})")
                fns.append(
                    (
                        lambda sl: (
                            lambda k, a, b, r, c: (
                                f"wG{sl}_{b}{r} * G{sl}_{a}{c} + wd{sl}_{k} * "
                                f"FMF{sl}_{''.join(map(str, sym(r, c)))}"
                            )
                        )
                    )(sl)
                )
        return fns

    def _spectral_cell(self, th: Sym):
        """F v_n, v_n . D_a and z[a, n, c] = sum_l theta_nl (v_l . D_a)(F v_l)_c; returns the
        function giving the 3x3 spectral term of edge k = (a, b).
        """
        s = self.src
        for n in range(3):
            for i in range(3):
                s(f"wn{n}{i} = F{i}0 * V0{n} + F{i}1 * V1{n} + F{i}2 * V2{n}")
            for a in range(4):
                s(f"cn{n}{a} = V0{n} * D{a}0 + V1{n} * D{a}1 + V2{n} * D{a}2")
        for n in range(3):
            for a in range(4):
                s(
                    f"tc{n}{a}_0, tc{n}{a}_1, tc{n}{a}_2 = "
                    + ", ".join(f"{th[sym(n, l)]} * cn{l}{a}" for l in range(3))
                )
                for c in range(3):
                    s(f"z{a}{n}{c} = " + " + ".join(f"tc{n}{a}_{l} * wn{l}{c}" for l in range(3)))

        def block(k: int, a: int, b: int) -> Dict[Tuple[int, int], str]:
            for n in range(3):
                s(f"rs{n} = " + " + ".join(f"tc{n}{a}_{l} * cn{l}{b}" for l in range(3)))
                for c in range(3):
                    s(f"y{n}{c} = cn{n}{b} * z{a}{n}{c} + rs{n} * wn{n}{c}")
            return {
                (r, c): "(" + " + ".join(f"wn{n}{r} * y{n}{c}" for n in range(3)) + ")"
                for r in range(3)
                for c in range(3)
            }

        return block

    def _exp_groups(self, groups) -> list:
        """du_a = (F S_g + h_g cof) D_a of each group with a function of its sum; returns one
        function per group giving its term c phi''(u) keep du_a[r] du_b[c].
        """
        s = self.src
        fns = []
        for gi, sc, Sg, hg in groups:
            FSg = self._F_times_sym(f"FSg{gi}_", Sg)
            M = {
                (i, j): s.let(f"Mu{gi}_{i}{j}", add(FSg[i, j], mul(hg, f"cf{i}{j}")))
                for i in range(3)
                for j in range(3)
            }
            self._apply(f"du{gi}_", lambda i, k: M[i, k])
            s(f"sk{gi} = {sc} * keep")
            fns.append(
                (lambda gi: lambda a, b, r, c: f"sk{gi} * du{gi}_{a}{r} * du{gi}_{b}{c}")(gi)
            )
        return fns

    # ---- the module
    def cell(self) -> None:
        """Write the body of the loop over cells e: everything one cell contributes (may be
        called once per function of a module: nothing written is reused across calls).
        """
        s = self.src
        self.I1_powers = {}
        self.kinematics()
        q = self.terms_and_groups()
        needs_d = q["h"] is not None or q["g2"] is not None or not _is_zero(q["Sh"])
        if needs_d:  # d_a = cof D_a = dJ/dx_a
            self._apply("dJ", lambda i, k: f"cf{i}{k}")
        self.force_and_stress(q)
        with s.block("if want_stiffness:"):
            self.stiffness(q)

    def module(self) -> str:
        self.target.module(self)
        return self.src.text()


# ------------------------------------------------------------------ targets
class Target:
    """Where the generated cell body sends what it computes, and the module around it.

    The body (kinematics, terms, groups, the stress, the gradient and the six edge blocks,
    all per cell e) is the same for every target; a target says how the results leave a cell
    (``add_energy``, ``add_force``, ``scatter``: the only statements that write memory shared
    between cells), which index the per-cell outputs J and S are written at (``out``), and
    writes the module around the body (``module``). Adding a kind of term never touches a
    target; adding a target never touches the body.
    """

    #: the index expression of the cell in the per-cell outputs (J_out, stress_out)
    out = "e"

    def gather(self, s: Source) -> None:
        """Read cell e: node numbers, rest shape vectors, positions and F (gather_cell)."""
        gather_cell(s)

    def cell_input(self, expr: str) -> str:
        """The expression reading ``expr``, a per-cell input indexed by e (V0[e], a per-cell
        frame entry), in the cell body.
        """
        return expr

    def cell_output(self, s: Source, array: str, index: str, expr: str) -> None:
        """Write ``expr`` into a per-cell output (J_out, stress_out) at the cell, then ``index``."""
        s(f"{array}[{self.out}{index}] = {expr}")

    @contextmanager
    def hoisted(self, s: Source, names: Sequence[str], condition: str = "") -> Iterator[Source]:
        """Where to write a computation of ``names`` that a target may move out of the cell
        body (calls that are not plain arithmetic: the eigen-decomposition, powers of the
        eigenvalues, divided differences; ``condition``: a flag already tested around it).
        Here: in place.
        """
        yield s

    def add_energy(self, s: Source, expr: str) -> None:
        s(f"energy += {expr}")

    def add_force(self, s: Source, a: int, i: int, expr: str) -> None:
        """Subtract ``expr`` (component i of node a's energy gradient) from the nodal force."""
        s(f"force[n{a}, {i}] -= {expr}")

    def scatter(self, s: Source) -> None:
        """Edge blocks into the mesh-edge sums U (transposed when the cell edge runs against the
        mesh edge), node blocks K_aa = -sum_b K_ab into Dg.
        """
        for k in range(len(EDGES)):
            scatter_edge_block(s, k, f"K{k}_")
        for a in range(4):  # K_aa is symmetric (a diagonal block of a Hessian): six sums, not nine
            for r, c in PAIRS6:
                s(f"N{r}{c} = " + node_block_sum(a, r, c))
            for r in range(3):
                for c in range(3):
                    s(f"Dg[n{a}, {r}, {c}] -= N{min(r, c)}{max(r, c)}")

    def module(self, kernel: "_Kernel") -> None:
        """The serial CPU module: ``mjed_cells`` of :data:`KERNEL_SIGNATURE`, one loop over the
        cells.
        """
        shape = kernel.shape
        write_kernel_module(
            kernel.src,
            f"MJED kernel generated by mjed.compiled.codegen for one kernel shape; do not "
            f"edit.\n\nshape: {shape!r}",
            [
                "from mjed.compiled.kernels import JIT_OPTIONS, divided_differences_sym, "
                "eigh3_sym, "
                "write_csr"
            ],
            "mjed_cells",
            KERNEL_SIGNATURE,
            _KERNEL_DOC,
            kernel.parameters,
            kernel.cell,
        )


def node_block_sum(a: int, r: int, c: int) -> str:
    """Entry (r, c) of sum_b K_ab over the edges of node a (from the edge-block locals K{k}_)."""
    parts = [f"K{k}_{r}{c}" for k, (p, _) in enumerate(EDGES) if p == a]
    parts += [f"K{k}_{c}{r}" for k, (_, q) in enumerate(EDGES) if q == a]
    return " + ".join(parts)


SERIAL = Target()


#: The arguments of the parallel ``mjed_cells``: the serial ones, then the schedule of
#: :class:`mjed.compiled.schedule.CellSchedule` (the per-cell arrays come in its order).
PARALLEL_SIGNATURE = KERNEL_SIGNATURE + ("cell_id", "chunk_ptr", "colour_ptr")


class ParallelTarget(Target):
    """The CPU kernel over all cores: the slabs of cells of one colour run in parallel
    (``prange``, one slab per iteration), the colours one after the other
    (:mod:`mjed.compiled.schedule`).

    Why colouring (and not per-cell buffers, atomics or private copies): the serial kernel
    adds each cell's blocks into per-edge and per-node sums that stay in cache (2.2 MB on
    cube-paper) and then writes each CSR entry once. Slabs of one colour share no node, hence
    no edge, so their cells add into the same sums from different threads with plain stores:
    the arithmetic and the traffic per cell stay those of the serial kernel. Per-cell block
    buffers summed by a second, slot-ordered pass would be race-free too, but write and read
    again 90 doubles per cell (15 MB on cube-paper), about the whole serial kernel's time at
    this machine's bandwidth; atomic adds on doubles are a compare-and-swap loop on x86;
    private copies of the sums per thread cost their zeroing and reduction (2.2 MB per
    thread, 35 MB on 16 cores). The price of colouring is one synchronisation per colour,
    two or three with slabs. The CSR data are then written in parallel over node rows (each
    row by one thread).
    """

    out = "cell_id[e]"

    def add_energy(self, s: Source, expr: str) -> None:
        s(f"energy_k += {expr}")

    def module(self, kernel: "_Kernel") -> None:
        """Two functions: ``mjed_cell_range`` runs the cell body over cells lo to hi - 1
        (serial, compiled like the serial kernel), and ``mjed_cells`` (the parallel driver,
        :data:`PARALLEL_SIGNATURE`) calls it once per chunk, the chunks of a colour in a
        ``prange``. Keeping the cell body out of the parallel loop keeps Numba's parallel
        analysis to a few statements: with the body inside the ``prange`` NeoHookean took
        33 s to compile, now 3.7 s (the serial kernel 2.8 s); one call per chunk costs
        nothing measurable.
        """
        s = kernel.src
        s(
            '"""MJED kernel generated by mjed.compiled.codegen for one kernel shape, parallel over '
            "cells; do not edit."
        )
        s("")
        s(f"shape: {kernel.shape!r}")
        s('"""')
        for line in (
            "import math",
            "",
            "from numba import njit, prange",
            "",
            "from mjed.compiled.kernels import JIT_OPTIONS, divided_differences_sym, eigh3_sym, "
            "write_csr_parallel, zero_sums_parallel",
            "",
            "",
        ):
            s(line)
        s("@njit(**JIT_OPTIONS)")
        with s.block(f"def mjed_cell_range(lo, hi, {', '.join(RANGE_ARGS)}):"):
            s('"""The cells lo to hi - 1 of mjed_cells (schedule order); returns their energy."""')
            kernel.parameters()
            s("energy_k = 0.0")
            with s.block("for e in range(lo, hi):"):
                kernel.cell()
            s("return energy_k")
        write_parallel_driver(s)


def write_parallel_driver(s: Source) -> None:
    """The parallel ``mjed_cells`` (:data:`PARALLEL_SIGNATURE`): the chunks of each colour in a
    ``prange``, each chunk by ``mjed_cell_range(lo, hi, *RANGE_ARGS)``, then the CSR write.
    """
    s("")
    s("")
    s("@njit(parallel=True, **JIT_OPTIONS)")
    with s.block(f"def mjed_cells({', '.join(PARALLEL_SIGNATURE)}):"):
        for line in _PARALLEL_DOC.splitlines():
            s(line)
        with s.block("if want_stiffness:"):
            s("zero_sums_parallel(U, Dg)")
        s("energy = 0.0")
        with s.block("for colour in range(colour_ptr.shape[0] - 1):"):
            s("energy_c = 0.0")
            with s.block("for chunk in prange(colour_ptr[colour], colour_ptr[colour + 1]):"):
                s(
                    "energy_c += mjed_cell_range(chunk_ptr[chunk], chunk_ptr[chunk + 1], "
                    f"{', '.join(RANGE_ARGS)})"
                )
            s("energy += energy_c")
        with s.block("if want_stiffness:"):
            s("write_csr_parallel(U, Dg, src, blkptr, indptr, data)")
        s("return energy")


#: The arguments of the generated mjed_cell_range after (lo, hi).
RANGE_ARGS = CELL_INPUTS + (
    "cell_edges",
    "cell_flip",
    "U",
    "Dg",
    "force",
    "J_out",
    "stress_out",
    "cell_id",
)


PARALLEL = ParallelTarget()


def write_kernel_module(
    s: Source,
    title: str,
    imports: Sequence[str],
    name: str,
    signature: Sequence[str],
    doc: str,
    before_loop: Callable[[], None],
    cell: Callable[[], None],
) -> None:
    """Write a kernel module: its docstring ``title``, the imports, and one compiled function
    ``name(*signature)`` with docstring ``doc`` that runs ``before_loop`` (parameters read
    once), clears the assembly sums U and Dg when the stiffness is wanted, writes ``cell``
    (the body of the loop over cells e, which adds to ``energy``) and finally the CSR data
    (also used by reference_fem.classical_codegen).
    """
    for line in f'"""{title}'.splitlines():
        s(line)
    s('"""')
    s("import math")
    s("")
    s("from numba import njit")
    s("")
    for line in imports:
        s(line)
    s("")
    s("")
    s("@njit(**JIT_OPTIONS)")
    with s.block(f"def {name}({', '.join(signature)}):"):
        for line in doc.splitlines():
            s(line)
        s("m = cells.shape[0]")
        before_loop()
        with s.block("if want_stiffness:"):
            s("U[:] = 0.0")
            s("Dg[:] = 0.0")
        s("energy = 0.0")
        with s.block("for e in range(m):"):
            cell()
        with s.block("if want_stiffness:"):
            s("write_csr(U, Dg, src, blkptr, indptr, data)")
        s("return energy")


def kernel_source(shape: KernelShape, target: "Target" = None) -> str:
    """The source of the kernel module for ``shape``: the serial CPU kernel, or the module of
    ``target`` (e.g. :data:`PARALLEL`, or mjed.cuda.codegen's CUDA targets).
    """
    return _Kernel(shape, target).module()
