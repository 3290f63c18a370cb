"""Python source of a classical Galerkin kernel specialised to one :class:`LawShape`.

The classical Total Lagrangian element (the paper's "standard FEM"), per cell: F, J, C,
C^-1; the law gives W, S (Voigt 6) and the symmetric 6x6 elasticity tensor CC; B_a (6 x 3)
the Green-Lagrange strain rate of node a; f_a = -V0 F S D_a and
K_ab = V0 (B_a^T CC B_b + (D_a . S D_b) Id) for the six edges a < b and the four node blocks.
The laws are the formulas of :mod:`reference_fem.classical_materials` (Holzapfel's
invariant and decoupled forms, the spectral form for Ogden, the fibre-frame quadratic for
Costa), written here as scalar expressions.

Why generate it: the array-based kernel that this replaces kept B (6 x 12), CC (6 x 6) and
CC B in small stack arrays and ran at about half the flop rate of the generated MJED kernel
(whose 3x3 quantities are scalar locals, :mod:`mjed.compiled.codegen`), so part of MJED's
measured advantage was code style. This generator gives the classical element the same
treatment, as a careful C++ programmer would write it for one law:

- every per-cell quantity is a scalar local (F00 ... F22, S0 ... S5, the 21 entries of the
  symmetric CC, B, CC B, the blocks); entries that are structurally zero for the law (St
  Venant-Kirchhoff's CC, Arruda-Boyce's shear fictitious stress, ...) are dropped while the
  source is written, as MJED's generator drops its zero terms;
- CC is stored and read as its upper triangle; the node blocks K_aa as theirs;
- V0 scales S and CC once per cell, not every block entry;
- the decoupled laws' isochoric projection P CCb P^T is expanded into rank-one updates of
  CCb (P = Id - C^-1 (x) w), and the volumetric part of U = k0/2 (ln J)^2 is simplified
  (J (U' + J U'') = k0, 2 J U' = 2 k0 ln J); Ogden's lam^(q-2) is lam^(q-1) / lam. These
  are identities in real arithmetic; results agree with the NumPy element to round-off.

The assembly is the MJED kernels' (edge blocks summed per mesh edge, node blocks per node,
one ordered write of the CSR data, :func:`mjed.compiled.kernels.write_csr`), the
eigen-solver is theirs (:func:`mjed.compiled.kernels.eigh3_sym`) and the module is loaded
through :func:`mjed.compiled.specialise.generated_module`, so both kernels are compiled by
the same compiler with the same options and cached the same way.

The generated ``classical_cells`` takes the arguments of :data:`KERNEL_SIGNATURE`
(documented in its docstring). The cell body is written for a target, as MJED's is
(:class:`mjed.compiled.codegen.Target`): the serial CPU kernel above
(:class:`ClassicalTarget`), or the CUDA kernels ``classical_cells`` and ``classical_force``
of :data:`CUDA_SIGNATURE` (:class:`ClassicalCudaTarget`, built on
:class:`mjed.cuda.codegen.CudaTarget`: one thread per cell, the force and every block added
by atomics straight into the CSR values through the per-mesh block map, FP64 or FP32;
launched by reference_fem.classical_cuda). The two targets differ only in how a cell's
energy, force and blocks leave it. Pure Python; no Numba.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from mjed.compiled.codegen import (
    ASSEMBLY_ARGS,
    EDGES,
    Source,
    Target,
    add,
    gather_cell,
    mul,
    scatter_edge_block,
    write_kernel_module,
)
from mjed.cuda.codegen import (
    CUDA_ASSEMBLY_ARGS,
    Assembly,
    CudaTarget,
    write_cuda_module,
)
from mjed.materials.classical_forms import IsochoricPsi

__all__ = [
    "LawShape",
    "classical_source",
    "KERNEL_SIGNATURE",
    "CUDA_SIGNATURE",
    "LAWS",
    "ClassicalTarget",
    "ClassicalCudaTarget",
]

#: The law kinds.
LAWS = ("svk", "neohooke", "decoupled", "ogden", "costa")

#: What every classical cell kernel starts with: positions, connectivity, shape gradients,
#: volumes, the law's parameters and tensor, and what to compute.
CLASSICAL_INPUTS = ("x", "cells", "D", "V0", "P", "Tt", "want_force", "want_stiffness")

#: The arguments of the generated ``classical_cells``, in order.
KERNEL_SIGNATURE = CLASSICAL_INPUTS + ASSEMBLY_ARGS

_KERNEL_DOC = '''"""Energy, forces and stiffness of every cell by the classical Galerkin, for one
law.

x (n, 3) positions; cells (m, 4); D (m, 4, 3) rest shape vectors; V0 (m,) rest volumes;
P (k,) the law's parameters (reference_fem.classical_compiled.lower_law); Tt (1 or m, 6, 6)
Costa's tensor (read only by Costa); want_force / want_stiffness: what to form;
cell_edges (m, 6), cell_flip (m, 6), U (E, 3, 3), Dg (n, 3, 3), src, blkptr, indptr: the
assembly of mjed.compiled.assembly.CompiledAssembly. Adds -dW/dx into force (n, 3), writes
d2W/dx2 into data (nnz,) and J per cell into J_out (m,). Returns the total energy.
"""'''

VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))  # Voigt index I <-> (i, j)
_V = {ij: I for I, ij in enumerate(VOIGT)}
_V.update({(j, i): I for (i, j), I in list(_V.items())})
Expr = Optional[str]  # None: structurally zero
Vec6 = List[Expr]
Sym6 = Dict[Tuple[int, int], Expr]  # a symmetric 6x6 by its upper triangle (I <= K)
UPPER6 = [(I, K) for I in range(6) for K in range(I, 6)]


@dataclass(frozen=True)
class LawShape:
    """What changes the code of a classical kernel: the law kind (one of :data:`LAWS`), the
    isochoric Psi of a decoupled law (a material's declared function, else None), the names
    of the parameters that Psi reads, and whether Costa's tensor is one per cell. The law's
    numbers stay arguments (P, Tt).
    """

    law: str
    psi: Optional[IsochoricPsi] = None
    psi_parameters: Tuple[str, ...] = ()
    per_cell_T: bool = False


def neg(e: Expr) -> Expr:
    """-e (None stays None)."""
    if e is None:
        return None
    factor = mul(e)  # e itself if it is a name or a number, else (e)
    return e[1:] if e.startswith("-") and factor == e else f"-{factor}"


def cc(M: Sym6, I: int, K: int) -> Expr:
    """Entry (I, K) of a symmetric 6x6 stored as its upper triangle."""
    return M[(I, K) if I <= K else (K, I)]


def _c(i: int, j: int) -> str:
    return f"C{min(i, j)}{max(i, j)}"


def _ci(i: int, j: int) -> str:
    return f"Ci{min(i, j)}{max(i, j)}"


class _Classical:
    """Writes the kernel of one law shape; each method writes one part of the cell loop."""

    def __init__(self, shape: LawShape, target: "ClassicalTarget" = None):
        if shape.law not in LAWS or (shape.law == "decoupled") != (shape.psi is not None):
            raise ValueError(f"no classical kernel for {shape!r}")
        self.shape = shape
        self.target = SERIAL_CLASSICAL if target is None else target
        self.src = Source()

    # ---- parameters, read once before the loop
    def parameters(self) -> None:
        s, law = self.src, self.shape.law
        if law in ("svk", "neohooke"):
            s("mu, lm = P[0], P[1]")
        if law == "svk":
            s("tmu = 2.0 * mu")
            s("lm2mu = lm + tmu")
            s("hlm = 0.5 * lm")
        elif law == "decoupled":
            s("k0 = P[0]")
            s("tk0 = 2.0 * k0")
            # hoists what depends on the parameters only
            self.psi_calls, self.psi_cell = _declared_psi(s, self.shape)
        elif law == "ogden":
            s("c, q, r, alpha, k0 = P[0], P[1], P[2], P[3], P[4]")
            s("qm1 = q - 1.0")
            s("ma3 = -alpha / 3.0")
            s("tk0 = 2.0 * k0")
            s("qqm1 = q * qm1")
            s("rr = r * r")
        elif law == "costa":
            s("ca, k0 = P[0], P[1]")
            s("ha = 0.5 * ca")
            if not self.shape.per_cell_T:
                self._load_T("0")

    def _load_T(self, cell: str) -> None:
        for I, K in UPPER6:
            self.src(f"T{I}{K} = Tt[{cell}, {I}, {K}]")

    # ---- kinematics: F, J, C and (if the law reads them) C^-1, ln J
    def kinematics(self) -> None:
        s = self.src
        gather_cell(s)
        s(
            "J = F00 * (F11 * F22 - F12 * F21) - F01 * (F10 * F22 - F12 * F20) + F02 * (F10 * F21 "
            "- F11 * F20)"
        )
        s("J_out[e] = J")
        for i, j in VOIGT:
            s(f"{_c(i, j)} = F0{i} * F0{j} + F1{i} * F1{j} + F2{i} * F2{j}")
        s("vol = V0[e]")
        if self.shape.law == "svk":
            return
        s("L = math.log(J)")
        s("idet = 1.0 / (J * J)")  # C^-1 = adj(C) / det C, det C = J^2
        s("Ci00 = (C11 * C22 - C12 * C12) * idet")
        s("Ci11 = (C00 * C22 - C02 * C02) * idet")
        s("Ci22 = (C00 * C11 - C01 * C01) * idet")
        s("Ci01 = (C02 * C12 - C01 * C22) * idet")
        s("Ci12 = (C02 * C01 - C00 * C12) * idet")
        s("Ci02 = (C01 * C12 - C02 * C11) * idet")

    def ci(self) -> Vec6:
        return [_ci(i, j) for i, j in VOIGT]

    def odot(self) -> Sym6:
        """C^-1 (.) C^-1, (A_ik A_jl + A_il A_jk) / 2 for I = (i, j), K = (k, l); where both
        products are the same it is that product (exact: 0.5 (p + p) = p).
        """
        out = {}
        for I, K in UPPER6:
            (i, j), (k, l) = VOIGT[I], VOIGT[K]
            p1, p2 = sorted((_ci(i, k), _ci(j, l))), sorted((_ci(i, l), _ci(j, k)))
            expr = (
                f"{p1[0]} * {p1[1]}"
                if p1 == p2
                else f"0.5 * ({p1[0]} * {p1[1]} + {p2[0]} * {p2[1]})"
            )
            out[I, K] = self.src.let(f"od{I}{K}", expr)
        return out

    # ---- the laws: stress(W, S) on every path, tangent(CC) only when the stiffness is wanted
    def stress(self) -> Tuple[str, Vec6]:
        """W and S (named S0 ... S5, structural zeros kept as None)."""
        W, S = getattr(self, f"_{self.shape.law}_stress")()
        return W, [self.src.let(f"S{I}", S[I]) for I in range(6)]

    def tangent(self) -> Sym6:
        """CC (named CC{I}{K}, upper triangle)."""
        CC = getattr(self, f"_{self.shape.law}_tangent")()
        return {ik: self.src.let(f"CC{ik[0]}{ik[1]}", CC[ik]) for ik in UPPER6}

    def _svk_stress(self) -> Tuple[str, Vec6]:
        s = self.src
        for I, (i, j) in enumerate(VOIGT):
            s(f"E{I} = 0.5 * ({_c(i, j)} - 1.0)" if i == j else f"E{I} = 0.5 * {_c(i, j)}")
        s("trE = 0.5 * (C00 + C11 + C22) - 1.5")
        W = s.let(
            "W",
            "hlm * trE * trE + mu * (E0 * E0 + E1 * E1 + E2 * E2 + 2.0 * (E3 * E3 + E4 * E4 + E5 * "
            "E5))",
        )
        s("lt = lm * trE")
        return W, [f"tmu * E{I} + lt" if I < 3 else f"tmu * E{I}" for I in range(6)]

    def _svk_tangent(self) -> Sym6:
        # lm I (x) I + 2 mu II: constant, nine of 21 entries non-zero
        return {
            (I, K): ("lm2mu" if I == K else "lm") if K < 3 else ("mu" if I == K else None)
            for I, K in UPPER6
        }

    def _neohooke_stress(self) -> Tuple[str, Vec6]:
        s = self.src
        W = s.let("W", "0.5 * mu * (C00 + C11 + C22 - 3.0) - mu * L + 0.5 * lm * L * L")
        s("sa = lm * L - mu")
        return W, [add(mul("sa", c), "mu" if I < 3 else None) for I, c in enumerate(self.ci())]

    def _neohooke_tangent(self) -> Sym6:
        s = self.src
        od = self.odot()
        ci = self.ci()
        s("sb = 2.0 * (mu - lm * L)")
        return {(I, K): add(mul("lm", ci[I], ci[K]), mul("sb", od[I, K])) for I, K in UPPER6}

    def _psi(self) -> Tuple[str, Expr, Expr, Expr]:
        """Psi(I1b, I2b) and its derivatives Psi_1, Psi_2, Psi_11 written into the cell loop
        (the decoupled tangent below takes Psi_12 = Psi_22 = 0); returns their names.
        """
        s = self.src
        for name, call in self.psi_calls:
            s(f"{name} = {call}")
        psi_v, p1, p2, p11, p12, p22 = self.psi_cell
        if p12 is not None or p22 is not None:
            raise NotImplementedError(
                f"{self.shape.psi!r}: the compiled decoupled law needs Psi_12 = Psi_22 = 0"
            )
        return s.let("psi_v", psi_v), s.let("p1", p1), s.let("p2", p2), s.let("p11", p11)

    def _decoupled_stress(self) -> Tuple[str, Vec6]:
        """S_iso = J^(-2/3) Sb - tr/3 C^-1, Sb = 2 (Psi1 + I1b Psi2) I - 2 Psi2 Cb, plus
        S_vol = k0 ln J C^-1.
        """
        s = self.src
        s("I1 = C00 + C11 + C22")
        s("j23 = J ** (-2.0 / 3.0)")
        s("I1b = j23 * I1")
        reads = [e for e in self.psi_cell if e is not None] + [c for _, c in self.psi_calls]
        if any("I2b" in e for e in reads):
            s(
                "I2 = 0.5 * (I1 * I1 - (C00 * C00 + C11 * C11 + C22 * C22 + 2.0 * (C01 * C01 + C12 "
                "* C12 + C02 * C02)))"
            )
            s("I2b = j23 * j23 * I2")
        psi_v, p1, p2, p11 = self._psi()
        self.p2, self.p11 = p2, p11
        W = s.let("W", f"{psi_v} + 0.5 * k0 * L * L")
        cv = [_c(i, j) for i, j in VOIGT]
        # j23 Sb = 2 j23 (Psi1 + I1b Psi2) I - 2 Psi2 j23^2 C
        sn = s.let("sn", mul("2.0", "j23", add(p1, mul("I1b", p2))))
        m2 = s.let("m2", mul("-2.0", p2, "j23", "j23")) if p2 else None
        jSb = [add(mul(m2, cv[I]), sn if I < 3 else None) for I in range(6)]
        weights = ["1.0", "1.0", "1.0", "2.0", "2.0", "2.0"]
        s.let("tr", add(*[mul(weights[I], jSb[I], cv[I]) for I in range(6)]))
        s("tr3 = tr * (1.0 / 3.0)")
        ci = self.ci()
        self.Siso = [s.let(f"Si{I}", add(jSb[I], neg(mul("tr3", ci[I])))) for I in range(6)]
        s("kL = k0 * L")
        return W, [add(self.Siso[I], mul("kL", ci[I])) for I in range(6)]

    def _decoupled_tangent(self) -> Sym6:
        """CC = P CCb P^T + 2/3 tr (C^-1 (.) C^-1 - C^-1 (x) C^-1 / 3) - 2/3 (C^-1 (x) S_iso +
        S_iso (x) C^-1) + k0 C^-1 (x) C^-1 - 2 k0 ln J C^-1 (.) C^-1, with P = Id - C^-1 (x) w,
        w = W o C / 3 (Voigt weights W), so P CCb P^T = CCb - C^-1 (x) v - v (x) C^-1
        + (w . v) C^-1 (x) C^-1, v = CCb w: all rank-one updates.
        """
        s = self.src
        p2, p11 = self.p2, self.p11
        # CCb = j43 [a I (x) I + 4 Psi22 Cb (x) Cb - 4 Psi2 II] (Psi12 = Psi22 = 0 here)
        s("j43 = j23 * j23")
        ja = s.let("ja", mul("4.0", "j43", add(p11, p2)))
        jp = (
            s.let("jp", mul("-4.0", "j43", p2)) if p2 else None
        )  # -4 j43 Psi2 on the normal diagonal
        hjp = (
            s.let("hjp", mul("0.5", jp)) if jp else None
        )  # and half of it on the shear one (II = 1/2)
        CCb: Sym6 = {}
        for I, K in UPPER6:
            CCb[I, K] = s.let(
                f"Cb{I}{K}", add(ja if K < 3 else None, (jp if I < 3 else hjp) if I == K else None)
            )
        cv = [_c(i, j) for i, j in VOIGT]
        w = [
            s.let(f"w{L}", mul("0.3333333333333333" if L < 3 else "0.6666666666666666", cv[L]))
            for L in range(6)
        ]
        v = [s.let(f"v{I}", add(*[mul(cc(CCb, I, L), w[L]) for L in range(6)])) for I in range(6)]
        wv = add(*[mul(w[L], v[L]) for L in range(6)])
        s(f"alpha = {wv or '0.0'} - (2.0 / 9.0) * tr + k0")
        s("beta = (2.0 / 3.0) * tr - tk0 * L")
        ci = self.ci()
        # u = -(v + 2/3 S_iso): the coefficient of the symmetric outer product with C^-1
        u = [
            s.let(f"u{I}", neg(add(v[I], mul("0.6666666666666666", self.Siso[I]))))
            for I in range(6)
        ]
        od = self.odot()
        return {
            (I, K): add(
                cc(CCb, I, K),
                mul(ci[I], u[K]),
                mul(u[I], ci[K]),
                mul("alpha", ci[I], ci[K]),
                mul("beta", od[I, K]),
            )
            for I, K in UPPER6
        }

    def _ogden_stress(self) -> Tuple[str, Vec6]:
        """S_iso = sum_i 2 w_i N_i (x) N_i, w_i = c P (q lam_i^(q-1) + r Sigma / lam_i)."""
        s = self.src
        s("eig = eigh3_sym(C00, C01, C02, C11, C12, C22)")
        s("lam0, lam1, lam2 = eig[0], eig[1], eig[2]")
        for i in range(3):  # N{i}{n}: component i of eigenvector n
            s(
                ", ".join(f"N{i}{n}" for n in range(3))
                + f" = eig[{3 + 3 * i}], eig[{4 + 3 * i}], eig[{5 + 3 * i}]"
            )
        for n in range(3):
            s(f"lq{n} = lam{n} ** qm1")
            s(f"il{n} = 1.0 / lam{n}")
        s("sigma = lq0 * lam0 + lq1 * lam1 + lq2 * lam2")
        s("Pj = J ** ma3")
        s("cP = c * Pj")
        s("rs = r * sigma")
        for n in range(3):
            s(f"tw{n} = 2.0 * cP * (q * lq{n} + rs * il{n})")
        for I, (i, j) in enumerate(VOIGT):  # M{I}{n}: Voigt entry I of N_n (x) N_n
            for n in range(3):
                s(f"M{I}{n} = N{i}{n} * N{j}{n}")
        W = s.let("W", "c * (Pj * sigma - 3.0) + 0.5 * k0 * L * L")
        s("kL = k0 * L")
        ci = self.ci()
        return W, [f"M{I}0 * tw0 + M{I}1 * tw1 + M{I}2 * tw2 + kL * {ci[I]}" for I in range(6)]

    def _ogden_tangent(self) -> Sym6:
        """sum_ij 4 c P H_ij M_i (x) M_j + sum_{i<j} theta_ij G_ij (x) G_ij + the volumetric
        part.
        """
        s = self.src
        s("c4 = 4.0 * cP")
        for n in range(3):
            s(f"ql{n} = q * lq{n}")
        for i in range(3):
            for j in range(i, 3):
                h = f"r * (ql{i} * il{j} + ql{j} * il{i}) + rr * sigma * il{i} * il{j}"
                if i == j:  # lam^(q-2) = lam^(q-1) / lam
                    h += f" + qqm1 * lq{i} * il{i} - rs * il{i} * il{i}"
                s(f"H{i}{j} = c4 * ({h})")
        H = lambda i, j: f"H{min(i, j)}{max(i, j)}"  # noqa: E731
        for I in range(6):
            for j in range(3):
                s(f"MH{I}{j} = " + " + ".join(f"M{I}{l} * {H(l, j)}" for l in range(3)))
        out = {(I, K): f"MH{I}0 * M{K}0 + MH{I}1 * M{K}1 + MH{I}2 * M{K}2" for I, K in UPPER6}
        for p, (i, j) in enumerate(((0, 1), (1, 2), (0, 2))):
            s(f"t = math.log(lam{i} / lam{j})")
            s("ratio = qm1 if t == 0.0 else math.expm1(qm1 * t) / math.expm1(t)")
            s(f"th{p} = 2.0 * cP * (q * lq{j} * il{j} * ratio - rs * il{i} * il{j})")
            for I, (k, l) in enumerate(VOIGT):
                s(f"G{p}_{I} = N{k}{i} * N{l}{j} + N{k}{j} * N{l}{i}")
                s(f"tG{p}_{I} = th{p} * G{p}_{I}")
        od = self.odot()
        ci = self.ci()
        s("mkL = -tk0 * L")
        return {
            (I, K): add(
                out[I, K],
                *[f"tG{p}_{I} * G{p}_{K}" for p in range(3)],
                mul("k0", ci[I], ci[K]),
                mul("mkL", od[I, K]),
            )
            for I, K in UPPER6
        }

    def _costa_stress(self) -> Tuple[str, Vec6]:
        """Q = 1/2 E : T : E, q = T : E; S = Psi_Q q + J Psi_J C^-1."""
        s = self.src
        if self.shape.per_cell_T:
            self._load_T("e")
        T = {ik: f"T{ik[0]}{ik[1]}" for ik in UPPER6}
        for I, (i, j) in enumerate(
            VOIGT
        ):  # engineering strain: the shear entries are 2 E_ij = C_ij
            s(f"ee{I} = 0.5 * ({_c(i, j)} - 1.0)" if i == j else f"ee{I} = {_c(i, j)}")
        for I in range(6):
            s(f"qv{I} = " + " + ".join(f"{cc(T, I, K)} * ee{K}" for K in range(6)))
        s("Q = 0.5 * (" + " + ".join(f"ee{I} * qv{I}" for I in range(6)) + ")")
        s("j43 = J ** (-4.0 / 3.0)")
        s("ex = ha * math.exp(j43 * Q)")
        s("pQ = ex * j43")
        s("pJ = -4.0 / 3.0 * ex * Q * j43 / J + k0 * L")
        s("JpJ = J * pJ")
        W = s.let("W", "ha * math.expm1(j43 * Q) + k0 * (J * L - J + 1.0)")
        ci = self.ci()
        return W, [f"pQ * qv{I} + JpJ * {ci[I]}" for I in range(6)]

    def _costa_tangent(self) -> Sym6:
        s = self.src
        s("pQQ = ex * j43 * j43")
        s("JpQJ = J * (-4.0 / 3.0 * ex * j43 / J * (1.0 + j43 * Q))")
        s("pJJ = ex * (16.0 / 9.0 * Q * Q * j43 * j43 + 28.0 / 9.0 * Q * j43) / (J * J) + k0 / J")
        s("cA = J * (J * pJJ + pJ)")
        s("cB = -2.0 * JpJ")
        od = self.odot()
        ci = self.ci()
        return {
            (
                I,
                K,
            ): f"pQQ * qv{I} * qv{K} + JpQJ * (qv{I} * {ci[K]} + {ci[I]} * qv{K}) + pQ * T{I}{K} "
            f"+ cA * {ci[I]} * {ci[K]} + cB * {od[I, K]}"
            for I, K in UPPER6
        }

    # ---- the element: force, B, CC B, the blocks, the scatter
    def force(self, S: Vec6) -> None:
        """SD_a = V0 S D_a (kept for the geometric stiffness), f_a = -F SD_a."""
        s = self.src
        Sv = [s.let(f"Sv{I}", mul("vol", S[I])) for I in range(6)]
        for a in range(4):
            for i in range(3):
                s(
                    f"SD{a}{i} = "
                    + (add(*[mul(Sv[_V[i, k]], f"D{a}{k}") for k in range(3)]) or "0.0")
                )
        with s.block("if want_force:"):
            for a in range(4):
                for k in range(3):
                    self.target.add_force(
                        s, a, k, f"F{k}0 * SD{a}0 + F{k}1 * SD{a}1 + F{k}2 * SD{a}2"
                    )

    def stiffness(self, CC: Sym6) -> None:
        s = self.src
        CCv = {ik: s.let(f"CCv{ik[0]}{ik[1]}", mul("vol", CC[ik])) for ik in UPPER6}
        for a in range(
            4
        ):  # B_a[I, k] = D_a,j F_k,i + D_a,i F_k,j for I = (i, j) (once on the diagonal)
            for I, (i, j) in enumerate(VOIGT):
                for k in range(3):
                    s(
                        f"B{a}_{I}{k} = "
                        + (
                            f"D{a}{i} * F{k}{i}"
                            if i == j
                            else f"D{a}{j} * F{k}{i} + D{a}{i} * F{k}{j}"
                        )
                    )
        for b in range(4):  # CB_b = V0 CC B_b
            for I in range(6):
                for l in range(3):
                    s(
                        f"CB{b}_{I}{l} = "
                        + (add(*[mul(cc(CCv, I, L), f"B{b}_{L}{l}") for L in range(6)]) or "0.0")
                    )

        def block(a: int, b: int, k: int, l: int) -> str:
            return add(
                *[f"B{a}_{I}{k} * CB{b}_{I}{l}" for I in range(6)], f"g{a}{b}" if k == l else None
            )

        for a in range(4):
            for b in range(a, 4):
                s(f"g{a}{b} = D{a}0 * SD{b}0 + D{a}1 * SD{b}1 + D{a}2 * SD{b}2")
        self.target.before_blocks(s)
        for kk, (a, b) in enumerate(EDGES):  # edge blocks, then out of the cell
            for k in range(3):
                for l in range(3):
                    s(f"K{k}{l} = {block(a, b, k, l)}")
            self.target.edge_block(s, kk, a, b)
        for a in range(4):  # node blocks: symmetric, six entries
            for k in range(3):
                for l in range(k, 3):
                    s(f"K{k}{l} = {block(a, a, k, l)}")
            self.target.node_block(s, a)

    # ---- the module
    def cell(self) -> None:
        """Write the body of the loop over cells e (everything one cell contributes)."""
        s = self.src
        self.kinematics()
        W, S = self.stress()
        self.target.add_energy(s, f"vol * {W}")
        with s.block("if want_force or want_stiffness:"):
            self.force(S)
            with s.block("if want_stiffness:"):
                self.stiffness(self.tangent())

    def module(self) -> str:
        self.target.module(self)
        return self.src.text()


# ------------------------------------------------------------------ targets
class ClassicalTarget(Target):
    """The serial CPU kernel ``classical_cells`` of :data:`KERNEL_SIGNATURE`: MJED's serial
    target (:class:`mjed.compiled.codegen.Target`: energy and force added in the loop), with
    the classical element's blocks added into the mesh-edge sums U (each edge block,
    transposed when the cell edge runs against the mesh edge) and the node sums Dg (each node
    block, formed by the element), then every CSR entry written once.
    """

    def before_blocks(self, s: Source) -> None:
        """Anything the block writes need once per cell (nothing here)."""

    def edge_block(self, s: Source, k: int, a: int, b: int) -> None:
        """The block (a, b) of cell edge k, locals K{r}{c}, out of the cell."""
        scatter_edge_block(s, k, "K")

    def node_block(self, s: Source, a: int) -> None:
        """The node block (a, a), symmetric, locals K{r}{c} for r <= c, out of the cell."""
        for k in range(3):
            for l in range(3):
                s(f"Dg[n{a}, {k}, {l}] += K{min(k, l)}{max(k, l)}")

    def module(self, writer: "_Classical") -> None:
        write_kernel_module(
            writer.src,
            "Classical Galerkin kernel generated by reference_fem.classical_codegen for one law; "
            f"do not edit.\n\nshape: {writer.shape!r}",
            ["from mjed.compiled.kernels import JIT_OPTIONS, eigh3_sym, write_csr"],
            "classical_cells",
            KERNEL_SIGNATURE,
            _KERNEL_DOC,
            writer.parameters,
            writer.cell,
        )


SERIAL_CLASSICAL = ClassicalTarget()

#: The arguments of the generated CUDA ``classical_cells`` and ``classical_force``, in order
#: (the launch order of mjed.cuda.launch.CellLauncher).
CUDA_SIGNATURE = CLASSICAL_INPUTS + CUDA_ASSEMBLY_ARGS


class ClassicalCudaTarget(CudaTarget):
    """The CUDA kernels ``classical_cells`` and ``classical_force`` of :data:`CUDA_SIGNATURE`
    in ``dtype``: the MJED CUDA target (:class:`mjed.cuda.codegen.CudaTarget`: one thread per
    cell, E_out[e] = its energy, the force by atomic adds, FP32 by the same source rewrite),
    each block added straight into the CSR values through the per-mesh block map: the edge
    block (a, b) and its transpose at (b, a), the node block (a, a); 144 atomic adds per cell,
    as MJED's kernel; or, with ``assembly=Assembly.ELEMENT``, stored per cell for the
    gather kernel, as MJED's (:class:`mjed.cuda.codegen.Assembly`, the before_blocks and
    block methods inherited). The edge assembly (:attr:`mjed.cuda.codegen.Assembly.EDGE`) is
    MJED's alone: refused here.
    """

    def __init__(self, dtype=np.float64, assembly=Assembly.ATOMIC):
        super().__init__(dtype, assembly)
        if self.assembly is Assembly.EDGE:
            raise NotImplementedError(
                "the classical element has no edge assembly (MJED's alone): atomic or element"
            )

    def edge_block(self, s: Source, k: int, a: int, b: int) -> None:
        self.block(s, a, b, lambda r, c: f"K{r}{c}")
        self.block(s, b, a, lambda r, c: f"K{c}{r}")

    def node_block(self, s: Source, a: int) -> None:
        self.block(s, a, a, lambda r, c: f"K{min(r, c)}{max(r, c)}")

    def module(self, writer: "_Classical") -> None:
        write_cuda_module(
            writer,
            f"Classical Galerkin CUDA kernel ({self.dtype.name}{self.title_note}) generated by "
            "reference_fem.classical_codegen for one law; do not edit.",
            ("classical_cells", "classical_force"),
            CUDA_SIGNATURE,
            self.dtype,
        )


class _Sym:
    """An expression of the generated source, written by evaluating a declared Psi on it.

    ``const`` marks an expression of the parameters only: when it meets a per-cell one, it is
    named before the loop (:class:`_Hoist`), so the loop computes no parameter arithmetic.
    """

    def __init__(self, text: str, const: bool, hoist: "_Hoist"):
        self.text, self.const, self.hoist = text, const, hoist

    def _wrap(self, other) -> "_Sym":
        if isinstance(other, _Sym):
            return other
        # a float literal, ints too: int64 * float32 is float64 to Numba (integer powers are
        # products, see _integer_power)
        text = repr(float(other))
        return _Sym(text, True, self.hoist)

    def _op(self, a, b, op: str) -> "_Sym":
        a, b = self._wrap(a), self._wrap(b)
        if op == "+" and a.text in ("0", "0.0"):  # what sum() starts from
            return b
        if a.const and b.const:
            return _Sym(f"({a.text} {op} {b.text})", True, self.hoist)
        text = f"({self.hoist(a)} {op} {self.hoist(b)})"
        if op == "*" and not a.const and not b.const:  # a power of cell values, e.g. I1b^2:
            return _Sym(self.hoist.cell(text), False, self.hoist)  # formed once, then reused
        return _Sym(text, False, self.hoist)

    def __add__(self, o):
        return self._op(self, o, "+")

    def __radd__(self, o):
        return self._op(o, self, "+")

    def __sub__(self, o):
        return self._op(self, o, "-")

    def __rsub__(self, o):
        return self._op(o, self, "-")

    def __mul__(self, o):
        return self._op(self, o, "*")

    def __rmul__(self, o):
        return self._op(o, self, "*")

    def __truediv__(self, o):
        return self._op(self, o, "/")

    def __rtruediv__(self, o):
        return self._op(o, self, "/")

    def __pow__(self, o):
        if isinstance(o, int) and not isinstance(o, bool):
            return self._integer_power(o)
        return self._op(self, o, "**")

    def _integer_power(self, k: int) -> "_Sym":
        """The integer power x ** k as products (1 / x ** -k for k < 0): Numba types
        float32 ** int64 as float64, which would put double arithmetic in the FP32 CUDA kernel.
        """
        if k < 0:
            return self._op(1.0, self._integer_power(-k), "/")
        result = self._wrap(1.0)
        for _ in range(k):
            result = self if result.text == "1.0" else self._op(result, self, "*")
        return result

    def __rpow__(self, o):
        return self._op(o, self, "**")

    def __neg__(self):
        return self._op(0.0, self, "-")


class _Hoist:
    """Names a parameter-only expression before the loop (once per distinct text), and keeps
    the per-cell function calls and products of cell values (``cell_lets``, written at the
    top of the cell's Psi) so that one used by Psi and its derivatives is formed once.
    """

    def __init__(self, src: Source):
        self.src, self.names = src, {}
        self.cell_lets: List[Tuple[str, str]] = []

    def cell(self, text: str) -> str:
        """The name of a per-cell expression, assigned once in the cell."""
        for name, known in self.cell_lets:
            if known == text:
                return name
        name = f"pc{len(self.cell_lets)}"
        self.cell_lets.append((name, text))
        return name

    def __call__(self, e: _Sym) -> str:
        if not e.const or _SIMPLE_NAME.match(e.text):
            return e.text
        if e.text not in self.names:
            self.names[e.text] = self.src.let(f"hp{len(self.names)}", e.text)
        return self.names[e.text]


_SIMPLE_NAME = re.compile(r"^-?([A-Za-z_][A-Za-z0-9_]*|[0-9.e+-]+)$")


class _SourceMath:
    """The m of a declared Psi for the source writer: m.exp, m.log write math.exp, math.log."""

    def __init__(self, hoist: _Hoist):
        self.hoist = hoist

    def _call(self, name: str, x) -> _Sym:
        x = x if isinstance(x, _Sym) else _Sym(repr(float(x)), True, self.hoist)
        if x.const:
            return _Sym(f"math.{name}({x.text})", True, self.hoist)
        return _Sym(self.hoist.cell(f"math.{name}({x.text})"), False, self.hoist)

    def exp(self, x):
        return self._call("exp", x)

    def log(self, x):
        return self._call("log", x)


def _declared_psi(src: Source, shape: LawShape) -> Tuple[List[Tuple[str, str]], Tuple[Expr, ...]]:
    """Evaluate the shape's declared Psi on symbols: the parameters P[1], P[2], ... (read and
    combined before the loop) and the per-cell I1b, I2b. Returns the cell's named function
    calls (name, expression), to be written first, and the six cell expressions (Psi, Psi_1,
    Psi_2, Psi_11, Psi_12, Psi_22), None where the declaration gives 0.
    """
    hoist = _Hoist(src)
    names = {}
    for k, name in enumerate(shape.psi_parameters, start=1):
        names[name] = _Sym(src.let(f"prm_{name}", f"P[{k}]"), True, hoist)
    params = type("PsiParameters", (), names)()
    I1b, I2b = _Sym("I1b", False, hoist), _Sym("I2b", False, hoist)
    out = shape.psi.function(params, I1b, I2b, _SourceMath(hoist))
    exprs: List[Expr] = []
    for e in out:
        if isinstance(e, _Sym):
            exprs.append(hoist(e) if e.const else e.text)
        elif e == 0:
            exprs.append(None)  # structurally zero: its terms are dropped
        else:
            exprs.append(repr(float(e)))
    return hoist.cell_lets, tuple(exprs)


def classical_source(shape: LawShape, target: ClassicalTarget = None) -> str:
    """The source of the classical kernel module for ``shape``: the serial CPU kernel (its
    function ``classical_cells``), or the module of ``target`` (:class:`ClassicalCudaTarget`).
    """
    return _Classical(shape, target).module()
