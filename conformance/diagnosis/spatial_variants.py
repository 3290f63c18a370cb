"""Mistakes of an updated-Lagrangian element: its spatial tangent c in a wrong form, or one part
of its element matrix in another local dof order.

An engine written with the Cauchy stress sigma, the spatial tangent c (6 x 6 Voigt), B matrices
from grad N = D F^-1 and integrals over v = J V0 computes, per cell,

    K_e = v B^T c B + v (grad N_a . sigma grad N_b) I,    f_a = -v sigma grad N_a.

From the oracle's per-cell stress and tangent (the element split's S and CC,
:mod:`conformance.diagnosis.invariant_pieces`), pushed forward by
:func:`conformance.diagnosis.spatial_tangent.spatial_cells`, c = F F F F : CC / J and
sigma = F S F^T / J are exact, so each family mistake below predicts the engine's force and
stiffness with nothing fitted:

1. **Voigt unpacking** (:data:`VOIGT_SLIPS` on the targets of :data:`SLIP_TARGETS`). A
   tangent or stress packed in Abaqus' Voigt order (11, 22, 33, 12, 13, 23) and unpacked with a
   slip: the shear slots read in another order (any of the five other orders of 12, 13, 23;
   c filled in Abaqus' order while B uses FEBio's is the exchange of 13 and 23), a factor 2 or
   1/2 on the shear rows, columns or both (engineering against tensor shear), or the
   minor-symmetric mirror entries left zero (only the slots i <= j, k <= l filled). The slip
   hits c alone, or the UMAT's DDSDDE = c + (the Jaumann terms) before the driver removes those
   terms, or sigma together with c or DDSDDE (then the force is wrong too).
2. **Tensor shear rows in B.** B's shear rows (v_i,j + v_j,i)/2 instead of engineering shear:
   the shear rows of B halved, so the force sees sigma's shear halved and B^T c B its shear
   rows and columns halved.
3. **Objective rate.** The tangent of the Jaumann rate of the Kirchhoff stress (Abaqus UMAT's
   DDSDDE / J) used as c: c + (d_ik s_jl + s_ik d_jl + d_il s_jk + s_il d_jk) / 2 (stiffness
   only); its correction with the other sign is tested beside it, so that the sign is evidence.
   A perturbation tangent (Miehe's) that differences sigma instead of tau = J sigma is left
   with -sigma_ij delta_kl (the derivative of 1/J), a variant of the same kind.
4. **One part in another local order.** The geometric (initial-stress) block written
   kron(I3, G), component-major, inside a node-major element matrix (or the material part so
   while the geometric part is node-major): stiffness only.

A variant is named only when its prediction matches the engine within the case's tolerance and
is not the oracle's own; several that match are said as ambiguous by the caller. The numerical
variant (a perturbation tangent) may leave more, up to the round-off of its differences
(:data:`NUMERICAL`): then it is said as partly explaining, with what it leaves.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations
from typing import Callable, Dict, List, Sequence, Tuple

import numpy as np

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, PARTIAL, Finding
from conformance.diagnosis.invariant_pieces import CellTensors
from conformance.diagnosis.spatial_tangent import SpatialCells, material_stiffness, spatial_cells

__all__ = [
    "FEBIO",
    "ABAQUS",
    "jaumann_pieces",
    "VoigtSlip",
    "VOIGT_SLIPS",
    "SLIP_TARGETS",
    "slip_tensor",
    "slip_stress",
    "to_voigt",
    "from_voigt",
    "jaumann_terms",
    "TANGENT_VARIANTS",
    "PART_ORDERS",
    "spatial_variant_findings",
]

#: FEBio's Voigt order of the index pairs: xx, yy, zz, xy, yz, xz.
FEBIO = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))

#: Abaqus' Voigt order (a UMAT's STRESS and DDSDDE): 11, 22, 33, 12, 13, 23.
ABAQUS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))

_EYE = np.eye(3)


def _pack(c: np.ndarray, order: Sequence[Tuple[int, int]]) -> np.ndarray:
    """(m, 6, 6) the Voigt matrix of c (m, 3, 3, 3, 3) in ``order`` (six index pairs)."""
    i = np.array([p[0] for p in order])
    j = np.array([p[1] for p in order])
    return c[:, i[:, None], j[:, None], i[None, :], j[None, :]]


def _unpack(C6: np.ndarray, order: Sequence[Tuple[int, int]], mirror: bool = True) -> np.ndarray:
    """(m, 3, 3, 3, 3) the tensor of a Voigt matrix C6 (m, 6, 6) read in ``order``; mirror:
    the minor-symmetric entries (j, i), (l, k) filled too (else left zero).
    """
    idx = np.zeros((3, 3), dtype=int)
    filled = np.zeros((3, 3))
    for k, (i, j) in enumerate(order):
        idx[i, j] = k
        filled[i, j] = 1.0
        if mirror:
            idx[j, i] = k
            filled[j, i] = 1.0
    c = C6[:, idx[:, :, None, None], idx[None, None, :, :]]
    return c * (filled[:, :, None, None] * filled[None, None, :, :])


def to_voigt(c: np.ndarray) -> np.ndarray:
    """(m, 6, 6) the Voigt matrix of c (m, 3, 3, 3, 3) in :data:`FEBIO` order."""
    return _pack(c, FEBIO)


def from_voigt(C6: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) the minor-symmetric tensor of a Voigt matrix C6 (m, 6, 6), FEBio order:
    with engineering shear in B, B^T C6 B is this tensor contracted with grad N on both sides.
    """
    return _unpack(C6, FEBIO)


def _voigt_map(rows: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """The map c -> c' whose Voigt matrix is c's with its rows and columns scaled or moved by
    ``rows`` (6, 6): C6' = R C6 R^T.
    """
    return lambda c: from_voigt(rows @ to_voigt(c) @ rows.T)


_HALF = np.diag([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])


def jaumann_pieces(sigma: np.ndarray) -> np.ndarray:
    """(4, m, 3, 3, 3, 3) the four Jaumann-rate terms of sigma (m, 3, 3), each halved:
    d_ik s_jl / 2, s_ik d_jl / 2, d_il s_jk / 2, s_il d_jk / 2 (their sum: the correction that
    turns the Truesdell tangent c into a UMAT's DDSDDE, the Jaumann tangent of tau over J).
    """
    d = _EYE
    return 0.5 * np.stack(
        [
            np.einsum("ik,mjl->mijkl", d, sigma),
            np.einsum("mik,jl->mijkl", sigma, d),
            np.einsum("il,mjk->mijkl", d, sigma),
            np.einsum("mil,jk->mijkl", sigma, d),
        ]
    )


def jaumann_terms(sigma: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3, 3) the Jaumann-rate terms (d_ik s_jl + s_ik d_jl + d_il s_jk + s_il d_jk) / 2
    of the Cauchy stresses sigma (m, 3, 3): DDSDDE less c (the sum of :func:`jaumann_pieces`).
    """
    return jaumann_pieces(sigma).sum(axis=0)


def _jaumann(sign: float) -> Callable[[SpatialCells], np.ndarray]:
    """The Jaumann-rate terms (:func:`jaumann_terms`), times sign."""
    return lambda t: sign * jaumann_terms(t.sigma)


_PAIR = {(0, 1): "12", (0, 2): "13", (1, 2): "23"}


@dataclass(frozen=True)
class VoigtSlip:
    """A slip in unpacking a Voigt (Abaqus order) matrix and vector: read back in ``order``, rows
    and columns scaled by ``rows`` and ``cols`` (6,), the mirror entries filled or not.
    """

    code: str
    words: str
    order: Tuple[Tuple[int, int], ...] = ABAQUS
    rows: Tuple[float, ...] = (1.0,) * 6
    cols: Tuple[float, ...] = (1.0,) * 6
    mirror: bool = True
    stress: bool = True  # the slip has a meaning for the stress vector too


def _slips() -> Tuple[VoigtSlip, ...]:
    """The declared unpacking slips: the five other orders of the shear slots, a factor 2 or
    1/2 on the shear rows, columns or both, the mirror entries missing.
    """
    out = []
    for shear in permutations(ABAQUS[3:]):
        if shear == ABAQUS[3:]:
            continue
        names = ", ".join(_PAIR[p] for p in shear)
        out.append(
            VoigtSlip(
                "order-" + "-".join(_PAIR[p] for p in shear),
                "Voigt order of the shear slots: packed in Abaqus' order 11, 22, 33, 12, 13, 23 "
                f"and unpacked as 11, 22, 33, {names}",
                ABAQUS[:3] + tuple(shear),
            )
        )
    for f, name in ((2.0, "doubled"), (0.5, "halved")):
        k = (1.0, 1.0, 1.0, f, f, f)
        for where, rows, cols in (
            ("rows", k, (1.0,) * 6),
            ("columns", (1.0,) * 6, k),
            ("rows-and-columns", k, k),
        ):
            out.append(
                VoigtSlip(
                    f"shear-{where}-{name}",
                    f"the shear {where.replace('-', ' and ')} (12, 13, 23) of the Voigt tangent "
                    f"{name} when unpacked (engineering against tensor shear strain: "
                    "gamma = 2 eps)",
                    rows=rows,
                    cols=cols,
                    stress=False,
                )
            )
    out.append(
        VoigtSlip(
            "no-mirror",
            "the Voigt matrix unpacked into c_ijkl only at the pairs i <= j, k <= l: the "
            "minor-symmetric mirror entries c_jikl, c_ijlk (and sigma_ji) left zero",
            mirror=False,
        )
    )
    return tuple(out)


#: The declared unpacking slips (:class:`VoigtSlip`).
VOIGT_SLIPS: Tuple[VoigtSlip, ...] = _slips()

#: What a slip hits -> (words, sigma slipped too, the slip applied to DDSDDE = c + Jaumann
#: terms (removed after unpacking, from the sigma the driver has) rather than to c).
SLIP_TARGETS: Dict[str, Tuple[str, bool, bool]] = {
    "c": ("the spatial tangent c alone (force right)", False, False),
    "ddsdde": (
        "the UMAT's DDSDDE (c plus the Jaumann-rate terms, removed after unpacking; force right)",
        False,
        True,
    ),
    "stress-c": ("the Cauchy stress and the spatial tangent c (force wrong too)", True, False),
    "stress-ddsdde": (
        "STRESS and DDSDDE both (the Jaumann-rate terms then removed with the unpacked "
        "stress; force wrong too)",
        True,
        True,
    ),
}


def slip_tensor(c: np.ndarray, slip: VoigtSlip) -> np.ndarray:
    """(m, 3, 3, 3, 3) c (minor-symmetric) packed in Abaqus' order and unpacked with ``slip``."""
    C6 = _pack(c, ABAQUS) * np.asarray(slip.rows)[:, None] * np.asarray(slip.cols)[None, :]
    return _unpack(C6, slip.order, slip.mirror)


def slip_stress(sigma: np.ndarray, slip: VoigtSlip) -> np.ndarray:
    """(m, 3, 3) sigma packed in Abaqus' order and unpacked with ``slip`` (its rows' factor)."""
    s6 = sigma[:, [p[0] for p in ABAQUS], [p[1] for p in ABAQUS]] * np.asarray(slip.rows)
    out = np.zeros_like(sigma)
    for k, (i, j) in enumerate(slip.order):
        out[:, i, j] = s6[:, k]
        if slip.mirror:
            out[:, j, i] = s6[:, k]
    return out


#: (slip code, target) named with an older code (kept stable for the reports that use it).
_LEGACY = {("order-12-23-13", "c"): "voigt-abaqus-order"}


#: code -> (words, the engine's c minus the right c (SpatialCells -> (m, 3, 3, 3, 3)), the
#: factor on sigma's shear in the force (1: the force right)).
TANGENT_VARIANTS: Dict[str, tuple] = {
    "tensor-shear-b": (
        "B written with tensor shear rows (v_i,j + v_j,i)/2 where Voigt's engineering shear "
        "strain v_i,j + v_j,i belongs: the shear rows of B halved, so the shear part of the "
        "force is halved and B^T c B has its shear rows and columns halved",
        lambda t: _voigt_map(_HALF)(t.c) - from_voigt(to_voigt(t.c)),
        0.5,
    ),
    "jaumann": (
        "the tangent of the Jaumann rate of the Kirchhoff stress (Abaqus UMAT's DDSDDE / J: "
        "c + (d_ik sigma_jl + sigma_ik d_jl + d_il sigma_jk + sigma_il d_jk)/2) used as the "
        "spatial tangent c beside the geometric stiffness: the objective-rate correction not "
        "subtracted",
        _jaumann(1.0),
        1.0,
    ),
    "jaumann-subtracted": (
        "the Jaumann-rate terms (d_ik sigma_jl + sigma_ik d_jl + d_il sigma_jk + sigma_il "
        "d_jk)/2 subtracted from the spatial tangent c (an objective-rate correction applied "
        "to a tangent that did not carry it)",
        _jaumann(-1.0),
        1.0,
    ),
    "miehe-cauchy": (
        "the derivative of J left out of the tangent of J sigma (c left with a -sigma_ij "
        "delta_kl term, not symmetric): the deformed volume v = J V0 held constant (dv/dx "
        "missing) where the force is v sigma grad N, or a perturbation tangent (Miehe's: F "
        "moved by eps sym(e_k e_l) F) that differences the Cauchy stress sigma where the "
        "Kirchhoff stress tau = J sigma belongs",
        lambda t: -np.einsum("mij,kl->mijkl", t.sigma, _EYE),
        1.0,
    ),
}

#: The unit round-off of double precision, u = 2^-53.
U = 2.0**-53

#: Variants that are numerical tangents (differences of the stress), and the stiffness error
#: they may leave beyond the tolerance, as a fraction of the variant's own term (the stiffness
#: of that term, i.e. of the prediction less the oracle, which the data give).
#:
#: Why sqrt(u), and why relative to the term. A difference quotient of a stress computed in
#: double with step eps carries that stress's rounding (a few u |sigma|) divided by eps, in
#: every column of c. Steps in use are at least sqrt(u) (~1.1e-8, the optimal step of
#: one-sided differences; below it round-off exceeds the truncation of any scheme, the case of
#: the finite-difference-roundoff reading), so the round-off left in c is at most about
#: sqrt(u) |sigma|, and its stiffness about sqrt(u) times that of a term of sigma's size: the
#: -sigma_ij delta_kl term itself (up to factors of order one from how the rounding falls; no
#: margin is added). The truncation of central differences, (eps^2 / 6) sigma''', is within
#: this for the usual steps (1e-6 to 1e-5; at 1e-4 it is comparable). A one-sided scheme's
#: truncation, (eps / 2) sigma'', is not: with any coarse step it is far beyond this, and is
#: not claimed here (the perturbation reading of
#: :mod:`conformance.diagnosis.perturbation_differences` fits a step to it). Anything else left
#: (another mistake beside the differences) is beyond this bound unless it is below the
#: differences' own round-off, where no reading can see it.
NUMERICAL = {"miehe-cauchy": U**0.5}

#: code -> words: the part of the element matrix written in component-major order.
PART_ORDERS: Dict[str, str] = {
    "geometric": "geometric (initial-stress) element block laid out component-major, "
    "kron(I3, G) instead of kron(G, I3), inside the node-major element matrix",
    "material": "material element block (B^T c B v) laid out component-major while the "
    "geometric block and the scatter are node-major",
}

#: Local dof i of a component-major 12-vector (i = 4 c + a) holds node-major dof 3 a + c.
_COMP_MAJOR = (3 * np.arange(4)[None, :] + np.arange(3)[:, None]).ravel()


def _material_part(t: SpatialCells, dc: np.ndarray) -> np.ndarray:
    """(m, 12, 12) v grad N_a . dc . grad N_b, node-major (local dof 3 a + i)."""
    Km = np.einsum("m,maj,mijkl,mbl->maibk", t.v, t.gN, dc, t.gN, optimize=True)
    return Km.reshape(-1, 12, 12)


def _shear_force(split: ElementSplit, t: SpatialCells, factor: float) -> np.ndarray:
    """(m, 4, 3) the element forces with sigma's off-diagonal scaled by ``factor``."""
    off = t.sigma - np.einsum("mii->mi", t.sigma)[:, :, None] * _EYE
    dfe = -(factor - 1.0) * np.einsum("m,mij,maj->mai", t.v, off, t.gN)
    return split.fe + dfe


def _slip_findings(
    split: ElementSplit, t: SpatialCells, matches: Callable[..., float]
) -> List[Finding]:
    """The unpacking slips of :data:`VOIGT_SLIPS` on the targets of :data:`SLIP_TARGETS` whose
    prediction (the oracle's sigma and c so unpacked, then assembled) matches the engine.
    """
    corr = jaumann_terms(t.sigma)
    found = []
    for slip in VOIGT_SLIPS:
        for target, (where, stress, ddsdde) in SLIP_TARGETS.items():
            if stress and not slip.stress:
                continue
            sigma = slip_stress(t.sigma, slip) if stress else t.sigma
            if ddsdde:
                c = slip_tensor(t.c + corr, slip) - jaumann_terms(sigma)
            else:
                c = slip_tensor(t.c, slip)
            ds = sigma - t.sigma
            geo = np.einsum("m,maj,mjl,mbl,ik->maibk", t.v, t.gN, ds, t.gN, _EYE)
            Ke = split.Ke + _material_part(t, c - t.c) + geo.reshape(-1, 12, 12)
            fe = split.fe - np.einsum("m,mij,maj->mai", t.v, ds, t.gN)
            left = matches(*assemble(split.cells, split.n, fe, Ke))
            if np.isfinite(left):
                code = _LEGACY.get((slip.code, target), f"voigt-{slip.code}-{target}")
                found.append(
                    Finding(
                        f"spatial-{code}",
                        f"Voigt unpacking of {where}: {slip.words}",
                        FULL,
                        "the oracle's per-cell stress and tangent pushed forward (sigma, c = "
                        "F F F F : CC / J), packed in Abaqus' Voigt order and unpacked so, the "
                        f"force and element matrices rebuilt: errors against your engine "
                        f"{left:.1e}",
                        {"slip": slip.code, "target": target, "residual": left},
                    )
                )
    return found


def spatial_variant_findings(
    split: ElementSplit,
    cells: CellTensors,
    matches: Callable[..., float],
    tolerance: float = 0.0,
) -> List[Finding]:
    """The spatial-tangent variants and part orders whose prediction matches the engine.

    cells: the oracle's per-cell stress S (m, 3, 3) and material tangent CC (m, 3, 3, 3, 3);
    matches(f, K, allowance): the engine's error against the prediction, inf unless within
    tolerance (a numerical variant: within its allowance of :data:`NUMERICAL`, a fraction of the
    prediction's own distance from the oracle) and the prediction differs from the oracle's (as
    in :mod:`conformance.diagnosis.hand_derived`); tolerance: the case's stiffness tolerance (a
    numerical variant beyond it is partial, and says what it leaves).
    """
    t = spatial_cells(split, cells.S, cells.CC)
    found = []
    for code, (words, dc, shear) in TANGENT_VARIANTS.items():
        Ke = split.Ke + _material_part(t, dc(t))
        fe = split.fe if shear == 1.0 else _shear_force(split, t, shear)
        left = matches(*assemble(split.cells, split.n, fe, Ke), NUMERICAL.get(code, 0.0))
        if np.isfinite(left):
            numerical = left > tolerance
            found.append(
                Finding(
                    f"spatial-{code}",
                    words,
                    PARTIAL if numerical else FULL,
                    "the oracle's per-cell stress and tangent pushed forward (sigma, c = "
                    "F F F F : CC / J, grad N = D F^-1, v = J V0), the element matrices "
                    f"rebuilt so: errors against your engine {left:.1e}"
                    + (
                        f", beyond the tolerance {tolerance:.0e}: not fully explained; what is "
                        f"left is below sqrt(u) = {NUMERICAL[code]:.1e} times this term's own "
                        "stiffness, the round-off that differences of the stress at a step of "
                        "sqrt(u) or more leave"
                        if numerical
                        else ""
                    ),
                    {"variant": code, "residual": left},
                )
            )
    found += _slip_findings(split, t, matches)
    # v grad N_a . sigma grad N_b = V0 D_a . S D_b: the geometric block the material way.
    geo = split.Ke - material_stiffness(split, cells.S)
    for part, words in PART_ORDERS.items():
        moved = geo if part == "geometric" else split.Ke - geo
        Ke = split.Ke - moved + moved[:, _COMP_MAJOR][:, :, _COMP_MAJOR]
        left = matches(*assemble(split.cells, split.n, split.fe, Ke))
        if np.isfinite(left):
            found.append(
                Finding(
                    f"element-part-order-{part}",
                    f"element dofs in another local order (one part only): {words}",
                    FULL,
                    "the oracle's element matrices split into the geometric part (from its "
                    "per-cell stress) and the rest, that part reordered so and assembled: "
                    f"errors against your engine {left:.1e}",
                    {"part": part, "residual": left},
                )
            )
    return found
