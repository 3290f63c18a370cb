"""A material's declared MJED terms lowered to flat arrays a compiled kernel can read.

Each term f(J) g(C) of each group becomes one row of integer codes and float parameters:

- the function of J: its kind (:data:`J_KINDS`) and up to three parameters;
- the invariant function: its kind (:data:`G_KINDS`), up to twelve parameters and, for the
  fibre quadratic, its frame R (one (3, 3) or one per cell);
- its tangent pairs, each the index of a *slot*: a (kind, constant matrix) shared by every
  pair with the same kind and matrix, as in the NumPy engine (mjed/engine.py), so that
  F M D_a is formed once per slot and per cell.

The per-mesh edge quantities of the paper (D_a x D_b, D_a . M D_b) are not stored: the
generated kernels form them from D in registers, which costs less than reading them.
:mod:`mjed.compiled.shape` reads the table's structure, from which the kernel is generated.

Which kinds exist is decided by type (a registry keyed by the Python class of the J-function
or invariant function); a term of a type without a compiled form is refused with a
:class:`NotImplementedError` that names it, so the caller can fall back to the NumPy engine.
This module is pure NumPy; it does not import Numba.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, List, Tuple

import numpy as np

from mjed.fibre import FibreQuadratic
from mjed.spectral import EigenPowerSum
from mjed.terms import (
    IDENTITY,
    Exp,
    GreenLagrangeQuadratic,
    I1Power,
    JLogJ,
    JPower,
    LinearI2,
    Log,
    LogPolynomial,
    Power,
    TermGroup,
    Unity,
)

__all__ = ["J_KINDS", "G_KINDS", "SLOT_KINDS", "GROUP_KINDS", "TermTable", "lower_groups"]

#: Codes of the functions of J (the kernel branches on them).
J_KINDS = {JPower: 0, LogPolynomial: 1, JLogJ: 2}
#: Codes of the invariant functions.
G_KINDS = {
    Unity: 0,
    I1Power: 1,
    LinearI2: 2,
    GreenLagrangeQuadratic: 3,
    FibreQuadratic: 4,
    EigenPowerSum: 5,
}
#: Codes of the function of a group's sum (0: a plain group, no function).
GROUP_KINDS = {Exp: 1, Log: 2, Power: 3}
#: Codes of the tangent pair kinds.
SLOT_KINDS = {"first": 0, "second": 1, "spectral": 2}

MAX_PAIRS = 3  # the most tangent pairs of one invariant function (Costa's split of B)


@dataclass(frozen=True)
class TermTable:
    """The arrays of one material on one mesh (T terms, G groups, S slots, m cells).

    jkind (T,), jpar (T, 3); gkind (T,), gpar (T, 12), gmat (T, 1 or m, 3, 3) (frames);
    npair (T,), tslot (T, 3) slot of each tangent pair (-1 unused); group_start (G + 1,),
    group_kind (G,) 0 for a plain group, else the code of its function (:data:`GROUP_KINDS`),
    group_coef (G, 3): the coefficient c, then the function's shift a and exponent p (ln(a + u),
    (a + u)^p; zero when unused); slot_kind (S,), slot_ident (S,)
    1 when the slot's matrix is the identity, slot_M (S, 1 or m, 3, 3); need_eig: a term reads
    the eigen-decomposition of C.
    """

    jkind: np.ndarray
    jpar: np.ndarray
    gkind: np.ndarray
    gpar: np.ndarray
    gmat: np.ndarray
    npair: np.ndarray
    tslot: np.ndarray
    group_start: np.ndarray
    group_kind: np.ndarray
    group_coef: np.ndarray
    slot_kind: np.ndarray
    slot_ident: np.ndarray
    slot_M: np.ndarray
    need_eig: bool


# ------------------------------------------------------------------ J-functions
def _jpower(f: JPower) -> List[float]:
    return [f.p]


def _logpoly(f: LogPolynomial) -> List[float]:
    return [f.a2, f.a1, f.a0]


def _jlogj(f: JLogJ) -> List[float]:
    return [f.k, f.c]


_J_PARAMS: Dict[type, Callable] = {JPower: _jpower, LogPolynomial: _logpoly, JLogJ: _jlogj}


# ------------------------------------------------------------------ invariant functions
def _no_params(g) -> Tuple[List[float], "np.ndarray | None"]:
    return [], None


def _i1power(g: I1Power):
    return [g.c, float(g.n)], None


def _lineari2(g: LinearI2):
    return [g.c], None


def _glq(g: GreenLagrangeQuadratic):
    return [g.mu, g.lam], None


def _fibre(g: FibreQuadratic):
    # B (9 entries), then the signs of the split (one per tangent pair).
    return list(np.asarray(g.B, float).ravel()) + [float(s) for s in g.signs], np.asarray(
        g.R, float
    )


def _eigen(g: EigenPowerSum):
    return [g.c, g.q, 0.0 if g.tangent_mode == "exact" else 1.0], None


def _group_row(group: TermGroup) -> Tuple[int, List[float]]:
    """(kind code, [c, shift, p]) of a group."""
    fn = group.function
    if fn is None:
        return 0, [float(group.coefficient), 0.0, 0.0]
    kind = _kind_of(fn, GROUP_KINDS, "function of a group's sum")
    shift = float(getattr(fn, "shift", 0.0))
    return kind, [float(group.coefficient), shift, float(getattr(fn, "p", 0.0))]


_G_PARAMS: Dict[type, Callable] = {
    Unity: _no_params,
    I1Power: _i1power,
    LinearI2: _lineari2,
    GreenLagrangeQuadratic: _glq,
    FibreQuadratic: _fibre,
    EigenPowerSum: _eigen,
}


def _kind_of(obj, table: Dict[type, object], what: str):
    for cls in type(obj).__mro__:
        if cls in table:
            return table[cls]
    raise NotImplementedError(
        f"the compiled (numba) backend has no kernel for the {what} {type(obj).__name__}; it "
        f"supports {', '.join(c.__name__ for c in table)}. Use backend='numpy' for this material."
    )


# ------------------------------------------------------------------ lowering
def lower_groups(groups: Tuple[TermGroup, ...], D: np.ndarray) -> TermTable:
    """The term table of ``groups`` on a mesh with rest shape vectors D (m, 4, 3)."""
    m = len(D)
    rows_j, rows_g, mats, tslots, npair = [], [], [], [], []
    slots: Dict[Tuple[str, object], int] = {}
    slot_list: List[Tuple[str, np.ndarray]] = []
    group_start, group_kind, group_coef = [0], [], []
    need_eig = False
    for group in groups:
        for term in group.terms:
            jk = _kind_of(term.f, J_KINDS, "function of J")
            gk = _kind_of(term.g, G_KINDS, "invariant function")
            jp = _kind_of(term.f, _J_PARAMS, "function of J")(term.f)
            gp, R = _kind_of(term.g, _G_PARAMS, "invariant function")(term.g)
            need_eig |= gk == G_KINDS[EigenPowerSum]
            rows_j.append((jk, jp))
            rows_g.append((gk, gp))
            mats.append(R)
            pairs = term.g.tangent
            if len(pairs) > MAX_PAIRS:
                raise NotImplementedError(
                    f"{type(term.g).__name__} declares {len(pairs)} tangent pairs; the compiled "
                    f"kernel takes at most {MAX_PAIRS}"
                )
            row = [-1] * MAX_PAIRS
            for p, pair in enumerate(pairs):
                key = _slot_key(pair)
                if key not in slots:
                    slots[key] = len(slot_list)
                    slot_list.append((pair.kind, pair.matrix))
                row[p] = slots[key]
            tslots.append(row)
            npair.append(len(pairs))
        group_start.append(len(rows_j))
        kind, row = _group_row(group)
        group_kind.append(kind)
        group_coef.append(row)

    T = len(rows_j)
    jkind = np.array([k for k, _ in rows_j], dtype=np.int64)
    jpar = np.zeros((T, 3))
    for t, (_, p) in enumerate(rows_j):
        jpar[t, : len(p)] = p
    gkind = np.array([k for k, _ in rows_g], dtype=np.int64)
    gpar = np.zeros((T, 12))
    for t, (_, p) in enumerate(rows_g):
        gpar[t, : len(p)] = p
    per_cell = any(R is not None and R.ndim == 3 for R in mats)
    gmat = np.zeros((T, m if per_cell else 1, 3, 3))
    for t, R in enumerate(mats):
        if R is not None:
            gmat[t] = R
    slot_kind, slot_ident, slot_M = _slot_arrays(slot_list, m)
    return TermTable(
        jkind,
        jpar,
        gkind,
        gpar,
        gmat,
        np.array(npair, dtype=np.int64),
        np.array(tslots, dtype=np.int64).reshape(T, MAX_PAIRS),
        np.array(group_start, dtype=np.int64),
        np.array(group_kind, dtype=np.int64),
        np.array(group_coef, dtype=float).reshape(-1, 3),
        slot_kind,
        slot_ident,
        slot_M,
        bool(need_eig),
    )


def _slot_key(pair) -> Tuple[str, object]:
    if pair.kind == "spectral":
        return pair.kind, None
    M = np.asarray(pair.matrix)
    return (pair.kind, M.tobytes()) if M.ndim == 2 else (pair.kind, id(pair.matrix))


def _slot_arrays(slot_list, m: int):
    """slot_kind (S,), slot_ident (S,), slot_M (S, 1 or m, 3, 3) of the slots."""
    S = len(slot_list)
    per_cell = any(kind != "spectral" and np.ndim(M) == 3 for kind, M in slot_list)
    slot_M = np.zeros((S, m if per_cell else 1, 3, 3))
    kinds = np.zeros(S, dtype=np.int64)
    ident = np.zeros(S, dtype=np.int64)
    for s, (kind, M) in enumerate(slot_list):
        kinds[s] = SLOT_KINDS[kind]
        if kind == "spectral":
            continue
        M = np.asarray(M, float)
        slot_M[s] = M
        ident[s] = int(M.ndim == 2 and np.array_equal(M, IDENTITY))
    return kinds, ident, slot_M
