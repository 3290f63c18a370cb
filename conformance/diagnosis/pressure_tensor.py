"""The J part of a term's stress written with another tensor than C^-1.

A term f(J) g(C) contributes to the second Piola stress its J part f'(J) g J C^-1 (the pressure
part, for a volumetric term U(J): J U'(J) C^-1). Hand-written engines put another tensor there:

- the identity: in a principal-stress engine, S_a = tau_a / lambda_a^2 with the 1/lambda_a^2
  left out of this part; or the spatial form of the pressure (sigma = p I) carried into S;
- C, the inverse forgotten;
- b^-1 = F^-T F^-1, the inverse of the left Cauchy-Green tensor where that of the right one
  belongs (F F^T inverted for F^T F);
- C^(-1/2), each principal value divided by the stretch lambda_a where its square belongs (a
  principal-stress engine writing S_a = tau_a / lambda_a for tau_a / lambda_a^2).

Each variant changes the force alone (by f'(J) g J F (X - C^-1) D_a per cell and node); a term
whose f is a polynomial in ln J is also read monomial by monomial (an engine writing
k0 ln J C^-1 - mu C^-1 may slip in one of them). What the engine's stiffness does is its own
(a hand tangent may be right, or built from the wrong stress): :mod:`conformance.diagnosis.
mjed_parts` names a variant in full when the stiffness is right, and otherwise says it explains
the force alone.
"""

from __future__ import annotations

from typing import Any, Callable, Dict, List, Tuple

import numpy as np

from conformance.diagnosis.elements import cell_kinematics

__all__ = ["TENSORS", "j_tensor_forces"]


def _sym_power(C: np.ndarray, p: float) -> np.ndarray:
    """C^p (m, 3, 3) of symmetric positive definite C (m, 3, 3), by eigen-decomposition."""
    c, N = np.linalg.eigh(C)
    return np.einsum("mia,ma,mja->mij", N, c**p, N)


#: words -> X (m, 3, 3) from F (m, 3, 3) and C = F^T F, put where C^-1 belongs.
TENSORS: Dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "I (in principal form the 1/lambda_a^2 of each principal value left out; or a spatial "
    "sigma = p I carried into S)": (lambda F, C: np.broadcast_to(np.eye(3), C.shape)),
    "C (the inverse forgotten)": lambda F, C: C,
    "b^-1 = (F F^T)^-1 (the left Cauchy-Green tensor inverted for the right one)": (
        lambda F, C: np.linalg.inv(F @ F.swapaxes(1, 2))
    ),
    "C^(-1/2) (principal values over the stretch lambda_a where lambda_a^2 belongs)": (
        lambda F, C: _sym_power(C, -0.5)
    ),
}


def _pieces(term: Any) -> List[Tuple[str, Any]]:
    """(words, f) of a term's J function: itself, and each monomial of a polynomial in ln J
    with two or more of them.
    """
    from mjed.terms import LogPolynomial

    f = term.f
    out = [("", f)]
    if isinstance(f, LogPolynomial) and f.a2 != 0.0 and f.a1 != 0.0:
        out.append((f" (its {f.a2:.6g} (ln J)^2 alone)", LogPolynomial(f.a2)))
        out.append((f" (its {f.a1:.6g} ln J alone)", LogPolynomial(0.0, f.a1)))
    return out


def j_tensor_forces(
    model: Any,
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    label: Callable[[Any, Any], str],
    assemble_force: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> List[Tuple[str, str, np.ndarray]]:
    """(term words, tensor words, engine-minus-oracle force (3n,)) of every variant: each term
    (and monomial) alone, and the same tensor in every term's J part. label(term, group): the
    term in words; assemble_force(fe (m, 4, 3), V0 (m,)): the nodal sum, as the oracle's force
    (minus dW/dx). Empty when the model has no MJED decomposition.
    """
    from mjed.kinematics import Kinematics

    try:
        groups = model.decomposition()
    except Exception:  # noqa: BLE001 - not an MJED material: nothing to read
        return []
    V0, D, F = cell_kinematics(points, cells, x)
    kin = Kinematics(F)
    J = kin.J
    C = F.swapaxes(1, 2) @ F
    Cinv = np.linalg.inv(C)
    tensors = {words: make(F, C) - Cinv for words, make in TENSORS.items()}
    scales: List[Tuple[str, np.ndarray]] = []
    for group in groups:
        built = [(t, t.f(J), np.broadcast_to(t.g.value(kin), J.shape)) for t in group.terms]
        w1 = np.broadcast_to(np.asarray(group.coefficient, dtype=float), J.shape)
        if not group.plain:
            u = np.sum([f[0] * g for _, f, g in built], axis=0)
            w1 = group.coefficient * group.function(u)[1]
        for term, _, g in built:
            for words, f in _pieces(term):
                f1 = np.broadcast_to(f(J)[1], J.shape)
                if np.any(f1 * g):
                    scales.append((label(term, group) + words, w1 * f1 * g * J))
    out = []
    for tensor, dX in tensors.items():
        every = np.zeros(3 * len(points))
        for which, scale in scales:
            fe = scale[:, None, None] * np.einsum("mik,mkl,mal->mai", F, dX, D)
            df = -assemble_force(fe, V0)  # the oracle's force is -dW/dx
            out.append((f"of the term {which}", tensor, df))
            if "alone)" not in which:
                every = every + df
        if len([s for s in scales if "alone)" not in s[0]]) > 1:
            out.append(("of every term", tensor, every))
    return out
