"""A stiffness off by round-off alone, the force exact: float32 blocks, or differences whose
step is too small.

When an engine's force and energy are right to double precision and its stiffness is off by
1e-9 to 1e-5, with no formula matching, two mechanisms leave that trace, and they are told
apart by evidence of their own:

- **Part of K in float32.** A double computed value is a float32 number with odds of about
  2^-29, so a class of K's entries that are all float32 numbers was stored or accumulated in
  single precision: the node blocks off the diagonal (the edge blocks of an edge-based
  engine, often a float32 GPU buffer) or on it, or all of K. Named when the engine's entries of
  one class are float32 numbers (90 % or more) and the oracle's are not, and that class's error
  is of float32's size.
- **Round-off noise.** Otherwise the error is measured at the kit's probes (x + h d, h about
  1e-4 of the cells' size): an error from a formula is smooth in x and comes back nearly the
  same, round-off is drawn anew (correlation near 0, a change about its own size). Noise of
  that kind in a tangent that is not float32's storage is what a derivative taken by finite
  differences leaves when the step is so small that cancellation dominates: about u |S| / h
  for first differences of a stress, u |W| / h^2 for second differences of the energy. Unless
  it is far below float32's size (under u32 / 30), a tangent computed in float32 arithmetic
  leaves the same noise (above 30 u32 too: float32 inputs to an ill-conditioned computation
  are amplified), and both are said, as ambiguous. The steps the noise implies for
  either scheme are given, and whether K kept its symmetry (second differences of W are
  symmetric; first differences of a stress are not). On a state where every cell has two equal
  principal stretches, an eigen-solution that loses its digits there (a closed-form,
  trigonometric one) leaves the same noise, and is said beside them.

Nothing is compiled: the oracle at the probes is one assembly each.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import norm as sparse_norm

from conformance.diagnosis.elements import case_split, cell_piola
from conformance.diagnosis.energy_alone import cell_energies
from conformance.diagnosis.findings import FULL, PARTIAL, Finding, named_first
from conformance.diagnosis.mixed_precision import noise

__all__ = [
    "BlockPrecision",
    "block_precision",
    "single_precision_blocks_finding",
    "noise_finding",
    "repeated_stretches",
    "stiffness_noise_reading",
]

_U32 = 2.0**-24
_U64 = 2.0**-53

#: Share of a class's entries that must be float32 numbers (the engine's), and may be (the
#: oracle's), to name that class stored in float32.
STORED = 0.9
BY_CHANCE = 0.1

#: Relative size of the noise from which float32 arithmetic is said beside differences.
FLOAT32_LEAST = _U32 / 30

#: The stiffness errors read here: above double's round-off, below any formula slip's.
NOISE_RANGE = (1e-12, 1e-4)

_CLASSES = {
    "diagonal": "the diagonal node blocks (each node with itself: the vertex blocks)",
    "off-diagonal": "the off-diagonal node blocks (node pairs: the edge blocks)",
}


@dataclass(frozen=True)
class BlockPrecision:
    """Per class of K's entries ("diagonal", "off-diagonal" node blocks): the share of the
    engine's and of the oracle's nonzero entries that are float32 numbers, and the class's
    relative error (Frobenius, against the oracle's class).
    """

    engine: dict
    oracle: dict
    error: dict

    def stored(self) -> List[str]:
        """The classes stored in float32 (see :data:`STORED`)."""
        return [
            k
            for k in _CLASSES
            if self.engine[k] >= STORED
            and self.oracle[k] <= BY_CHANCE
            and self.error[k] <= 30 * _U32
        ]


def _is_f32(v: np.ndarray) -> np.ndarray:
    return v.astype(np.float32).astype(np.float64) == v


def block_precision(K: sp.spmatrix, K_o: sp.spmatrix) -> BlockPrecision:
    """Which node-block classes of K (3n, 3n) hold float32 numbers, against the oracle's K_o."""
    eng, ora, err = {}, {}, {}
    D = sp.coo_matrix(sp.csr_matrix(K) - sp.csr_matrix(K_o))
    for name, M, out in (("engine", K, eng), ("oracle", K_o, ora)):
        C = sp.coo_matrix(M)
        nz = C.data != 0
        same = (C.row // 3 == C.col // 3)[nz]
        f32 = _is_f32(np.asarray(C.data[nz], dtype=np.float64))
        out["diagonal"] = float(f32[same].mean()) if same.any() else 0.0
        out["off-diagonal"] = float(f32[~same].mean()) if (~same).any() else 0.0
    Co = sp.coo_matrix(K_o)
    for k, pick in (("diagonal", np.equal), ("off-diagonal", np.not_equal)):
        dm = pick(D.row // 3, D.col // 3)
        om = pick(Co.row // 3, Co.col // 3)
        ref = float(np.linalg.norm(Co.data[om]))
        err[k] = float(np.linalg.norm(D.data[dm])) / ref if ref > 0 else float("inf")
    return BlockPrecision(eng, ora, err)


def single_precision_blocks_finding(K: sp.spmatrix, K_o: sp.spmatrix) -> Optional[Finding]:
    """The node blocks of K held in float32, named from their values; None without that
    evidence.
    """
    bp = block_precision(K, K_o)
    stored = bp.stored()
    if not stored:
        return None
    what = "all of K's entries" if len(stored) == 2 else _CLASSES[stored[0]]
    rest = [k for k in _CLASSES if k not in stored]
    return Finding(
        "single-precision-blocks",
        f"{what} are single-precision (float32) numbers: "
        "stored or accumulated in a float32 buffer"
        + (f", {_CLASSES[rest[0]]} in double" if rest else ""),
        FULL,
        "; ".join(
            f"{_CLASSES[k]}: {100 * bp.engine[k]:.1f} % of your entries are float32 numbers "
            f"(the oracle's: {100 * bp.oracle[k]:.1f} %), their error {bp.error[k]:.1e} "
            f"({bp.error[k] / _U32:.2g} float32 unit round-offs)"
            for k in _CLASSES
        )
        + "; a value computed in double is a float32 number with odds of about 2^-29",
        {"engine": bp.engine, "oracle": bp.oracle, "error": bp.error},
    )


def _on_pattern(D: sp.spmatrix, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    return np.asarray(sp.csr_matrix(D)[rows, cols], dtype=np.float64).ravel()


def _implied_steps(
    P: np.ndarray, A: np.ndarray, W: np.ndarray, relative: float
) -> Tuple[float, float]:
    """(first, second): the step h for which first differences of the stress (noise about
    u |P| / h) and second differences of W (about u |W| / h^2) leave a tangent noise of
    ``relative`` x |A| (RMS over the cells).
    """
    nP = float(np.sqrt(np.mean(np.sum(P**2, axis=(1, 2)))))
    nA = float(np.sqrt(np.mean(np.sum(A**2, axis=(1, 2, 3, 4)))))
    nW = float(np.sqrt(np.mean(W**2)))
    first = _U64 * nP / (relative * nA) if nA > 0 else float("nan")
    second = float(np.sqrt(_U64 * nW / (relative * nA))) if nA > 0 else float("nan")
    return first, second


def noise_finding(
    K: sp.spmatrix,
    K_o: sp.spmatrix,
    probe_K: Sequence[sp.spmatrix],
    probe_K_o: Sequence[sp.spmatrix],
    steps: Optional[Tuple[float, float]] = None,
) -> Optional[Finding]:
    """The stiffness error named round-off noise when it is drawn anew at every probe (engine
    K and oracle K_o at the case, probe_K and probe_K_o at each probe); None when it is smooth
    or there are no probes. steps: the implied steps of :func:`_implied_steps`, when known.
    """
    if not probe_K or len(probe_K) != len(probe_K_o):
        return None
    Co = sp.coo_matrix(K_o)
    rows, cols = Co.row, Co.col
    e0 = _on_pattern(sp.csr_matrix(K) - sp.csr_matrix(K_o), rows, cols)
    ep = [
        _on_pattern(sp.csr_matrix(k) - sp.csr_matrix(ko), rows, cols)
        for k, ko in zip(probe_K, probe_K_o)
    ]
    nz = noise(e0, ep)
    if not nz.noisy:
        return None
    D = sp.csr_matrix(K) - sp.csr_matrix(K_o)
    rel = float(sparse_norm(D)) / max(float(sparse_norm(K_o)), 1e-300)
    asym = float(sparse_norm(D - D.T)) / max(float(sparse_norm(D)), 1e-300)
    float32_possible = rel >= FLOAT32_LEAST
    symmetric = asym < 1e-3
    scheme = (
        "second differences of the energy (which keep K symmetric, as yours is)"
        if symmetric
        else "first differences of a stress or of the forces (which break K's symmetry, as "
        "yours is broken)"
    )
    title = (
        "the stiffness error is round-off noise, not a formula: a tangent by finite differences "
        "with a step so small that cancellation dominates"
        + (
            ", or a tangent computed in single precision (float32) arithmetic"
            if float32_possible
            else ""
        )
    )
    implied = ""
    if steps is not None and all(np.isfinite(steps)):
        implied = (
            f"; that size implies a step of about {steps[0]:.0e} for first differences of the "
            f"stress, {steps[1]:.0e} for second differences of W"
        )
    return Finding(
        "tangent-roundoff-noise",
        title,
        PARTIAL if float32_possible else FULL,
        "the stiffness error is drawn anew at every probe x + h d (correlation with the case's "
        f"{', '.join(f'{v:+.2f}' for v in nz.correlations)}; it changes by "
        f"{nz.changes.min():.2g} to {nz.changes.max():.2g} of itself, where a formula error, "
        f"smooth in x, changes by about h), the force and energy exact; its size {rel:.1e} of K"
        + (
            f" ({rel / _U32:.2g} float32 unit round-offs) could be float32's too (rounding, "
            "or float32 inputs amplified by the computation): the two causes leave the same "
            "noise (ambiguous)"
            if float32_possible
            else f" is far below float32's ({rel / _U32:.2g} float32 unit round-offs)"
        )
        + f"; its asymmetry {asym:.1e} of itself points to {scheme}{implied}",
        {
            "relative": rel,
            "asymmetry": asym,
            "probe_correlations": [float(v) for v in nz.correlations],
            "probe_changes": [float(v) for v in nz.changes],
            **({"implied_steps": list(steps)} if steps is not None else {}),
        },
    )


def stiffness_noise_reading(diag, cache, ci, out, ref, s, probes, probe_stiffness):
    """``diag`` (force right, the stiffness off by :data:`NOISE_RANGE`, nothing named: the
    run's condition for this reading) with float32 node blocks or round-off noise named first;
    unchanged otherwise. probes: the case's probe KitCases; probe_stiffness: the engine's K at
    each (empty when unusable).
    """
    K, K_o = sp.csr_matrix(out.stiffness), sp.csr_matrix(ref.stiffness)
    if out.energy is not None and diag.errors.energy > diag.tolerances.energy:
        return diag
    found = single_precision_blocks_finding(K, K_o)
    if found is None and probes and len(probe_stiffness) == len(probes):
        try:
            probe_K_o = [cache.reference(p.input).stiffness for p in probes]
        except ValueError:  # the oracle cannot evaluate a probe
            return diag
        found = noise_finding(K, K_o, probe_stiffness, probe_K_o, _steps(diag, ci, ref, s))
        if found is not None and repeated_stretches(ci.points, ci.cells, ci.positions):
            found = _with_repeated_stretches(found)
    return named_first(diag, [found]) if found is not None else diag


def repeated_stretches(points: np.ndarray, cells: np.ndarray, x: np.ndarray) -> bool:
    """True when every cell has two principal stretches equal (to 1e-8 of the largest
    eigenvalue of C): a uniaxial or equibiaxial stretch, the rest state.
    """
    from conformance.diagnosis.elements import cell_kinematics

    F = cell_kinematics(points, cells, x)[2]
    w = np.linalg.eigvalsh(F.swapaxes(1, 2) @ F)
    gaps = np.diff(w, axis=1).min(axis=1)
    return bool(np.all(gaps <= 1e-8 * w[:, -1]))


def _with_repeated_stretches(found: Finding) -> Finding:
    """The noise finding on a state with repeated principal stretches: an eigen-solution that
    loses its digits where two eigenvalues coincide leaves the same noise, only at such states
    (the probes part them), so it is said beside differences, as ambiguous.
    """
    from dataclasses import replace

    return replace(
        found,
        title=found.title.replace(
            "not a formula: a tangent by finite differences",
            "not a formula: principal stretches computed inaccurately where two coincide (a "
            "closed-form, trigonometric eigenvalue solution loses digits there; this state has "
            "a repeated eigenvalue of C), or a tangent by finite differences",
        ),
        strength=PARTIAL,
        evidence=found.evidence
        + "; every cell here has two equal principal stretches, where an eigen-solution is "
        "ill-conditioned: the two causes leave the same noise (ambiguous)",
    )


def _steps(diag, ci, ref, s) -> Optional[Tuple[float, float]]:
    """The steps the noise's size implies (:func:`_implied_steps`), from MJED's split."""
    split = case_split(diag, ci, ref, s)
    if split is None:
        return None
    P, A = cell_piola(split)
    energies = cell_energies(ci.model, ci.points, ci.cells, [ci.positions])
    if energies is None:
        return None
    return _implied_steps(P, A, energies[0] / split.V0, diag.errors.stiffness)
