"""A user routine's packed second derivatives read wrongly by its driver (Abaqus UHYPER style).

Commercial codes let a user write an isotropic hyperelastic law as a routine that returns the
energy's derivatives in the isochoric invariants and J, packed::

    UI1 = (U_1, U_2, U_J),
    UI2 = (U_11, U_22, U_JJ, U_12, U_1J, U_2J)      (U_a = dU/dI_a, U_ab = d2U/dI_a dI_b,
                                                     I = (I1b, I2b, J)),

and a generic driver builds S = 2 sum_a U_a dI_a/dC and the material tangent::

    CC = 4 sum_a U_a d2I_a/dC2 + 4 sum_ab U_ab dI_a/dC (x) dI_b/dC.

The second derivatives enter the tangent alone (the force is right), each through a rank-one
pair of the gradients G_a = dI_a/dC, whose element matrix is 4 V0 g_a g_b^T with
g_a[node, i] = (F G_a D_node)_i. A driver that unpacks UI2 in another order (a row-wise
triangle of the 3x3 Hessian, two slots exchanged), counts a mixed derivative in one order only
(its transpose missing), or a routine that returns one entry off by a factor, changes the
stiffness by exactly sum_ab (U'_ab - U_ab) 4 V0 g_a g_b^T per cell, U' the engine's 3x3 matrix
as the slip makes it from the right values. Each slip of :func:`candidates` is such a map
U -> U' and predicts the engine's stiffness with nothing fitted: U_ab per cell is the declared
energy's, differentiated exactly (hyper-dual numbers) in I1b, I2b and J.

The driver's own second derivatives of the invariants by C (:func:`curvature_pieces`: the
terms of d2I1b/dC2, d2I2b/dC2, d2J/dC2 as written out) are read the same way: one term off by a
factor (a neighbour's 1/3 copied for 1/9, a sign, a term or its transpose left out), or one
invariant's whole second derivative, weighted by the declared energy's U_a.

A slip is named when its prediction matches the engine's stiffness within the tolerance and the
force is right; slips with the same prediction (a slot moved where both values are zero) are
said once, the fewest-moves first. Laws without a scalar formula in I1, I1b, I2, I2b and J
(Ogden's stretches, Costa's frame strain, St Venant-Kirchhoff's E components) are not read.
NumPy and MJED only.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from common.hyperdual import HD, exp, ln, sqrt
from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    element_split,
    piola_element_forces,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, Finding, ambiguous, named_first
from conformance.diagnosis.term_differences import declared_energy
from conformance.judge.compare import Scales, Tolerances, errors
from mjed.materials import StVenantKirchhoff

__all__ = [
    "SLOTS",
    "routine_hessians",
    "gradient_vectors",
    "candidates",
    "routine_derivative_findings",
    "routine_derivative_reading",
]

#: UHYPER's packing of UI2: (a, b) indices into (I1b, I2b, J).
SLOTS: Tuple[Tuple[int, int], ...] = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_NAMES = ("I1b", "I2b", "J")
_WORDS = tuple(
    f"d2U/d{_NAMES[a]}2" if a == b else f"d2U/d{_NAMES[a]} d{_NAMES[b]}" for a, b in SLOTS
)

#: Other packings a driver may read UI2 in (the 3x3 Hessian's upper triangle row by row,
#: column by column, the diagonal then the mixed entries in Voigt's order 23, 13, 12).
LAYOUTS: Dict[str, Tuple[Tuple[int, int], ...]] = {
    "the row-wise upper triangle of the 3x3 Hessian (11, 12, 1J, 22, 2J, JJ)": (
        (0, 0),
        (0, 1),
        (0, 2),
        (1, 1),
        (1, 2),
        (2, 2),
    ),
    "the column-wise upper triangle of the 3x3 Hessian (11, 12, 22, 1J, 2J, JJ)": (
        (0, 0),
        (0, 1),
        (1, 1),
        (0, 2),
        (1, 2),
        (2, 2),
    ),
    "the diagonal, then the mixed entries in Voigt's order (11, 22, JJ, 2J, 1J, 12)": (
        (0, 0),
        (1, 1),
        (2, 2),
        (1, 2),
        (0, 2),
        (0, 1),
    ),
}

#: Factors a routine's entry may be off by (a 2 lost or doubled, a sign, the entry missing).
FACTORS: Dict[float, str] = {
    0.0: "left out",
    -1.0: "with its sign flipped",
    2.0: "doubled",
    0.5: "halved",
}


def _seeded(energy: Any, I1b: np.ndarray, I2b: np.ndarray, J: np.ndarray, a: int, b: int):
    """(dW/dI_a, d2W/dI_a dI_b) (each (m,)) of the declared ``energy`` at (I1b, I2b, J), by
    one hyper-dual evaluation with I_a and I_b seeded (the first part meaningful where a == b).
    """
    one = np.ones_like(J)
    base = (I1b, I2b, J)
    args = [HD(x) for x in base]
    if a == b:
        args[a] = HD(base[a], one, one, 0.0)
    else:
        args[a] = HD(base[a], one, 0.0, 0.0)
        args[b] = HD(base[b], 0.0, one, 0.0)
    W = energy.evaluate(_namespace(*args).__getitem__, ln, exp, sqrt)
    first, second = (W.b, W.d) if isinstance(W, HD) else (0.0, 0.0)
    return np.broadcast_to(first, J.shape) + 0.0, np.broadcast_to(second, J.shape) + 0.0


def _invariants(F: np.ndarray):
    C = F.swapaxes(1, 2) @ F
    J = np.linalg.det(F)
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    return C, J, I1, I2, J ** (-2.0 / 3.0) * I1, J ** (-4.0 / 3.0) * I2


@dataclass(frozen=True)
class _InvariantForm:
    """An energy written in the invariants, for a law declared in other variables (St Venant-
    Kirchhoff's E components: tr E = (I1 - 3)/2, tr E^2 = (I1^2 - 2 I2 - 2 I1 + 3)/4).
    """

    formula: Any
    variables: Tuple[str, ...] = ("I1", "I2")

    def evaluate(self, variable, ln, exp, sqrt):
        return self.formula(variable("I1"), variable("I2"))


def _stvk_form(model) -> _InvariantForm:
    lam, mu = float(model.lam), float(model.mu)
    return _InvariantForm(
        lambda I1, I2: (
            lam / 8.0 * (I1 - 3.0) * (I1 - 3.0) + mu / 4.0 * (I1 * I1 - 2.0 * I2 - 2.0 * I1 + 3.0)
        )
    )


#: Laws declared in other variables than the invariants, by type: their invariant form.
INVARIANT_FORMS = {StVenantKirchhoff: _stvk_form}


def _readable(model: Any):
    form = INVARIANT_FORMS.get(type(model))
    if form is not None:
        return form(model)
    energy = declared_energy(model)
    if energy is None or not set(energy.variables) <= {"I1", "I1b", "I2", "I2b", "I3", "J"}:
        return None
    return energy


def _table(model: Any, F: np.ndarray, pairs, part: int) -> Optional[np.ndarray]:
    """(len(pairs), m): part 0 (first) or 1 (second) of :func:`_seeded` for each seeded pair
    (a, b) at F (m, 3, 3); None where the model has no scalar formula in I1, I1b, I2, I2b and J
    or a value is not finite.
    """
    energy = _readable(model)
    if energy is None:
        return None
    _, J, _, _, I1b, I2b = _invariants(F)
    try:
        with np.errstate(all="ignore"):
            out = np.stack([_seeded(energy, I1b, I2b, J, a, b)[part] for a, b in pairs])
    except (TypeError, AttributeError, KeyError, ValueError):
        return None
    return out if np.all(np.isfinite(out)) else None


def routine_slopes(model: Any, F: np.ndarray) -> Optional[np.ndarray]:
    """(3, m) the declared energy's first derivatives U_a in (I1b, I2b, J) at F (m, 3, 3) (the
    routine's UI1); None as for :func:`routine_hessians`.
    """
    return _table(model, F, ((0, 0), (1, 1), (2, 2)), 0)


def _namespace(i1b, i2b, j) -> Dict[str, Any]:
    """The variables a declared energy may read, from (I1b, I2b, J)."""
    return {
        "I1b": i1b,
        "I2b": i2b,
        "J": j,
        "I1": j ** (2.0 / 3.0) * i1b,
        "I2": j ** (4.0 / 3.0) * i2b,
        "I3": j * j,
    }


def routine_hessians(model: Any, F: np.ndarray) -> Optional[np.ndarray]:
    """(6, m) the declared energy's second derivatives in (I1b, I2b, J), in UHYPER's order
    (:data:`SLOTS`), at deformation gradients F (m, 3, 3); None where the model has no scalar
    formula in I1, I1b, I2, I2b and J or it is not finite.
    """
    return _table(model, F, SLOTS, 1)


def gradient_vectors(split: ElementSplit) -> np.ndarray:
    """(3, m, 12) g_a[node, i] = (F G_a D_node)_i for G_a = dI_a/dC of (I1b, I2b, J):
    dI1b/dC = J^(-2/3) (I - I1/3 C^-1), dI2b/dC = J^(-4/3) (I1 I - C - 2/3 I2 C^-1),
    dJ/dC = J/2 C^-1.
    """
    F, D = split.F, split.D
    C = F.swapaxes(1, 2) @ F
    Ci = np.linalg.inv(C)
    J = np.linalg.det(F)[:, None, None]
    I1 = np.trace(C, axis1=1, axis2=2)[:, None, None]
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C)[:, None, None])
    eye = np.eye(3)
    G = (
        J ** (-2.0 / 3.0) * (eye - I1 / 3.0 * Ci),
        J ** (-4.0 / 3.0) * (I1 * eye - C - 2.0 / 3.0 * I2 * Ci),
        0.5 * J * Ci,
    )
    m = F.shape[0]
    return np.stack([np.einsum("mij,mjk,mak->mai", F, g, D).reshape(m, 12) for g in G])


#: What a slip of the packed values is about.
ROUTINE = (
    "the user routine's packed second derivatives (UHYPER's UI2 in I1b, I2b, J) taken wrongly "
    "by the driver"
)


@dataclass(frozen=True)
class Slip:
    """One slip: words, how many entries it moves (its simplicity), and the engine's 3x3 matrix
    as a linear map of the packed values: coefficients (3, 3, 6), U'_ab = sum_s c_abs U_s.
    """

    words: str
    moves: int
    coefficients: np.ndarray
    about: str = ROUTINE


def _unpacked(layout: Tuple[Tuple[int, int], ...]) -> np.ndarray:
    """(3, 3, 6): the symmetric 3x3 matrix a driver fills from UHYPER's packed values when it
    reads them as ``layout`` (slot s of the vector taken for the entry layout[s]).
    """
    c = np.zeros((3, 3, 6))
    for s, (a, b) in enumerate(layout):
        c[a, b, s] = c[b, a, s] = 1.0
    return c


_RIGHT = _unpacked(SLOTS)


def candidates() -> List[Slip]:
    """The slips: every other order of the six packed values (the named layouts first), one
    entry off by a factor of :data:`FACTORS`, a mixed entry in one order only.
    """
    out: List[Slip] = []
    named = {}
    for words, layout in LAYOUTS.items():
        named[layout] = words
    for perm in itertools.permutations(range(6)):
        if perm == tuple(range(6)):
            continue
        layout = tuple(SLOTS[p] for p in perm)
        moved = [s for s in range(6) if perm[s] != s]
        if layout in named:
            words = f"UI2 read as {named[layout]} where UHYPER packs (11, 22, JJ, 12, 1J, 2J)"
        else:
            words = "UI2 unpacked in another order: " + ", ".join(
                f"{_WORDS[s]} used as {_WORDS[perm[s]]}" for s in moved
            )
        # a named layout is a driver's convention: said first among equal predictions
        out.append(Slip(words, 0 if layout in named else len(moved), _unpacked(layout)))
    for s, (a, b) in enumerate(SLOTS):
        for k, said in FACTORS.items():
            c = _RIGHT.copy()
            c[a, b, s] = c[b, a, s] = k
            out.append(Slip(f"{_WORDS[s]} {said} (the routine's UI2 entry)", 1, c))
        if a != b:
            for first, second in ((a, b), (b, a)):
                c = _RIGHT.copy()
                c[second, first, s] = 0.0
                out.append(
                    Slip(
                        f"the mixed term {_WORDS[s]} counted once, in the order dI_{_NAMES[first]}"
                        f"/dC (x) dI_{_NAMES[second]}/dC only (its transpose missing: the "
                        "tangent loses its major symmetry)",
                        1,
                        c,
                    )
                )
    return out


#: What a slip of the driver's own invariant second derivatives is about.
CURVATURE = "a second derivative of an invariant by C written wrongly in the driver's tangent"


def _outer(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    return np.einsum("mij,mkl->mijkl", A, B)


def _odot(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(A (.) B)_IJKL = (A_IK B_JL + A_IL B_JK) / 2."""
    return 0.5 * (np.einsum("mik,mjl->mijkl", A, B) + np.einsum("mil,mjk->mijkl", A, B))


def curvature_pieces(F: np.ndarray) -> Dict[Tuple[int, str], np.ndarray]:
    """{(a, words): T (m, 3, 3, 3, 3)}: the terms of d2I_a/dC2 for (I1b, I2b, J) as a driver
    writes them, each with its coefficient (their sum per a is the second derivative)::

        d2I1b/dC2 = J^(-2/3) (-1/3 (I (x) C^-1 + C^-1 (x) I) + I1/9 C^-1 (x) C^-1
                              + I1/3 C^-1 (.) C^-1),
        d2I2b/dC2 = J^(-4/3) (I (x) I - II - 2/3 (G (x) C^-1 + C^-1 (x) G)
                              + 4/9 I2 C^-1 (x) C^-1 + 2/3 I2 C^-1 (.) C^-1),   G = I1 I - C,
        d2J/dC2 = J/4 C^-1 (x) C^-1 - J/2 C^-1 (.) C^-1.
    """
    C, J, I1, I2, _, _ = _invariants(F)
    m = J.size
    Ci = np.linalg.inv(C)
    eye = np.broadcast_to(np.eye(3), (m, 3, 3))
    G = I1[:, None, None] * eye - C
    c = lambda x: x[:, None, None, None, None]  # noqa: E731 - a per-cell scalar on a tensor
    a1, a2 = c(J ** (-2.0 / 3.0)), c(J ** (-4.0 / 3.0))
    return {
        (0, "-1/3 J^(-2/3) I (x) C^-1"): -a1 / 3.0 * _outer(eye, Ci),
        (0, "-1/3 J^(-2/3) C^-1 (x) I"): -a1 / 3.0 * _outer(Ci, eye),
        (0, "J^(-2/3) I1/9 C^-1 (x) C^-1"): a1 * c(I1 / 9.0) * _outer(Ci, Ci),
        (0, "J^(-2/3) I1/3 C^-1 (.) C^-1"): a1 * c(I1 / 3.0) * _odot(Ci, Ci),
        (1, "J^(-4/3) I (x) I"): a2 * _outer(eye, eye),
        (1, "-J^(-4/3) II"): -a2 * _odot(eye, eye),
        (1, "-2/3 J^(-4/3) G (x) C^-1"): -2.0 / 3.0 * a2 * _outer(G, Ci),
        (1, "-2/3 J^(-4/3) C^-1 (x) G"): -2.0 / 3.0 * a2 * _outer(Ci, G),
        (1, "J^(-4/3) 4/9 I2 C^-1 (x) C^-1"): a2 * c(4.0 / 9.0 * I2) * _outer(Ci, Ci),
        (1, "J^(-4/3) 2/3 I2 C^-1 (.) C^-1"): a2 * c(2.0 / 3.0 * I2) * _odot(Ci, Ci),
        (2, "J/4 C^-1 (x) C^-1"): c(J / 4.0) * _outer(Ci, Ci),
        (2, "-J/2 C^-1 (.) C^-1"): -c(J / 2.0) * _odot(Ci, Ci),
    }


#: Factors a term of an invariant's second derivative may be off by (besides FACTORS): a
#: neighbouring term's coefficient copied (1/3 for 1/9, and back).
TERM_FACTORS: Dict[float, str] = {**FACTORS, 3.0: "three times too large", 1.0 / 3.0: "a third"}

#: Terms whose transpose is another term (one of the two left out breaks major symmetry).
_PAIRED = ("(x) C^-1", "C^-1 (x) I", "C^-1 (x) G")


def _curvature_slips(split: ElementSplit, model: Any, vector) -> List[Tuple[Slip, np.ndarray]]:
    """(slip, change on the pattern) for each term of :func:`curvature_pieces` off by a factor
    of :data:`TERM_FACTORS`, and each invariant's whole second derivative off by one of
    :data:`FACTORS`, weighted by the declared energy's 4 U_a; [] where it has none.
    """
    U1 = routine_slopes(model, split.F)
    if U1 is None:
        return []
    F = split.F
    by_term = {}
    for (a, words), T in curvature_pieces(F).items():
        if not np.any(U1[a]):
            continue
        CC = 4.0 * U1[a][:, None, None, None, None] * T
        A = np.einsum("miI,mIJKL,mkK->miJkL", F, CC, F, optimize=True)
        by_term[(a, words)] = vector(tangent_element_matrices(split.V0, split.D, A))
    out: List[Tuple[Slip, np.ndarray]] = []
    empty = np.zeros((3, 3, 6))
    for (a, words), v in by_term.items():
        pair = any(words.endswith(p) for p in _PAIRED) and "I (x) I" not in words
        for k, said in TERM_FACTORS.items():
            text = f"the term {words} of d2{_NAMES[a]}/dC2 {said} in your tangent"
            if pair and k == 0.0:
                text += " (its transpose kept: the tangent loses its major symmetry)"
            out.append((Slip(text, 1, empty, CURVATURE), (k - 1.0) * v))
    for a in range(3):
        whole = [v for (b, _), v in by_term.items() if b == a]
        if not whole:
            continue
        total = np.sum(whole, axis=0)
        for k, said in FACTORS.items():
            text = f"dU/d{_NAMES[a]} d2{_NAMES[a]}/dC2 (the whole second derivative) {said}"
            out.append((Slip(text, 2, empty, CURVATURE), (k - 1.0) * total))
    return out


def gradient_terms(F: np.ndarray) -> Dict[Tuple[int, str], np.ndarray]:
    """{(a, words): T (m, 3, 3)}: the terms of dI_a/dC for (I1b, I2b, J) as a driver writes
    them (their sum per a is the gradient): dI1b/dC = J^(-2/3) I - J^(-2/3) I1/3 C^-1,
    dI2b/dC = J^(-4/3) I1 I - J^(-4/3) C - 2/3 J^(-4/3) I2 C^-1, dJ/dC = J/2 C^-1.
    """
    C, J, I1, I2, _, _ = _invariants(F)
    m = J.size
    Ci = np.linalg.inv(C)
    eye = np.broadcast_to(np.eye(3), (m, 3, 3))
    c = lambda x: x[:, None, None]  # noqa: E731 - a per-cell scalar on a tensor
    a1, a2 = c(J ** (-2.0 / 3.0)), c(J ** (-4.0 / 3.0))
    return {
        (0, "J^(-2/3) I"): a1 * eye,
        (0, "-J^(-2/3) I1/3 C^-1"): -a1 * c(I1 / 3.0) * Ci,
        (1, "J^(-4/3) I1 I"): a2 * c(I1) * eye,
        (1, "-J^(-4/3) C"): -a2 * C,
        (1, "-2/3 J^(-4/3) I2 C^-1"): -2.0 / 3.0 * a2 * c(I2) * Ci,
        (2, "J/2 C^-1"): c(J / 2.0) * Ci,
    }


#: Per-cell slips of a gradient term: the isochoric invariant put for the plain one in the
#: projection's C^-1 term (its power of J applied twice).
_TWICE = {
    (0, "-J^(-2/3) I1/3 C^-1"): (-2.0 / 3.0, "I1b put for I1 (J^(-2/3) applied twice)"),
    (1, "-2/3 J^(-4/3) I2 C^-1"): (-4.0 / 3.0, "I2b put for I2 (J^(-4/3) applied twice)"),
}


def gradient_slip_findings(
    split: ElementSplit, model: Any, out, f_o: np.ndarray, K_o, s: Scales, tol: Tolerances
) -> List[Finding]:
    """The findings naming one term of a driver's dI_a/dC off by a factor of
    :data:`TERM_FACTORS` (or by a power of J, :data:`_TWICE`), in the stress and in every
    product of the tangent built from that gradient alike, predicted with the declared
    energy's U_a and U_ab; several distinct: ambiguous.
    """
    U1 = routine_slopes(model, split.F)
    H = routine_hessians(model, split.F)
    if U1 is None or H is None:
        return []
    U2 = np.zeros((3, 3, H.shape[1]))
    for t, (a, b) in enumerate(SLOTS):
        U2[a, b] = U2[b, a] = H[t]
    terms = gradient_terms(split.F)
    G = [sum(T for (b, _), T in terms.items() if b == a) for a in range(3)]
    J = np.linalg.det(split.F)
    F = split.F
    K_o = sp.csr_matrix(K_o)
    found = []
    for (a, words), T in terms.items():
        if not (np.any(U1[a]) or np.any(U2[a])):
            continue
        slips = [(k - 1.0, f"{said}") for k, said in TERM_FACTORS.items() if k != 1.0]
        if (a, words) in _TWICE:
            p, said = _TWICE[(a, words)]
            slips.append(((J**p - 1.0)[:, None, None], said))
        for k, said in slips:
            dG = k * T
            dS = 2.0 * U1[a][:, None, None] * dG
            dCC = 4.0 * U2[a, a][:, None, None, None, None] * _outer(dG, dG)
            for b in range(3):
                w = 4.0 * U2[a, b][:, None, None, None, None]
                dCC = dCC + w * (_outer(dG, G[b]) + _outer(G[b], dG))
            A = np.einsum("mkJ,mJIML,mlM->mkIlL", F, dCC, F, optimize=True)
            A = A + np.einsum("kl,mLI->mkIlL", np.eye(3), dS)
            fe = piola_element_forces(split.V0, split.D, F @ dS)
            df, dK = assemble(
                split.cells, split.n, fe, tangent_element_matrices(split.V0, split.D, A)
            )
            e = errors(out.force, out.stiffness, None, f_o + df, K_o + dK, 0.0, s)
            if not tol.within(e, energy=False):
                continue
            found.append(
                Finding(
                    "routine-gradient-term",
                    f"the driver's gradient dI/dC of an invariant written wrongly: the term "
                    f"{words} of d{_NAMES[a]}/dC: {said}, in the stress and in the tangent's "
                    "products of that gradient alike",
                    FULL,
                    "S = 2 sum_a U_a dI_a/dC and CC's products 4 sum_ab U_ab dI_a/dC (x) dI_b/dC "
                    "with this gradient and the declared energy's U_a, U_ab (exact, per cell) "
                    f"predict your force to {e.force:.1e} and your stiffness to "
                    f"{e.stiffness:.1e}, nothing fitted",
                    {"term": words, "invariant": _NAMES[a], "slip": said},
                )
            )
    return ambiguous(found) if len(found) > 1 else found


def routine_derivative_findings(
    split: ElementSplit, model: Any, out, f_o: np.ndarray, K_o: sp.spmatrix, s: Scales,
    tol: Tolerances,
) -> List[Finding]:  # fmt: skip
    """The findings naming a slip of :func:`candidates` whose prediction matches the engine's
    stiffness (the force right), equal predictions said once; several distinct: ambiguous.
    """
    U = routine_hessians(model, split.F)
    if U is None:
        return []
    g = gradient_vectors(split)
    m = split.cells.shape[0]
    dof = (3 * split.cells[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    N = 3 * split.n
    keys = rows.astype(np.int64) * N + cols
    pattern, where = np.unique(keys, return_inverse=True)

    def vector(Ke: np.ndarray) -> np.ndarray:
        return np.bincount(where, Ke.reshape(-1), minlength=pattern.size)

    # M[a, b, s]: the stiffness of the pair (a, b) weighted by the packed value s, on the pattern
    M = np.zeros((3, 3, 6, pattern.size))
    for a in range(3):
        for b in range(3):
            pair = 4.0 * split.V0[:, None, None] * np.einsum("mi,mj->mij", g[a], g[b])
            for t in range(6):
                if np.any(U[t]):
                    M[a, b, t] = vector(U[t][:, None, None] * pair)
    D = sp.coo_matrix(sp.csr_matrix(out.stiffness) - sp.csr_matrix(K_o))
    dkeys = D.row.astype(np.int64) * N + D.col
    pos = np.clip(np.searchsorted(pattern, dkeys), 0, pattern.size - 1)
    inside = pattern[pos] == dkeys
    if np.linalg.norm(D.data[~inside]) > 1e-12 * max(np.linalg.norm(D.data), 1e-300):
        return []  # entries where the mesh has none: not a tangent slip
    target = np.bincount(pos[inside], D.data[inside], minlength=pattern.size)
    scale = np.linalg.norm(target)
    if scale == 0.0:
        return []
    right = np.einsum("abs,absn->n", _RIGHT, M)
    changes = [
        (slip, np.einsum("abs,absn->n", slip.coefficients, M) - right) for slip in candidates()
    ] + _curvature_slips(split, model, vector)
    matches: Dict[bytes, List[Tuple[Slip, np.ndarray]]] = {}
    for slip, change in changes:
        if np.linalg.norm(target - change) > 1e-3 * scale:
            continue
        key = np.round(change / scale, 9).tobytes()
        matches.setdefault(key, []).append((slip, change))
    found = []
    K_o = sp.csr_matrix(K_o)
    for pairs in matches.values():
        pairs.sort(key=lambda x: x[0].moves)
        slips = [x for x, _ in pairs]
        head, change = pairs[0]
        dK = sp.csr_matrix((change, (pattern // N, pattern % N)), shape=(N, N))
        e = errors(out.force, out.stiffness, None, f_o, K_o + dK, 0.0, s)
        if not tol.within(e, energy=False):
            continue
        also = [x.words for x in slips[1:4]]
        found.append(
            Finding(
                "routine-second-derivative",
                f"{head.about}: {head.words}",
                FULL,
                "the tangent CC = 4 sum_a U_a d2I_a/dC2 + 4 sum_ab U_ab dI_a/dC (x) dI_b/dC with "
                "the declared energy's U_a, U_ab (exact, per cell) and this slip "
                f"predicts your stiffness to {e.stiffness:.1e} (force {e.force:.1e}), nothing "
                "fitted"
                + (
                    f"; the same prediction (the entries moved are zero here): {'; '.join(also)}"
                    if also
                    else ""
                ),
                {"slip": head.words, "about": head.about, "equivalent": len(slips) - 1},
            )
        )
    return ambiguous(found) if len(found) > 1 else found


def routine_derivative_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet, the force right) with a slip in a user
    routine's packed second derivatives named first; unchanged when none matches.
    """
    tol = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    with np.errstate(all="ignore"):
        found = []
        if diag.errors.force <= tol.force:
            found = routine_derivative_findings(
                split, ci.model, out, ref.force, ref.stiffness, s, tol
            )
        if not found:
            found = gradient_slip_findings(split, ci.model, out, ref.force, ref.stiffness, s, tol)
    return named_first(diag, found)
