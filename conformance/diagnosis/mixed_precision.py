"""Part of a double-precision engine in single precision: an intermediate (C, F, S, the
positions) rounded to float32, or the material routine run in float32, the assembly in double.

Such an engine keeps the balance laws (each cell's forces still sum to zero in double), so it
has not float32's own signature (:mod:`conformance.diagnosis.roundoff`), and its errors, 1e-9 to
1e-6, are as small as a slightly wrong constant's. What tells them apart:

- **Noise.** A formula error is a smooth function of the positions: at the kit's probes
  (x + h d, h about 1e-4 of the cells' size) the error is the same to about h (correlation 1,
  relative change 1e-4). Float32 round-off is not: a strain change of 1e-4 is thousands of
  float32 steps, and the rounding of every cell is drawn anew (correlation near 0, change about
  1 or more). Measured on the forces of the case and of each probe, engine minus oracle.
- **The rounding's own pattern.** The oracle's answer is split into cells (MJED's element
  forces, used only where their sum is the oracle's) and each hypothesis is computed exactly:
  C rounded to float32 and the rest in double (F' = R sqrt(C32) evaluated, its force carried
  back with F F'^-1), F rounded, the positions rounded, S, P or the Cauchy stress rounded (a
  stress field kept in float32 between the material routine and a double assembly). Where the
  cells differ, the engine's error correlates with one of these patterns, which no formula
  error or other noise does (chance measured with random per-cell patterns:
  :func:`chance_correlation`); its size is that pattern's to a small factor.

The stiffness alone in single precision (the material routine's tangent in float32, its
stress in double: the force and energy double-exact) keeps the balance laws too and leaves no
trace in the force, so neither test applies; there the rounding is predicted exactly instead
(:func:`rounded_tangent_finding`: the oracle's per-cell tangent rounded in one of its usual
forms, as the element buffers of :func:`rounded_elements_finding` are), and a double engine
with a small systematic tangent error does not match it.

Named only with both where the kit has probes, or, without probes, with a strong correlation
over many distinct cells; otherwise nothing (the caller's systematic reading stands). NumPy
and MJED only; the oracle at the probes is one force assembly each.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from conformance.diagnosis.elements import ElementSplit, assemble, piola_element_forces
from conformance.diagnosis.findings import FULL, Finding, named_first
from conformance.diagnosis.part_scalars import part_scalar_findings

__all__ = [
    "NOISE_CORRELATION",
    "PATTERN_CORRELATION",
    "Noise",
    "noise",
    "chance_correlation",
    "rounding_patterns",
    "mixed_precision_finding",
    "mixed_precision_reading",
    "rounded_elements_finding",
    "rounded_elements_reading",
    "rounded_tangent_finding",
    "rest_rounding_patterns",
    "rest_rounding_finding",
]

#: A probe's error counts as drawn anew when it differs from the case's by more than
#: :data:`NOISE_CHANGE` of its size (a smooth error changes by about the step, 1e-4) and their
#: |correlation| is below this (independent draws on a small mesh can correlate by 0.5).
NOISE_CORRELATION = 0.9
NOISE_CHANGE = 0.5

#: Smallest correlation with a rounding pattern that names it (chance: about 1 / sqrt(3n)).
PATTERN_CORRELATION = 0.3

#: The correlation with a rounding pattern must be this many times what chance gives.
SIGNIFICANT = 3.0

#: Without probes: the correlation needed, over at least this many distinct rounded cells.
UNPROBED_CORRELATION = 0.5
UNPROBED_CELLS = 50

#: The engine's error may be this many times the pattern's, or its inverse (float32 arithmetic
#: after the rounding adds errors of the same order).
SIZE_FACTOR = 30.0

_WHAT = {
    "C": "C = F^T F rounded to float32",
    "F": "F rounded to float32",
    "S": "the second Piola-Kirchhoff stress S rounded to float32",
    "P": "the first Piola-Kirchhoff stress P rounded to float32 (a float32 stress field)",
    "sigma": "the Cauchy stress sigma rounded to float32 (a float32 stress field)",
    "positions": "the positions rounded to float32",
    "grad I_C": "the gradient of I_C = tr C (2 F) computed from F rounded to float32, the rest in "
    "double",
    "grad II_C": "the gradient of II_C = C : C (4 F C) computed from F rounded to float32, the "
    "rest in double",
    "grad J": "the gradient of J, the cofactor matrix cof F, computed from F rounded to float32, "
    "the rest in double",
}

#: The pieces Psi_a dI_a/dF of P whose gradient alone may be computed from a float32 F (a
#: single-precision vector kernel for the cross products of cof F, say), by invariant.
_PIECES = ("grad I_C", "grad II_C", "grad J")


def _f32(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).astype(np.float32).astype(np.float64)


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return float(np.vdot(a, b) / (na * nb)) if na > 0 and nb > 0 else 0.0


@dataclass(frozen=True)
class Noise:
    """correlations (k,): of the case's force error with each probe's; changes (k,): |e_k - e_0|
    / |e_0|. noisy: every probe's error is drawn anew (not a smooth function of x).
    """

    correlations: np.ndarray
    changes: np.ndarray

    @property
    def noisy(self) -> bool:
        return bool(
            self.correlations.size
            and np.all(np.abs(self.correlations) < NOISE_CORRELATION)
            and np.all(self.changes > NOISE_CHANGE)
        )


def noise(error: np.ndarray, probe_errors: Sequence[np.ndarray]) -> Noise:
    """The case's force error (n, 3) against its probes' (each (n, 3)), engine minus oracle."""
    e0 = np.ravel(error)
    n0 = np.linalg.norm(e0)
    r = [_correlation(e0, np.ravel(e)) for e in probe_errors]
    c = [np.linalg.norm(np.ravel(e) - e0) / n0 if n0 > 0 else 0.0 for e in probe_errors]
    return Noise(np.asarray(r, dtype=float), np.asarray(c, dtype=float))


def _sqrtm(S: np.ndarray) -> np.ndarray:
    """Symmetric square roots of SPD matrices (m, 3, 3)."""
    w, V = np.linalg.eigh(S)
    return np.einsum("mij,mj,mkj->mik", V, np.sqrt(w), V)


def _element_forces(model: Any, points: np.ndarray, cells: np.ndarray, F: np.ndarray):
    """MJED's element forces (m, 4, 3) of each cell deformed by F (m, 3, 3) on its own nodes;
    None where MJED cannot (not finite at that F).
    """
    import mjed

    m = cells.shape[0]
    X = points[cells]
    rest = X.reshape(-1, 3)
    x = np.einsum("mij,maj->mai", F, X).reshape(-1, 3)
    try:
        field = mjed.make_force_field(
            mjed.TetMesh(rest, np.arange(4 * m, dtype=np.int64).reshape(m, 4)), model
        )
        fe = np.asarray(field.element_forces(x), dtype=np.float64)
    except Exception:  # noqa: BLE001 - not at this state: no pattern
        return None
    return fe if np.all(np.isfinite(fe)) else None


def rounding_patterns(
    split: ElementSplit, model: Any, points: np.ndarray, positions: np.ndarray
) -> Dict[str, np.ndarray]:
    """The force change (n, 3) of each rounding hypothesis of :data:`_WHAT`, by its name,
    computed in double from MJED per cell; a hypothesis MJED cannot evaluate is left out.
    """
    from mjed.kinematics import deformation_gradient

    cells, n, F = split.cells, split.n, split.F
    base = _element_forces(model, points, cells, F)
    if base is None:
        return {}
    f0 = assemble(cells, n, base, None)[0]
    out: Dict[str, np.ndarray] = {}
    C = np.einsum("mki,mkj->mij", F, F)
    Fc = F @ np.linalg.inv(_sqrtm(C)) @ _sqrtm(_f32(C))  # F'^T F' = C32, F' near F
    fe = _element_forces(model, points, cells, Fc)
    if fe is not None:  # the engine's P = F S(C32) = (F F'^-1) P'
        out["C"] = np.einsum("mij,maj->mai", F @ np.linalg.inv(Fc), fe)
    for name, Fp in (
        ("F", _f32(F)),
        ("positions", deformation_gradient(_f32(positions)[cells], split.D)),
    ):
        fe = _element_forces(model, points, cells, Fp)
        if fe is not None:
            out[name] = fe
    S = _second_piola(split, base)
    out["S"] = _stress_forces(split, _f32(S))
    P = split.F @ S
    out["P"] = piola_element_forces(split.V0, split.D, _f32(P))
    J = np.linalg.det(F)[:, None, None]
    Ft = np.swapaxes(F, 1, 2)
    sigma = P @ Ft / J  # sigma = P F^T / J, and back P = J sigma F^-T
    out["sigma"] = piola_element_forces(split.V0, split.D, J * _f32(sigma) @ np.linalg.inv(Ft))
    changes = {k: assemble(cells, n, fe, None)[0] - f0 for k, fe in out.items()}
    return {**changes, **_gradient_patterns(split, model)}


def _gradient_patterns(split: ElementSplit, model: Any) -> Dict[str, np.ndarray]:
    """The force change (n, 3) of each piece Psi_a dI_a/dF of P (invariants I_C, II_C, J) with
    its gradient dI_a/dF computed from F rounded to float32 and Psi_a in double; {} where the
    model declares no scalar energy of the invariants. Psi_J, at fixed I_C and II_C, is the
    same in the set I1, I2, J.
    """
    from conformance.diagnosis.invariant_gradients import gradient_tensors, invariant_slopes

    which = "I_C, II_C, J"
    slopes = invariant_slopes(model, split.F, which)
    if slopes is None:
        return {}
    rounded = gradient_tensors(_f32(split.F), which)
    exact = gradient_tensors(split.F, which)
    out = {}
    for a, name in enumerate(_PIECES):
        if not np.any(slopes[a]):
            continue
        dP = slopes[a][:, None, None] * (rounded[a] - exact[a])
        fe = piola_element_forces(split.V0, split.D, dP)
        out[name] = assemble(split.cells, split.n, fe, None)[0]
    return out


def _second_piola(split: ElementSplit, fe: np.ndarray) -> np.ndarray:
    """Per cell S (m, 3, 3) read back from element forces fe (m, 4, 3), f_a = -V0 F S D_a."""
    P = -np.einsum("mak,mja->mkj", fe, np.linalg.pinv(split.D)) / split.V0[:, None, None]
    return np.linalg.solve(split.F, P)


def _stress_forces(split: ElementSplit, S: np.ndarray) -> np.ndarray:
    """Element forces (m, 4, 3) of the second Piola stresses S (m, 3, 3) at the split's F."""
    return piola_element_forces(split.V0, split.D, split.F @ S)


#: Random per-cell patterns drawn to measure the correlation that chance gives.
SURROGATES = 16


def chance_correlation(split: ElementSplit, error: np.ndarray) -> float:
    """RMS correlation of ``error`` (n, 3) with noise that is not rounding: S of every cell
    given independent random relative errors (fixed seed, :data:`SURROGATES` draws). Where the
    force maps many cells onto few patterns (a small or uniform mesh), chance is large.
    """
    S = _second_piola(split, split.fe)
    rng = np.random.default_rng(0)
    r = []
    for _ in range(SURROGATES):
        dS = S * rng.standard_normal(S.shape)
        d = assemble(split.cells, split.n, _stress_forces(split, dS + np.swapaxes(dS, 1, 2)), None)
        r.append(_correlation(np.ravel(error), np.ravel(d[0])))
    return float(np.sqrt(np.mean(np.square(r))))


def mixed_precision_finding(
    split: ElementSplit,
    model: Any,
    points: np.ndarray,
    positions: np.ndarray,
    error: np.ndarray,
    probe_errors: Optional[List[np.ndarray]],
) -> Optional[Finding]:
    """The finding naming float32 inside a double-precision engine, or None without the
    evidence. error: engine minus oracle force (n, 3); probe_errors: the same at each probe
    (None: the kit has none).
    """
    patterns = rounding_patterns(split, model, points, positions)
    if not patterns:
        return None
    r = {k: _correlation(np.ravel(error), np.ravel(d)) for k, d in patterns.items()}
    best = max(r, key=lambda k: r[k])
    size = np.linalg.norm(error) / max(np.linalg.norm(patterns[best]), 1e-300)
    if not (1.0 / SIZE_FACTOR <= size <= SIZE_FACTOR):
        return None
    C32 = _f32(np.einsum("mki,mkj->mij", split.F, split.F)).reshape(-1, 9)
    distinct = np.unique(C32, axis=0).shape[0]  # cells alike round alike: fewer samples
    chance = chance_correlation(split, error)
    if r[best] < max(PATTERN_CORRELATION, SIGNIFICANT * chance):
        return None
    nz = noise(error, probe_errors) if probe_errors else None
    if nz is not None:
        if not nz.noisy:
            return None
        why = (
            "the error is drawn anew at every probe x + h d (correlation with the case's "
            f"{', '.join(f'{v:+.2f}' for v in nz.correlations)}; it changes by "
            f"{nz.changes.min():.2g} to {nz.changes.max():.2g} of itself, where a formula "
            "error, smooth in x, changes by about h)"
        )
    else:
        if r[best] < UNPROBED_CORRELATION or distinct < UNPROBED_CELLS:
            return None
        why = f"over {distinct} cells of distinct C"
    alike = sorted(
        (k for k in r if r[k] >= r[best] - 0.2 and r[k] >= PATTERN_CORRELATION),
        key=lambda k: -r[k],
    )
    what = _WHAT[alike[0]] + (
        " (or " + ", or ".join(_WHAT[k] for k in alike[1:]) + ")" if len(alike) > 1 else ""
    )
    return Finding(
        "single-precision-intermediate",
        "part of your double-precision engine computes in single precision (float32): its "
        f"error is that of {what}, the assembly in double",
        FULL,
        f"{why}; the force error correlates with the error that rounding makes, computed "
        f"exactly per cell (r = {r[best]:.2f}; by chance about {chance:.2f}), and is "
        f"{size:.2g} times its size (float32 arithmetic after the rounding adds errors of the "
        "same order); the balance laws hold, so the outputs were not stored in float32",
        {
            "correlations": {k: float(v) for k, v in r.items()},
            "best": best,
            "size_ratio": float(size),
            **(
                {}
                if nz is None
                else {
                    "probe_correlations": [float(v) for v in nz.correlations],
                    "probe_changes": [float(v) for v in nz.changes],
                }
            ),
        },
    )


#: A rest-data rounding is fixed, not drawn anew: it is named on a correlation this strong.
REST_CORRELATION = 0.9


def rest_rounding_patterns(
    split: ElementSplit, model: Any, points: np.ndarray, positions: np.ndarray
) -> Dict[str, np.ndarray]:
    """The force change (n, 3) of the shape-function gradients D_a (the inverse rest edge
    matrix) held in float32, computed in double through MJED's stress at F' = sum_a x_a D'_a:
    every D_a rounded ("D"), D_1..D_3 rounded and D_0 = -(D_1 + D_2 + D_3) from them
    ("D-sum"), or D_1..D_3 the inverse of the rest edge matrix computed in float32 (LAPACK's
    single-precision solve, as a float32 mesh buffer is inverted) and D_0 from them
    ("D-inverse"); a pattern MJED cannot evaluate is left out.
    """
    from conformance.diagnosis.routine_inputs import piola_at

    D, V0, cells, n = split.D, split.V0, split.cells, split.n
    x = positions[cells]
    rounded = _f32(D)
    summed = rounded.copy()
    summed[:, 0] = -rounded[:, 1:].sum(axis=1)
    X = points[cells]
    M = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)  # columns: the rest edges X_a - X_0
    inverse = np.empty_like(D)
    inverse[:, 1:] = np.linalg.inv(M.astype(np.float32)).astype(np.float64)
    inverse[:, 0] = -inverse[:, 1:].sum(axis=1)
    at = piola_at(model, points, split, split.F)
    if at is None:
        return {}
    f0 = assemble(cells, n, piola_element_forces(V0, D, at[0]), None)[0]
    out = {}
    for name, Dp in (("D", rounded), ("D-sum", summed), ("D-inverse", inverse)):
        at = piola_at(model, points, split, np.einsum("mak,mai->mki", x, Dp))
        if at is not None:
            out[name] = assemble(cells, n, piola_element_forces(V0, Dp, at[0]), None)[0] - f0
    return out


def rest_rounding_finding(
    split: ElementSplit,
    model: Any,
    points: np.ndarray,
    positions: np.ndarray,
    error: np.ndarray,
    probe_errors: Optional[List[np.ndarray]],
) -> Optional[Finding]:
    """The finding naming the rest gradients held in float32 (a mesh's single-precision
    buffers), or None without the evidence: the force error correlates with that rounding's
    own pattern (:func:`rest_rounding_patterns`) at :data:`REST_CORRELATION` or more, far above
    chance, of a size within :data:`SIZE_FACTOR` of it; and, unlike rounding in the material
    routine, it is not drawn anew at the probes (the rest data do not move).
    """
    patterns = rest_rounding_patterns(split, model, points, positions)
    if not patterns:
        return None
    r = {k: _correlation(np.ravel(error), np.ravel(d)) for k, d in patterns.items()}
    best = max(r, key=lambda k: r[k])
    size = np.linalg.norm(error) / max(np.linalg.norm(patterns[best]), 1e-300)
    chance = chance_correlation(split, error)
    if r[best] < max(REST_CORRELATION, SIGNIFICANT * chance):
        return None
    if not (1.0 / SIZE_FACTOR <= size <= SIZE_FACTOR):
        return None
    nz = noise(error, probe_errors) if probe_errors else None
    if nz is not None and nz.noisy:
        return None
    steady = (
        ""
        if nz is None
        else "; the error is the same at every probe x + h d to about h (fixed rest data, not "
        "rounding drawn anew in the material routine)"
    )
    how = {
        "D": "the shape-function gradients (the inverse rest edge matrix) rounded to float32",
        "D-sum": "the shape-function gradients (the inverse rest edge matrix) rounded to "
        "float32, node 0's summed from the others",
        "D-inverse": "the inverse rest edge matrix computed in float32 (the shape-function "
        "gradients from a single-precision inverse)",
    }[best]
    return Finding(
        "single-precision-rest-data",
        "the rest data of your double-precision engine held in single precision (float32): "
        f"its error is that of {how}, F and everything after in double",
        FULL,
        f"the force error correlates with the error those gradients make, computed "
        f"exactly per cell (r = {r[best]:.3f}; by chance about {chance:.2f}), and is "
        f"{size:.2g} times its size (an inverse computed in float32 rounds more than once)"
        f"{steady}; the balance laws hold, so the outputs were not stored in float32",
        {"correlations": {k: float(v) for k, v in r.items()}, "size_ratio": float(size)},
    )


#: What an engine may hold in float32 between its element routine and a double assembly.
_ELEMENT_BUFFERS = {
    (True, False): "the element force vectors",
    (False, True): "the element stiffness matrices",
    (True, True): "the element force vectors and stiffness matrices",
}


def rounded_elements_finding(split: ElementSplit, out, s, tol) -> Optional[Finding]:
    """Element vectors or matrices kept in a float32 buffer, then assembled in double: predicted
    exactly (the oracle's element matrices, from MJED's split, rounded to float32 and summed)
    and named when the engine matches that prediction within the double tolerance and the
    oracle itself does not; None otherwise. out: the engine's output; s: the case's scales;
    tol: its tolerances.
    """
    from conformance.diagnosis.elements import assemble
    from conformance.judge.compare import DOUBLE, errors

    f_o, K_o = assemble(split.cells, split.n, split.fe, split.Ke)
    f32, K32 = assemble(split.cells, split.n, _f32(split.fe), _f32(split.Ke))
    for (force, stiffness), what in _ELEMENT_BUFFERS.items():
        f_p = f32 if force else f_o
        K_p = K32 if stiffness else K_o
        e = errors(out.force, out.stiffness, None, f_p, K_p, 0.0, s)
        if not DOUBLE.within(e, energy=False):
            continue
        before = errors(out.force, out.stiffness, None, f_o, K_o, 0.0, s)
        return Finding(
            "single-precision-elements",
            f"{what} are kept in float32 (a single-precision buffer) and assembled in double",
            FULL,
            f"the oracle's element matrices (MJED's split of the cell) rounded to float32 and "
            f"summed give your output entry by entry: force error {e.force:.1e}, stiffness "
            f"error {e.stiffness:.1e} (against {before.force:.1e} and {before.stiffness:.1e} "
            "unrounded); the material routine itself is in double",
            {"force": force, "stiffness": stiffness},
        )
    return None


def _rounded_tangents(split: ElementSplit) -> Dict[str, np.ndarray]:
    """Form -> (m, 12, 12) the element matrices of the oracle's per-cell tangent rounded to
    float32 in that form (:data:`_TANGENTS`), the stress and the rest in double.
    """
    from conformance.diagnosis.elements import cell_piola
    from conformance.diagnosis.invariant_pieces import cell_tensors
    from conformance.diagnosis.spatial_tangent import spatial_cells
    from conformance.diagnosis.spatial_variants import jaumann_terms

    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    sc = spatial_cells(split, t.S, t.CC)
    J = np.linalg.det(split.F)[:, None, None, None, None]
    jau = jaumann_terms(sc.sigma)
    dc = {
        "Jc": _f32(J * sc.c) / J - sc.c,
        "c": _f32(sc.c) - sc.c,
        "ddsdde": _f32(sc.c + jau) - jau - sc.c,
        "CC": spatial_cells(split, t.S, _f32(t.CC)).c - sc.c,
    }
    out = {
        k: split.Ke
        + np.einsum("m,maj,mijkl,mbl->maibk", sc.v, sc.gN, d, sc.gN, optimize=True).reshape(
            -1, 12, 12
        )
        for k, d in dc.items()
    }
    dA = _f32(A) - A  # A[k, I, l, L] = dP_kI / dF_lL: K_e = V0 D_aI A D_bL
    Ke = np.einsum("m,maI,mkIlL,mbL->makbl", split.V0, split.D, dA, split.D, optimize=True)
    out["A"] = split.Ke + Ke.reshape(-1, 12, 12)
    return out


#: A stiffness error beyond this (relative) is not the rounding of a tangent to float32
#: (2^-24 = 6e-8 per entry; assembly's cancellations may magnify it, not a thousandfold).
ROUNDED_TANGENT = 1e3 * 2.0**-24

#: Form of the per-cell tangent an engine may compute or keep in float32 -> its words.
_TANGENTS = {
    "Jc": "the per-cell spatial (Kirchhoff) tangent J c",
    "c": "the per-cell spatial tangent c",
    "ddsdde": "the per-cell Jaumann-rate tangent (a UMAT's DDSDDE, c plus the Jaumann terms)",
    "CC": "the per-cell material tangent CC = dS/dE",
    "A": "the per-cell first elasticity tensor A = dP/dF",
}


def rounded_tangent_finding(split: ElementSplit, out, s) -> Optional[Finding]:
    """The stiffness alone in single precision: the oracle's per-cell tangent rounded to
    float32 in one of the forms of :data:`_TANGENTS` (the stress, the force and the assembly
    in double), predicted exactly, and named when the engine matches that prediction within
    the double tolerance and the oracle itself does not (several forms matching: the first,
    the others said); None otherwise. out: the engine's output; s: the case's scales.
    """
    from conformance.judge.compare import DOUBLE, errors

    before = errors(
        out.force, out.stiffness, None, *assemble(split.cells, split.n, split.fe, split.Ke), 0.0, s
    )
    if DOUBLE.within(before, energy=False) or before.force > DOUBLE.force:
        return None
    if before.stiffness > ROUNDED_TANGENT:  # beyond float32's rounding of any tangent
        return None
    with np.errstate(all="ignore"):
        forms = _rounded_tangents(split)
    hits = []
    for form, Ke in forms.items():
        K = assemble(split.cells, split.n, split.fe, Ke)[1]
        e = errors(out.force, out.stiffness, None, out.force, K, 0.0, s)
        if e.stiffness <= DOUBLE.stiffness:
            hits.append((form, e.stiffness))
    if not hits:
        return None
    form, left = hits[0]
    also = "; ".join(_TANGENTS[f] for f, _ in hits[1:])
    return Finding(
        "single-precision-tangent",
        "the stiffness computed in single precision (float32): "
        f"{_TANGENTS[form]} rounded to float32, the stress, force and assembly in double",
        FULL,
        "the oracle's per-cell tangent (read back from its element matrices) rounded to "
        f"float32 in that form and assembled gives your stiffness entry by entry: error "
        f"{left:.1e} (against {before.stiffness:.1e} unrounded, about float32's unit "
        "round-off times the tangent's entries, with no pattern a formula error has); the "
        "force is double-exact" + (f" (the same rounding of {also} matches too)" if also else ""),
        {"form": form, "residual": left, "forms": [f for f, _ in hits]},
    )


def rounded_elements_reading(diag, ci, out, ref, s):
    """``diag`` led by :func:`rounded_elements_finding` when it holds, else by
    :func:`rounded_tangent_finding` (the per-cell tangent rounded); unchanged otherwise (no
    MJED split of the case, or the engine matches neither). Cheap: a few assemblies of the
    rounded arrays; run whatever the force's error (a float32 stiffness buffer leaves the force
    exact).
    """
    from dataclasses import replace

    from conformance.diagnosis.elements import element_split

    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, diag.tolerances
    )
    found = None if split is None else rounded_elements_finding(split, out, s, diag.tolerances)
    if found is None and split is not None:
        found = rounded_tangent_finding(split, out, s)
    if found is None:
        return diag
    return replace(diag, findings=[found, *(f for f in diag.findings if f.code != "unexplained")])


def mixed_precision_reading(diag, cache, ci, out, ref, s, probes, probe_results):
    """``diag`` (a failed case within float32's tolerances whose error keeps the balance laws)
    with float32 inside the engine named first when the evidence holds; unchanged otherwise
    (no MJED split, or not noise with the rounding's pattern). probes: the case's probe
    KitCases; probe_results: (positions, force, energy) of the engine at each.
    """
    from conformance.diagnosis.elements import element_split

    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, diag.tolerances
    )
    if split is None:
        return diag
    probe_errors = None
    if probes and len(probe_results) == len(probes):
        try:
            oracle = cache.probes(ci, ref, [p.input for p in probes]).probe_forces
        except ValueError:  # the oracle cannot evaluate a probe: judged without probes
            oracle = None
        if oracle is not None:
            probe_errors = [np.asarray(f) - fo for (_, f, _), fo in zip(probe_results, oracle)]
    error = np.asarray(out.force, dtype=np.float64) - ref.force
    with np.errstate(all="ignore"):
        found = mixed_precision_finding(
            split, ci.model, ci.points, ci.positions, error, probe_errors
        ) or rest_rounding_finding(split, ci.model, ci.points, ci.positions, error, probe_errors)
        if found is None:
            # no tensor rounded: a scalar of one part of the energy, per cell
            noisy = noise(error, probe_errors).noisy if probe_errors else None
            parts = part_scalar_findings(
                split, ci.model, ci.points, ci.positions, out, ref.force, ref.stiffness, s,
                diag.tolerances, noisy,
            )  # fmt: skip
            return named_first(diag, parts)
    return named_first(diag, [found] if found is not None else [])
