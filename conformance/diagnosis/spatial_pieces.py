"""A UMAT driver's spatial tangent fitted as a combination of declared per-cell pieces.

An updated-Lagrangian driver around an Abaqus-style UMAT gets DDSDDE, the Jaumann-rate tangent
of the Kirchhoff stress over J, and removes the Jaumann terms to get the Truesdell tangent:

    c = DDSDDE - (T1 + T2 + T3 + T4),   DDSDDE = c + T1 + T2 + T3 + T4,
    T1 = d_ik s_jl / 2, T2 = s_ik d_jl / 2, T3 = d_il s_jk / 2, T4 = s_il d_jk / 2

(s the Cauchy stress, d Kronecker's delta). Its mistakes in that step come as a factor on
DDSDDE (a J too many or too few, units left in MPa) and weights on the four terms (added, not
removed, only some removed). From the oracle's per-cell sigma and c
(:func:`conformance.diagnosis.spatial_tangent.spatial_cells`), the stiffness of each piece,
v grad N_a . piece . grad N_b summed over the cells, is a column of a linear least-squares fit
of the engine's stiffness, the force being right (stiffness only):

    c_engine = (a0 + a_m / J + a_p J) DDSDDE + b1 T1 + b2 T2 + b3 T3 + b4 T4

(J per cell; the oracle: a0 = 1, b = -1). Each fitted coefficient is taken to the nearest
simple number (:data:`SCALES`, :data:`WEIGHTS`), and the cause is named only when that
combination, rebuilt with those numbers and nothing fitted, brings the engine's force and
stiffness within the case's tolerance. On a state whose cells share one J, DDSDDE / J,
DDSDDE J and DDSDDE coincide: the factor is fitted on DDSDDE alone and a factor J^+-1 is said
together with the constant it equals there. Pieces that coincide on a state otherwise (the fit
not determined) name nothing. T1 assembles exactly as half the geometric stiffness
v (grad N_a . sigma grad N_b) I: a weight on it is said with that reading too.

A law whose spatial tangent is isotropic with coefficients in J alone (the compressible
Neo-Hookean forms, c = lam/J I (x) I + 2 (mu - lam ln J)/J II) has its terms fitted the same
way over the pieces of :data:`ISOTROPIC` (I (x) I and II times 1/J and ln J / J):
:func:`isotropic_fit_findings` fits the oracle's c and the engine's, and names one term taken
wrong (:data:`RATIOS`: sign flipped, dropped, doubled, halved) when the oracle's c lies in the
pieces' span and that term so, nothing else changed, matches the engine; where no single
piece does, all pieces of one tensor by one ratio (a coefficient's 2 lost: 2 (mu - lam ln J)/J
II written once). On a state whose cells share one J the pieces of a tensor coincide (1/J and
ln J / J are one column there): only a whole tensor's coefficient taken wrong is named there;
a law outside that span (any with b in its tangent) is not read this way.
"""

from __future__ import annotations

from typing import Callable, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, Finding
from conformance.diagnosis.invariant_pieces import CellTensors
from conformance.diagnosis.least_squares import determined_lstsq
from conformance.diagnosis.spatial_tangent import SpatialCells, spatial_cells
from conformance.diagnosis.spatial_variants import jaumann_pieces
from conformance.judge.compare import Scales

__all__ = [
    "SCALES",
    "WEIGHTS",
    "TERMS",
    "piece_fit_findings",
    "deviatoric_piece_findings",
    "PRODUCTS",
    "unsymmetrised_product_findings",
    "ISOTROPIC",
    "RATIOS",
    "isotropic_fit_findings",
]

#: The simple numbers a factor on DDSDDE is taken to (1e-6 .. 1e6: units, MPa against Pa).
SCALES = (0.0, 0.5, -0.5, 1.0, -1.0, 2.0, -2.0, 1e-6, 1e-3, 1e3, 1e6)

#: The simple numbers a weight on one Jaumann term is taken to.
WEIGHTS = (0.0, 0.5, -0.5, 1.0, -1.0, 1.5, -1.5, 2.0, -2.0, 3.0, -3.0)

#: The four terms, as said.
TERMS = ("d_ik s_jl/2", "s_ik d_jl/2", "d_il s_jk/2", "s_il d_jk/2")

#: Singular values of the normalised fit below this fraction of the largest: not determined.
DETERMINED = 1e-8

#: Cells share one J when its spread is below this fraction.
ONE_J = 1e-9


def _stiffness(t: SpatialCells, piece: np.ndarray) -> np.ndarray:
    """(m, 12, 12) v grad N_a . piece . grad N_b, node-major."""
    K = np.einsum("m,maj,mijkl,mbl->maibk", t.v, t.gN, piece, t.gN, optimize=True)
    return K.reshape(-1, 12, 12)


def _nearest(x: float, values: Tuple[float, ...]) -> float:
    """The value of ``values`` nearest x."""
    return min(values, key=lambda v: abs(x - v))


def _number(x: float) -> str:
    """A simple number in words: 1, -1/2, 1e-06."""
    if x in (0.5, -0.5, 1.5, -1.5):
        return f"{'-' if x < 0 else ''}{int(abs(2 * x))}/2"
    return f"{x:g}"


def _scale_words(a: Tuple[float, float, float], J0: float) -> str:
    """The factor a0 + a_m / J + a_p J in words (J0: the single J of the state, else nan)."""
    a0, am, ap = a
    parts = [f"{_number(a0)}" if a0 else "", f"{_number(am)}/J" if am else ""]
    parts.append(("J" if ap == 1.0 else f"{_number(ap)} J") if ap else "")
    text = " + ".join(p for p in parts if p) or "0"
    if np.isfinite(J0) and (am or ap):
        text += (
            f" (J = {J0:.6g} in every cell here: equally the constant {a0 + am / J0 + ap * J0:.6g})"
        )
    return text


def _words(a: Tuple[float, float, float], b: np.ndarray, J0: float) -> str:
    """What the fitted combination says: DDSDDE's factor and the Jaumann terms' weights."""
    said = []
    if a != (1.0, 0.0, 0.0):
        how = {
            (0.0, 1.0, 0.0): "divided by J once more",
            (0.0, 0.0, 1.0): "multiplied by J",
            (1e-6, 0.0, 0.0): "1e-6 times too small (a unit left: MPa where Pa belongs)",
            (1e6, 0.0, 0.0): "1e6 times too large (a unit left: Pa where MPa belongs)",
            (1e-3, 0.0, 0.0): "1e-3 times too small (a unit left)",
            (1e3, 0.0, 0.0): "1e3 times too large (a unit left)",
        }.get(a, "scaled")
        said.append(f"DDSDDE {how}: times {_scale_words(a, J0)} where 1 belongs")
    if np.all(b == b[0]):
        if b[0] != -1.0:
            said.append(
                {
                    0.0: "the Jaumann-rate terms not removed (DDSDDE used as the spatial tangent)",
                    1.0: "the Jaumann-rate terms added instead of removed",
                    -2.0: "the Jaumann-rate terms removed twice",
                }.get(b[0], f"the Jaumann-rate terms taken {_number(b[0])} times")
                + " (the weight -1 belongs on each)"
            )
    else:
        off = [
            f"{TERMS[k]} "
            + ("left in (not removed)" if b[k] == 0 else f"with weight {_number(b[k])}")
            for k in range(4)
            if b[k] != -1.0
        ]
        kept = [TERMS[k] for k in range(4) if b[k] == -1.0]
        said.append(
            "the Jaumann correction incomplete or mixed: "
            + (f"only {', '.join(kept)} removed; " if kept else "")
            + "; ".join(off)
            + " (each of the four belongs with weight -1)"
        )
    if b[0] != -1.0:
        said.append(
            f"the term d_ik s_jl/2 assembles exactly as half the geometric stiffness "
            f"v (grad N_a . sigma grad N_b) I: its weight {_number(b[0])} is equally a geometric "
            f"stiffness weighted {_number(1.0 + (b[0] + 1.0) / 2.0)}"
        )
    return "; ".join(said)


def _entries(split: ElementSplit, Ke: np.ndarray) -> np.ndarray:
    """(q,) the assembled entries of element matrices Ke (m, 12, 12) on the mesh's pattern."""
    return assemble(split.cells, split.n, split.fe, Ke)[1].tocoo().data


def _fit(
    split: ElementSplit, t: SpatialCells, Ke: np.ndarray, K_engine: sp.spmatrix
) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """Least squares over the pieces' stiffnesses Ke (k, m, 12, 12) of the engine's material
    stiffness (its K less the oracle's geometric part) and of the oracle's (the stiffness of c):
    their coefficients (k,) each; None when the pieces are not determined on this state.
    """
    K_c = _stiffness(t, t.c)
    base = assemble(split.cells, split.n, split.fe, split.Ke - K_c)[1].tocoo()
    engine = np.asarray(sp.csr_matrix(K_engine)[base.row, base.col]).ravel()
    A = np.stack([_entries(split, k) for k in Ke], axis=1)
    y = np.stack([engine - base.data, _entries(split, K_c)], axis=1)
    x = determined_lstsq(A, y, DETERMINED)
    return None if x is None else (x[:, 0], x[:, 1])


def _ddsdde_columns(split: ElementSplit, cells: CellTensors):
    """(t, J (m,), one_j, the DDSDDE columns): the oracle's spatial cells, each cell's J, whether
    the cells share one J, and DDSDDE = c + the four Jaumann terms of sigma scaled per cell by
    1 (and, where J varies, by 1/J and J): the columns both DDSDDE fits start from.
    """
    t = spatial_cells(split, cells.S, cells.CC)
    J = t.v / split.V0
    one_j = bool(np.ptp(J) <= ONE_J * np.abs(J).max())
    D = t.c + jaumann_pieces(t.sigma).sum(axis=0)
    m = split.cells.shape[0]
    scales = [np.ones(m)] if one_j else [np.ones(m), 1.0 / J, J]
    return t, J, one_j, [q[:, None, None, None, None] * D for q in scales]


def piece_fit_findings(
    split: ElementSplit,
    cells: CellTensors,
    K_engine: sp.spmatrix,
    matches: Callable[..., float],
) -> List[Finding]:
    """The combination of DDSDDE (scaled per cell by 1, 1/J, J) and the four Jaumann terms that
    the engine's stiffness fits, named when its simple-number form matches the engine.

    cells: the oracle's per-cell S (m, 3, 3) and CC (m, 3, 3, 3, 3); K_engine: (3n, 3n);
    matches(f, K): the engine's error against the prediction, inf unless within the tolerance
    and the prediction is not the oracle's (:func:`conformance.diagnosis.hand_derived`).
    """
    t, J, one_j, scaled = _ddsdde_columns(split, cells)
    pieces = scaled + list(jaumann_pieces(t.sigma))
    Ke = np.stack([_stiffness(t, p) for p in pieces])  # (k, m, 12, 12)
    fit = _fit(split, t, Ke, K_engine)
    if fit is None:
        return []
    x, _ = fit
    J0 = float(J[0]) if one_j else float("nan")
    scale_values = SCALES + ((J0, 1.0 / J0) if one_j else ())
    a0 = _nearest(x[0], scale_values)
    if one_j and a0 in (J0, 1.0 / J0):
        a = [0.0, 1.0, 0.0] if a0 == 1.0 / J0 else [0.0, 0.0, 1.0]
    elif one_j:
        a = [a0, 0.0, 0.0]
    else:
        a = [_nearest(v, SCALES) for v in x[:3]]
    b = np.array([_nearest(v, WEIGHTS) for v in x[len(scaled) :]])
    coef = np.array(a if not one_j else [a[0] + a[1] / J0 + a[2] * J0])
    Kp = split.Ke + np.einsum("k,kmij->mij", np.concatenate([coef, b]), Ke) - _stiffness(t, t.c)
    left = matches(*assemble(split.cells, split.n, split.fe, Kp))
    if not np.isfinite(left):
        return []
    a3 = (float(a[0]), float(a[1]), float(a[2]))
    return [
        Finding(
            "spatial-tangent-pieces",
            "spatial tangent from a UMAT's DDSDDE (the Jaumann-rate tangent, c + T1 + T2 + T3 + "
            "T4 with T1 = d_ik s_jl/2, T2 = s_ik d_jl/2, T3 = d_il s_jk/2, T4 = s_il d_jk/2, s the "
            "Cauchy stress, d Kronecker's delta) converted wrong: " + _words(a3, b, J0),
            FULL,
            "the engine's stiffness fitted by least squares, cell by cell, as c_engine = "
            "(a0 + a_m/J + a_p J) DDSDDE + sum_k b_k T_k from the oracle's per-cell sigma and c "
            f"(fitted: {', '.join(f'{v:.6g}' for v in x)}); taken to a = "
            f"({', '.join(_number(v) for v in a3)}), b = ({', '.join(_number(v) for v in b)}) "
            "(the right: a = (1, 0, 0), b = (-1, -1, -1, -1)) and rebuilt with those numbers: "
            f"errors against your engine {left:.1e}",
            {
                "a": list(a3),
                "b": [float(v) for v in b],
                "fitted": [float(v) for v in x],
                "residual": left,
            },
        )
    ]


#: The isotropic pieces of a law whose spatial tangent is isotropic in J alone (the compressible
#: Neo-Hookean forms): code -> (words, f(J) (m,) -> (m,), the fourth-order tensor (3,3,3,3)).
_D = np.eye(3)
_IXI = np.einsum("ij,kl->ijkl", _D, _D)
_II = 0.5 * (np.einsum("ik,jl->ijkl", _D, _D) + np.einsum("il,jk->ijkl", _D, _D))
ISOTROPIC = {
    "IxI/J": ("(1/J) I (x) I", lambda J: 1.0 / J, _IXI),
    "II/J": ("(1/J) II", lambda J: 1.0 / J, _II),
    "lnJ IxI/J": ("(ln J / J) I (x) I", lambda J: np.log(J) / J, _IXI),
    "lnJ II/J": ("(ln J / J) II", lambda J: np.log(J) / J, _II),
}

#: What one isotropic term of the engine's tangent may be, as a multiple of the oracle's.
RATIOS = {-1.0: "with its sign flipped", 0.0: "dropped", 2.0: "doubled", 0.5: "halved"}

#: The multiples of a material parameter a coefficient is said as.
_MULTIPLES = (1.0, -1.0, 2.0, -2.0, 0.5, -0.5, 4.0, -4.0)


def _in_parameters(x: float, parameters: dict) -> str:
    """The number x as a simple multiple of a material parameter (2 lam), else as it is."""
    for name, value in parameters.items():
        for r in _MULTIPLES:
            if value and abs(x - r * value) <= 1e-9 * abs(x):
                return f"{'-' if r < 0 else ''}{_number(abs(r)) + ' ' if abs(r) != 1 else ''}{name}"
    return f"{x:.6g}"


def _spans_oracle(split: ElementSplit, t: SpatialCells, Ke: np.ndarray, alpha: np.ndarray) -> bool:
    """Whether the pieces' stiffnesses Ke (k, m, 12, 12) with the fitted coefficients alpha (k,)
    give the oracle's material stiffness (that of t.c) to 1e-9: its tangent is of their form.
    """
    y_c = _entries(split, _stiffness(t, t.c))
    fitted = np.stack([_entries(split, k) for k in Ke], 1) @ alpha
    return not np.linalg.norm(fitted - y_c) > 1e-9 * np.linalg.norm(y_c)


def isotropic_fit_findings(
    split: ElementSplit,
    cells: CellTensors,
    K_engine: sp.spmatrix,
    matches: Callable[..., float],
    parameters: dict,
) -> List[Finding]:
    """One term of an isotropic spatial tangent (:data:`ISOTROPIC`) taken wrong
    (:data:`RATIOS`): the oracle's c and the engine's fitted over the pieces' stiffnesses, named
    when the oracle's lies in their span, exactly one coefficient differs by a ratio of
    :data:`RATIOS`, and the rebuilt prediction matches. Nothing on a state whose cells share
    one J (the functions of J coincide there). parameters: the law's name -> value.
    """
    t = spatial_cells(split, cells.S, cells.CC)
    J = t.v / split.V0
    if np.ptp(J) <= ONE_J * np.abs(J).max():
        return _one_j_tensor_findings(split, t, K_engine, matches)
    tensors = [q(J)[:, None, None, None, None] * T for _, q, T in ISOTROPIC.values()]
    Ke = np.stack([_stiffness(t, p) for p in tensors])
    fit = _fit(split, t, Ke, K_engine)
    if fit is None:
        return []
    beta, alpha = fit
    if not _spans_oracle(split, t, Ke, alpha):
        return []  # the oracle's tangent is not of this form
    found = []
    for k, (code, (words, _, _)) in enumerate(ISOTROPIC.items()):
        if alpha[k] == 0.0 or abs(alpha[k]) < 1e-9 * np.abs(alpha).max():
            continue
        ratio = min(RATIOS, key=lambda v: abs(beta[k] / alpha[k] - v))
        Kp = split.Ke + (ratio - 1.0) * alpha[k] * Ke[k]
        left = matches(*assemble(split.cells, split.n, split.fe, Kp))
        if np.isfinite(left):
            term = f"{_in_parameters(alpha[k], parameters)} {words}"
            found.append(
                Finding(
                    "spatial-isotropic-term",
                    f"one term of the isotropic spatial tangent {RATIOS[ratio]}: {term} (II the "
                    "symmetric identity, I (x) I the dyad of identities, J the volume ratio) "
                    f"written as {_in_parameters(ratio * alpha[k], parameters)} {words}",
                    FULL,
                    "the oracle's spatial tangent fits, cell by cell, "
                    + " + ".join(
                        f"{_in_parameters(a, parameters)} {w}"
                        for a, (w, _, _) in zip(alpha, ISOTROPIC.values())
                        if abs(a) >= 1e-9 * np.abs(alpha).max()
                    )
                    + f"; the engine's stiffness fitted so (coefficients "
                    f"{', '.join(f'{v:.6g}' for v in beta)}); that term {RATIOS[ratio]} and "
                    f"the rest kept: errors against your engine {left:.1e}",
                    {"term": code, "ratio": ratio, "residual": left},
                )
            )
    return found or _tensor_findings(split, Ke, alpha, beta, matches, parameters)


#: The pieces of :data:`ISOTROPIC` by the tensor they carry: a coefficient written once for a
#: tensor (2 (mu - lam ln J)/J II with its 2 lost) changes all of that tensor's pieces alike.
TENSORS = {"II": ("II/J", "lnJ II/J"), "I (x) I": ("IxI/J", "lnJ IxI/J")}


def _tensor_findings(split, Ke, alpha, beta, matches, parameters) -> List[Finding]:
    """Every piece of one tensor (:data:`TENSORS`) taken wrong by one ratio of :data:`RATIOS`,
    the other tensor's right: named when the fitted coefficients say that ratio for each of
    its pieces and the rebuilt prediction matches.
    """
    codes = list(ISOTROPIC)
    big = 1e-9 * np.abs(alpha).max()
    found = []
    for tensor, pieces in TENSORS.items():
        idx = [codes.index(p) for p in pieces if abs(alpha[codes.index(p)]) > big]
        if len(idx) < 2:
            continue  # one piece: said as one term above
        ratios = {min(RATIOS, key=lambda v: abs(beta[k] / alpha[k] - v)) for k in idx}
        if len(ratios) != 1:
            continue
        ratio = ratios.pop()
        Kp = split.Ke + (ratio - 1.0) * sum(alpha[k] * Ke[k] for k in idx)
        left = matches(*assemble(split.cells, split.n, split.fe, Kp))
        if not np.isfinite(left):
            continue
        term = " + ".join(
            f"{_in_parameters(alpha[k], parameters)} {ISOTROPIC[codes[k]][0]}" for k in idx
        )
        found.append(
            Finding(
                "spatial-isotropic-term",
                f"the {tensor} term of the isotropic spatial tangent {RATIOS[ratio]} (II the "
                "symmetric identity, I (x) I the dyad of identities, J the volume ratio): "
                f"{term} written {ratio:g} times (its coefficient's factor lost or doubled)",
                FULL,
                "the oracle's spatial tangent fits, cell by cell, in the pieces 1/J and ln J / J "
                f"of I (x) I and II; the engine's coefficients of {tensor}'s pieces are each "
                f"{ratio:g} times the oracle's: that term so and the rest kept: errors against "
                f"your engine {left:.1e}",
                {"term": tensor, "ratio": ratio, "residual": left},
            )
        )
    return found


def _one_j_tensor_findings(split, t, K_engine, matches) -> List[Finding]:
    """On a state whose cells share one J, the functions of J are one number each, but the two
    tensors are still apart: I (x) I and II fitted, one of them taken wrong by a ratio of
    :data:`RATIOS` (the other right) named when that prediction matches.
    """
    tensors = {"I (x) I": _IXI, "II": _II}
    m = split.cells.shape[0]
    Ke = np.stack([_stiffness(t, np.broadcast_to(T, (m, 3, 3, 3, 3))) for T in tensors.values()])
    fit = _fit(split, t, Ke, K_engine)
    if fit is None:
        return []
    beta, alpha = fit
    if not _spans_oracle(split, t, Ke, alpha):
        return []  # the oracle's tangent is not isotropic
    found = []
    for k, tensor in enumerate(tensors):
        if abs(alpha[k]) < 1e-9 * np.abs(alpha).max():
            continue
        ratio = min(RATIOS, key=lambda v: abs(beta[k] / alpha[k] - v))
        left = matches(
            *assemble(split.cells, split.n, split.fe, split.Ke + (ratio - 1.0) * alpha[k] * Ke[k])
        )
        if np.isfinite(left):
            found.append(
                Finding(
                    "spatial-isotropic-term",
                    f"the {tensor} term of the isotropic spatial tangent {RATIOS[ratio]} (II the "
                    "symmetric identity, I (x) I the dyad of identities; this state has one J, "
                    "so its coefficient is one number here)",
                    FULL,
                    f"the oracle's spatial tangent is {alpha[0]:.6g} I (x) I + {alpha[1]:.6g} II "
                    f"in every cell; the engine's fitted {beta[0]:.6g} and {beta[1]:.6g}: that "
                    f"term times {ratio:g} and the other kept: errors against your engine "
                    f"{left:.1e}",
                    {"term": tensor, "ratio": ratio, "residual": left},
                )
            )
    return found


#: The simple numbers the pressure pieces' weights are taken to (right: -2 on p II, 0 on
#: p I (x) I).
PRESSURE_WEIGHTS = (0.0, 1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0, -4.0, 6.0, -6.0)


def _signed(x: float, what: str) -> str:
    """' + 2 T(s)', ' - p II' ('' for 0)."""
    if x == 0.0:
        return ""
    k = abs(x)
    return f" {'-' if x < 0 else '+'} {'' if k == 1.0 else _number(k) + ' '}{what}"


#: (offset of T(s), of p II) -> how a UMAT comes to it.
_PRESSURE_CAUSES = {
    (-2.0, 0.0): "the deviatoric stress's Jaumann-rate terms subtracted in DDSDDE where they "
    "belong added, and removed again by the conversion",
    (0.0, -2.0): "the volumetric part of DDSDDE written in its Truesdell form, (p + J dp/dJ) "
    "I (x) I - 2 p II, where the Jaumann DDSDDE has (p + J dp/dJ) I (x) I alone: -2 p II counted "
    "twice",
    (0.0, 2.0): "the pressure's rate terms added to a Truesdell tangent, or not removed",
}


def _pressure_words(b: np.ndarray, w: Tuple[float, float]) -> str:
    """The engine's tangent as the Truesdell c plus multiples of the deviatoric stress's
    Jaumann terms T_k(s) (weights b (4,), right -1) and of p II, p I (x) I (weights w, right
    (-2, 0)), in words.
    """
    if np.all(b == b[0]):
        text = "c" + _signed(b[0] + 1.0, "T(s)")
    else:
        text = "c" + "".join(_signed(b[k] + 1.0, f"({TERMS[k]} of s)") for k in range(4))
    text += _signed(w[0] + 2.0, "p II") + _signed(w[1], "p I (x) I")
    cause = _PRESSURE_CAUSES.get((b[0] + 1.0, w[0] + 2.0)) if np.all(b == b[0]) else None
    return (
        f"your spatial tangent is {text} (c the Truesdell tangent; T(s) = (d_ik s_jl + s_ik d_jl "
        "+ d_il s_jk + s_il d_jk)/2 the Jaumann-rate terms of the deviatoric stress "
        "s = dev(sigma), 2 p II those of the pressure, p = tr(sigma)/3: a UMAT's DDSDDE is "
        "c + T(s) + 2 p II)" + (f": e.g. {cause}" if cause and not w[1] else "")
    )


def deviatoric_piece_findings(
    split: ElementSplit,
    cells: CellTensors,
    K_engine: sp.spmatrix,
    matches: Callable[..., float],
) -> List[Finding]:
    """:func:`piece_fit_findings` with the Jaumann terms of the deviatoric stress and the
    pressure's, p II and p I (x) I (p = tr(sigma)/3), as pieces of their own: a UMAT that
    writes its volumetric DDSDDE in another rate's form, or removes the deviatoric stress's
    Jaumann terms alone, weights them apart. Nothing where these pieces are not determined (a
    law whose tangent is a multiple of II and I (x) I with p in every cell, on a state of one
    J) or where the weights say what :func:`piece_fit_findings` reads.
    """
    t, J, one_j, scaled = _ddsdde_columns(split, cells)
    m = split.cells.shape[0]
    p = np.trace(t.sigma, axis1=1, axis2=2) / 3.0
    T = jaumann_pieces(t.sigma - p[:, None, None] * np.eye(3))
    P = [p[:, None, None, None, None] * np.broadcast_to(X, (m, 3, 3, 3, 3)) for X in (_II, _IXI)]
    pieces = scaled + list(T) + P
    Ke = np.stack([_stiffness(t, q) for q in pieces])
    fit = _fit(split, t, Ke, K_engine)
    if fit is None:
        return []
    x, _ = fit
    k = len(scaled)
    if one_j:
        a = [_nearest(x[0], SCALES), 0.0, 0.0]
    else:
        a = [_nearest(v, SCALES) for v in x[:3]]
    b = np.array([_nearest(v, WEIGHTS) for v in x[k : k + 4]])
    w = (_nearest(x[k + 4], PRESSURE_WEIGHTS), _nearest(x[k + 5], PRESSURE_WEIGHTS))
    if (np.all(b == b[0]) and w == (2.0 * b[0], 0.0)) or (np.all(b == -1.0) and w == (-2.0, 0.0)):
        return []  # the whole stress's terms by one weight, or right: piece_fit_findings' to say
    coef = np.concatenate([a[:k], b, w])
    Kp = split.Ke + np.einsum("k,kmij->mij", coef, Ke) - _stiffness(t, t.c)
    left = matches(*assemble(split.cells, split.n, split.fe, Kp))
    if not np.isfinite(left):
        return []
    a3 = (float(a[0]), float(a[1]), float(a[2]))
    said = [_words(a3, np.full(4, -1.0), float("nan"))] if a3 != (1.0, 0.0, 0.0) else []
    said.append(_pressure_words(b, w))
    return [
        Finding(
            "spatial-tangent-pieces",
            "spatial tangent from a UMAT's DDSDDE (the Jaumann-rate tangent, c + T(sigma), "
            "T(sigma) = (d_ik s_jl + s_ik d_jl + d_il s_jk + s_il d_jk)/2 = T(s) + 2 p II for "
            "s = dev(sigma), p = tr(sigma)/3) converted wrong: " + "; ".join(x for x in said if x),
            FULL,
            "the engine's stiffness fitted by least squares, cell by cell, as c_engine = "
            "(a0 + a_m/J + a_p J) DDSDDE + sum_k b_k T_k(s) + w1 p II + w2 p I (x) I from the "
            f"oracle's per-cell sigma and c (fitted: {', '.join(f'{v:.6g}' for v in x)}); taken "
            f"to b = ({', '.join(_number(v) for v in b)}), w = ({_number(w[0])}, "
            f"{_number(w[1])}) (the right: a = (1, 0, 0), b = (-1, -1, -1, -1), w = (-2, 0)) "
            f"and rebuilt with those numbers: errors against your engine {left:.1e}",
            {"a": list(a3), "b": [float(v) for v in b], "w": list(w), "residual": left},
        )
    ]


#: The products X (.) X a spatial tangent holds (X_ik X_jl + X_il X_jk) / 2: the tensor X per
#: cell from b (m, 3, 3), and what it is.
PRODUCTS = {
    "I (.) I": (lambda b: np.broadcast_to(np.eye(3), b.shape), "II, the symmetric identity"),
    "b (.) b": (lambda b: b, "b (.) b (St Venant-Kirchhoff's push-forward of II)"),
}


def unsymmetrised_product_findings(
    split: ElementSplit,
    cells: CellTensors,
    K_engine: sp.spmatrix,
    matches: Callable[..., float],
    parameters: dict,
) -> List[Finding]:
    """A product X (.) X of the spatial tangent written X_ik X_jl (one index order) and packed
    into a Voigt DDSDDE, which keeps the entries (ij) <= (kl) of the six slots: the engine's c
    holds beta (X_ik X_jl - X_il X_jk) / 2 more on those entries (minor symmetry restored by
    the packing), beta (the product's coefficient) fitted with one unknown per group of cells
    in the same state (:func:`conformance.diagnosis.stress_forms.group_fit`); named when the
    rebuilt stiffness matches, the force right.
    """
    from conformance.diagnosis.strain_differences import voigt_matrix, voigt_tensor
    from conformance.diagnosis.stress_forms import group_fit

    t = spatial_cells(split, cells.S, cells.CC)
    J = t.v / split.V0
    b = split.F @ split.F.swapaxes(1, 2)
    f0, K0 = assemble(split.cells, split.n, split.fe, split.Ke)
    dK = sp.csr_matrix(K_engine) - K0
    zero = np.zeros((split.cells.shape[0], 4, 3))
    found = []
    for name, (tensor, words) in PRODUCTS.items():
        X = tensor(b)
        half = 0.5 * (np.einsum("mik,mjl->mijkl", X, X) - np.einsum("mil,mjk->mijkl", X, X))
        packed = voigt_tensor(voigt_matrix(half))
        Ke = _stiffness(t, packed)
        beta = group_fit(split, zero, Ke, np.zeros((split.n, 3)), dK, _UNIT)
        if beta is None or not np.any(beta):
            continue
        Kp = split.Ke + beta[:, None, None] * Ke
        left = matches(*assemble(split.cells, split.n, split.fe, Kp))
        if not np.isfinite(left):
            continue
        said = _in_parameters(float(np.median(beta * J)), parameters)
        steady = np.ptp(beta * J) <= 1e-6 * np.abs(beta * J).max()
        found.append(
            Finding(
                "spatial-unsymmetrised-product",
                f"the product {name} of your spatial tangent ({words}) written with one index "
                f"order, X_ik X_jl, where (X_ik X_jl + X_il X_jk)/2 belongs, then packed into a "
                "Voigt DDSDDE (the minor symmetrisation lost on its shear entries)",
                FULL,
                "the oracle's c plus beta (X_ik X_jl - X_il X_jk)/2 on the Voigt entries, beta "
                "fitted per cell ("
                + (f"beta J = {said} in every cell" if steady else "beta varying over the cells")
                + f"): errors against your engine {left:.1e}",
                {"product": name, "beta_J_median": float(np.median(beta * J)), "residual": left},
            )
        )
    return found


#: Unit scales: the stiffness fit of :func:`unsymmetrised_product_findings` weighs nothing
#: against a force (none is fitted there).
_UNIT = Scales(1.0, 1.0, 1.0)
