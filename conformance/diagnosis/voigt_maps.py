"""A Voigt stress vector read through the wrong map: components in another order, a shear
factor, a sign.

Engines written in Voigt notation (the force r = V0 B^T s of a 6-vector s, B the nonlinear
strain-displacement matrix) hold the stress as six numbers whose order and shear convention
must agree between the routine that fills s and the matrix B that reads it: (11, 22, 33, 12,
23, 13) against (11, 22, 33, 23, 13, 12), a tensor shear S_12 where an engineering one is
read, a component typed with the wrong sign. Each of these is one fixed 6 x 6 map M, the same
in every cell: the engine's force is that of s' = M s.

The force is linear in M, so M is fitted by least squares over the 36 per-cell patterns
(s_B put in component A, assembled as element forces -V0 F S D_a), from the oracle's per-cell
second Piola stress. The fit is then snapped to the numbers a slip writes (0, +-1/2, +-1, +-2)
and the snapped map, nothing fitted, must give the engine's force within the case's tolerance;
only then is it named, with the map in words (a permutation of components, factors, signs).
The stiffness is said right or not; a stiffness built from the same misread s is not
predicted here.

The material tangent D = dS/dE of such an engine (a 6 x 6 matrix whose rows meet the rows of B)
is read through the unpacking slips of :data:`conformance.diagnosis.spatial_variants.VOIGT_SLIPS`
(the shear slots in another order, a factor 2 or 1/2 on the shear rows, columns or both, the
mirror entries left zero), applied here to the total-Lagrangian CC: the stiffness
K + V0 D_a F (CC' - CC) F D_b predicted per cell with nothing fitted, the force right.
"""

from __future__ import annotations

from typing import List, Optional

import numpy as np

from conformance.diagnosis.elements import (
    ElementSplit,
    assemble,
    case_split,
    cell_piola,
    tangent_element_matrices,
)
from conformance.diagnosis.findings import FULL, PARTIAL, Finding, named_first
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.strain_differences import (
    material_stiffness,
    symmetric_from_voigt,
    voigt_matrix,
    voigt_tensor,
    voigt_vector,
)
from conformance.judge.compare import errors

__all__ = [
    "NAMES",
    "voigt_map_patterns",
    "fit_voigt_map",
    "voigt_map_words",
    "voigt_map_findings",
    "geometric_stiffness",
    "tangent_slip_findings",
    "voigt_map_reading",
]

NAMES = ("11", "22", "33", "12", "23", "13")

#: The numbers a misread Voigt map holds.
_SNAP = np.array([0.0, 0.5, -0.5, 1.0, -1.0, 2.0, -2.0])
#: How far a fitted entry may be from its snapped value.
_SNAP_TOL = 0.05


def voigt_map_patterns(split: ElementSplit, S: np.ndarray, spatial: bool = False) -> np.ndarray:
    """(36, n, 3): the force of s_B (the B-th Voigt component of S (m, 3, 3)) written into
    component A, for A, B in 0..5 (row 6 A + B). spatial: S is the Cauchy stress of an
    updated-Lagrangian engine (f_a = -v sigma g_a, g = D F^-1, v = J V0), not the second Piola
    stress (f_a = -V0 F S D_a).
    """
    s = voigt_vector(S)
    units = symmetric_from_voigt(np.eye(6))  # (6, 3, 3): component A alone (a shear: both)
    if spatial:
        J = np.linalg.det(split.F)
        g = split.D @ np.linalg.inv(split.F)
        FD = np.einsum("kI,maJ->mkIaJ", np.eye(3), g)
        w = J * split.V0
    else:
        FD = np.einsum("mkI,maJ->mkIaJ", split.F, split.D)
        w = split.V0
    out = np.empty((36, split.n, 3))
    for A in range(6):
        base = -w[:, None, None] * np.einsum("mkIaJ,IJ->mak", FD, units[A])  # (m, 4, 3)
        for B in range(6):
            fe = s[:, B, None, None] * base
            out[6 * A + B] = assemble(split.cells, split.n, fe, None)[0]
    return out


def fit_voigt_map(patterns: np.ndarray, error: np.ndarray) -> Optional[np.ndarray]:
    """The snapped 6 x 6 map M (M - I fitted to the force error (n, 3) over ``patterns``), or
    None when the fit is not near a map of :data:`_SNAP` numbers or snaps to the identity.
    """
    Aop = patterns.reshape(36, -1).T
    dM, *_ = np.linalg.lstsq(Aop, error.ravel(), rcond=None)
    M = np.eye(6) + dM.reshape(6, 6)
    snapped = _SNAP[np.argmin(np.abs(M[..., None] - _SNAP), axis=-1)]
    if np.max(np.abs(M - snapped)) > _SNAP_TOL or np.array_equal(snapped, np.eye(6)):
        return None
    return snapped


def voigt_map_words(M: np.ndarray) -> str:
    """The map in words: a permutation of components (with factors), else its rows."""

    def number(c: float) -> str:
        return {1.0: "", -1.0: "-", 2.0: "2 ", -2.0: "-2 ", 0.5: "1/2 ", -0.5: "-1/2 "}[c]

    nz = M != 0
    shear = np.diag(M)[3:]
    if np.array_equal(M, np.diag(np.diag(M))) and np.all(np.diag(M)[:3] == 1.0):
        if np.all(shear == shear[0]) and shear[0] in (2.0, 0.5):
            how = "doubled" if shear[0] == 2.0 else "halved"
            return (
                f"the three shear components {how} (s_12 holds {number(shear[0])}S_12, and "
                "likewise 23 and 13: an engineering factor 2 applied twice, or missing, between "
                "the stress vector and the shear rows of B)"
            )
    if np.all(nz.sum(axis=1) == 1) and np.all(nz.sum(axis=0) <= 1):
        parts = []
        for A in range(6):
            B = int(np.flatnonzero(nz[A])[0])
            if A != B or M[A, B] != 1.0:
                parts.append(f"s_{NAMES[A]} holds {number(M[A, B])}S_{NAMES[B]}")
        return "; ".join(parts)
    rows = []
    for A in range(6):
        terms = [f"{number(M[A, B])}S_{NAMES[B]}" for B in range(6) if M[A, B] != 0]
        if not (len(terms) == 1 and M[A, A] == 1.0):
            rows.append(f"s_{NAMES[A]} = " + (" + ".join(terms) if terms else "0"))
    return "; ".join(rows)


def _spatial_stiffness(split: ElementSplit, dc: np.ndarray):
    """The assembled v (g_a . dc . g_b) of per-cell spatial tangents dc (m, 3, 3, 3, 3)."""
    J = np.linalg.det(split.F)
    g = split.D @ np.linalg.inv(split.F)
    Ke = np.einsum("m,maj,mijkl,mbl->maibk", J * split.V0, g, dc, g).reshape(-1, 12, 12)
    return assemble(split.cells, split.n, np.zeros((split.V0.size, 4, 3)), Ke)[1]


def voigt_map_findings(
    split: ElementSplit, f, K, f_o, K_o, s, tol, stiffness_known: bool = True
) -> List[Finding]:
    """The misread Voigt map whose exact force is the engine's (f (n, 3)), or []: of the second
    Piola stress (a total-Lagrangian engine), else of the Cauchy stress (an updated-Lagrangian
    engine's spatial B matrix). stiffness_known: False where the engine's stiffness is not
    known (a probe: K is then the oracle's and nothing is said of it).
    """
    from conformance.diagnosis.spatial_tangent import spatial_cells

    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    S, CC = t.S, t.CC
    error = np.asarray(f, dtype=float) - np.asarray(f_o, dtype=float)
    for spatial in (False, True):
        sc = spatial_cells(split, S, CC) if spatial else None
        patterns = voigt_map_patterns(split, sc.sigma if spatial else S, spatial)
        M = fit_voigt_map(patterns, error)
        if M is None:
            continue
        dM = M - np.eye(6)
        predicted = np.asarray(f_o, dtype=float) + np.tensordot(dM.ravel(), patterns, axes=1)
        e = errors(f, K, None, predicted, K_o, 0.0, s)
        if e.force <= tol.force:
            break
    else:
        return []
    # The rows of B read through the map (B' = R B, M = R^T): the material stiffness
    # B'^T D B' = B^T (M D M^T) B carries it too, the geometric part (from S) does not.
    if spatial:
        D = voigt_matrix(sc.c)
        dK_rows = _spatial_stiffness(split, voigt_tensor(M @ D @ M.T) - sc.c)
    else:
        D = voigt_matrix(CC)
        dK_rows = material_stiffness(split, voigt_tensor(M @ D @ M.T) - CC)
    e_rows = errors(f, K, None, predicted, K_o + dK_rows, 0.0, s)
    if not stiffness_known:
        where, strength, said = "the stress vector or the rows of B", FULL, "force alone compared"
    elif e.stiffness <= tol.stiffness:
        where, strength, said = "the stress vector", FULL, "your stiffness is right"
    elif e_rows.stiffness <= tol.stiffness:
        where, strength = "the rows of B (so B^T D B carries it too)", FULL
        said = f"your stiffness is B'^T D B' + K_geo with B' so read: error {e_rows.stiffness:.1e}"
    else:
        where, strength = "the stress vector or the rows of B", PARTIAL
        said = f"your stiffness is wrong as well ({e.stiffness:.1e}), which this does not predict"
    return [
        Finding(
            "voigt-map",
            f"{'the Cauchy stress: ' if spatial else ''}{where} read through another Voigt "
            "map than the one it was filled in: "
            f"{voigt_map_words(M)} (the Voigt order or shear convention of s and of the rows of "
            "B disagree, or a component is typed wrongly)",
            strength,
            "the force of s' = M s per cell, M fitted over the 36 component patterns from the "
            "oracle's per-cell S and snapped to the numbers such a slip writes, then predicted "
            f"with nothing fitted: force error {e.force:.1e}; {said}",
            {"map": M.tolist()},
        )
    ]


def geometric_stiffness(split: ElementSplit, dS: np.ndarray):
    """The assembled geometric stiffness V0 (D_a . dS D_b) I3 of per-cell stresses dS (m, 3, 3):
    the element matrices of the tangent delta_kl dS_IL.
    """
    A = np.einsum("kl,mIL->mkIlL", np.eye(3), dS)
    Ke = tangent_element_matrices(split.V0, split.D, A)
    return assemble(split.cells, split.n, np.zeros((split.V0.size, 4, 3)), Ke)[1]


def _stress_maps() -> List[tuple]:
    """(words, M) of the maps a stress vector unpacked for the geometric stiffness may go
    through: the shears doubled or halved (unpacked with the strain's engineering factor, or
    packed with it), the shear slots in another order.
    """
    out = [
        ("the three shear stresses doubled", np.diag([1, 1, 1, 2, 2, 2.0])),
        (
            "the three shear stresses halved (unpacked with the strain's engineering factor)",
            np.diag([1, 1, 1, 0.5, 0.5, 0.5]),
        ),
    ]
    for order in ((3, 5, 4), (4, 3, 5), (4, 5, 3), (5, 3, 4), (5, 4, 3)):
        M = np.zeros((6, 6))
        for a, b in enumerate((0, 1, 2, *order)):
            M[a, b] = 1.0
        out.append((f"the shear stresses in another order ({voigt_map_words(M)})", M))
    return out


def _mapped(S: np.ndarray, M: np.ndarray) -> np.ndarray:
    """(m, 3, 3) the symmetric S' whose Voigt vector is M times S's."""
    return symmetric_from_voigt(voigt_vector(S) @ M.T)


def tangent_slip_findings(split: ElementSplit, f, K, f_o, K_o, s, tol) -> List[Finding]:
    """The Voigt unpacking slips of the material tangent, and the maps of the stress in the
    geometric stiffness, whose exact stiffness is the engine's (K), the force right; several:
    each said (the caller shows them as ambiguous).
    """
    from conformance.diagnosis.spatial_variants import VOIGT_SLIPS, slip_tensor

    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    CC, S = t.CC, t.S
    base = errors(f, K, None, f_o, K_o, 0.0, s)
    found = []
    for words, M in _stress_maps():
        e = errors(f, K, None, f_o, K_o + geometric_stiffness(split, _mapped(S, M) - S), 0.0, s)
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    "voigt-geometric-stress",
                    f"the stress of your geometric stiffness read through another Voigt map: "
                    f"{words} (the stress vector unpacked for K_geo with another helper or "
                    "order than the force's)",
                    FULL,
                    "the oracle's per-cell S so mapped in V0 (D_a . S D_b) I3 alone, the material "
                    f"part and the force right (nothing fitted): stiffness error {e.stiffness:.1e} "
                    f"(against {base.stiffness:.1e})",
                    {"map": M.tolist()},
                )
            )
    for slip in VOIGT_SLIPS:
        dCC = slip_tensor(CC, slip) - CC
        if not np.any(dCC):
            continue
        e = errors(f, K, None, f_o, K_o + material_stiffness(split, dCC), 0.0, s)
        if tol.within(e, energy=False):
            found.append(
                Finding(
                    f"voigt-tangent-{slip.code}",
                    "your material tangent D = dS/dE (Voigt) read through another map than it "
                    f"was filled in: {slip.words}",
                    FULL,
                    "the oracle's per-cell CC so unpacked, its material stiffness "
                    "V0 D_a F CC' F D_b assembled with the geometric part right (nothing "
                    f"fitted): stiffness error {e.stiffness:.1e} (against {base.stiffness:.1e}); "
                    "the force right",
                    {"slip": slip.code},
                )
            )
    return found


def voigt_map_reading(diag, ci, out, ref, s):
    """``diag`` (nothing named) with a misread Voigt map named first: the stress's when the
    force is wrong (its exact force the engine's), the tangent's when only the stiffness is;
    unchanged otherwise, and when the engine's energy is wrong: a vector misread between the
    material routine and B leaves the energy right, so a wrong energy puts the mistake
    upstream (in the strain or the kinematics both use).
    """
    from conformance.diagnosis.findings import ambiguous

    e = diag.errors.energy
    if e is not None and e > diag.tolerances.energy:
        return diag
    split = case_split(diag, ci, ref, s)
    if split is None:
        return diag
    args = (split, out.force, out.stiffness, ref.force, ref.stiffness, s, diag.tolerances)
    with np.errstate(all="ignore"):
        if diag.errors.force > diag.tolerances.force:
            found = voigt_map_findings(*args)
        else:
            found = tangent_slip_findings(*args)
    if len(found) > 1:
        found = ambiguous(found, "each predicts your stiffness")
    return named_first(diag, found)
