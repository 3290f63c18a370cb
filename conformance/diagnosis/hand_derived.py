"""The reading of a hand-derived stress or tangent: per cell, the oracle's stress and tangent
(:mod:`conformance.diagnosis.elements`' split) with one piece written as such engines get it
wrong, each predicting the engine's force and stiffness with nothing fitted to the engine:

- a piece of the chain rule through the invariants
  (:mod:`conformance.diagnosis.invariant_pieces`), or of an SVD engine's chain through the
  singular values (:mod:`conformance.diagnosis.singular_value_pieces`);
- the Voigt stress vector's shear components doubled (:mod:`conformance.diagnosis.voigt_stress`);
- the spatial tangent without its 1/J (:mod:`conformance.diagnosis.spatial_tangent`);
- at the probes near a state where the force is right, the first Piola stress formed as S F
  (or F^T S, S F^T) for F S (:mod:`conformance.diagnosis.piola_assembly`), or an
  updated-Lagrangian engine's kinematic slips and its routine handed U, F^T or a corotated
  frame (:mod:`conformance.diagnosis.routine_inputs`), which rotation-free states hide;
- the spatial tangent in a wrong form (Voigt order, tensor shear rows in B, the Jaumann rate's
  terms) or one part of the element matrix in another local order
  (:mod:`conformance.diagnosis.spatial_variants`);
- a fibre strain form's dQ/dC and d2Q/dCdC rotated back from the frame wrongly (with the
  transpose, or not at all: :mod:`conformance.diagnosis.fibre_pieces`);
- when none of these: a UMAT driver's DDSDDE scaled and its Jaumann terms weighted, fitted over
  declared per-cell pieces and named in simple numbers, or one term of an isotropic tangent in
  J alone taken wrong (:mod:`conformance.diagnosis.spatial_pieces`).

A cause is named when its prediction matches the engine within the case's tolerance; several
that match with different predictions are shown as ambiguous.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import MAX_CELLS, cell_piola, element_split
from conformance.diagnosis.fibre_pieces import fibre_piece_findings
from conformance.diagnosis.findings import ambiguous
from conformance.diagnosis.invariant_pieces import (
    cell_tensors,
    law_fit,
    piece_findings,
)
from conformance.diagnosis.piola_assembly import piola_force_findings
from conformance.diagnosis.routine_inputs import probe_force_findings
from conformance.diagnosis.singular_value_pieces import singular_value_findings
from conformance.diagnosis.spatial_pieces import (
    deviatoric_piece_findings,
    isotropic_fit_findings,
    piece_fit_findings,
    unsymmetrised_product_findings,
)
from conformance.diagnosis.spatial_tangent import spatial_findings
from conformance.diagnosis.spatial_variants import spatial_variant_findings
from conformance.diagnosis.voigt_maps import voigt_map_findings
from conformance.diagnosis.voigt_stress import voigt_stress_findings
from conformance.judge.compare import Scales, errors

__all__ = ["hand_derived_reading"]

#: The nearby state's displacement from the case's, in mean edge lengths (random, fixed seed).
NEARBY = 0.03


def _nearby(cache, ci, s: Scales, tol):
    """The oracle's per-cell tensors at a state near the case's (positions moved randomly by
    :data:`NEARBY` edge lengths): C has distinct eigenvalues there, so every derivative of
    the law is determined; None when the split does not add up to the oracle there.
    """
    from common.tolerances import mean_edge_length

    h = mean_edge_length(ci.points, ci.cells)
    rng = np.random.default_rng(20261127)
    near = replace(
        ci, positions=ci.positions + NEARBY * h * rng.standard_normal(ci.positions.shape)
    )
    try:
        r = cache.reference(near)
    except ValueError:  # not finite there
        return None
    split = element_split(
        near.model, near.points, near.cells, near.positions, r.force, r.stiffness, s, tol
    )
    return None if split is None else cell_tensors(*cell_piola(split), split.F)


def _parameters(model) -> dict:
    """The law's scalar parameters, name -> value (none when it is not a dataclass)."""
    if not dataclasses.is_dataclass(model):
        return {}
    values = {f.name: getattr(model, f.name) for f in dataclasses.fields(model)}
    return {k: float(v) for k, v in values.items() if isinstance(v, (int, float))}


def hand_derived_reading(diag, cache, ci, out, ref, s: Scales):
    """``diag`` (a failed case nothing explained yet) with the mistaken pieces the engine
    matches named first (the 'unexplained' finding dropped); unchanged when none matches.
    cache: the oracles (:class:`conformance.judge.oracle.OracleCache`), for a nearby state.
    """
    if ci.cells.shape[0] > MAX_CELLS:
        return diag
    tol = diag.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, ref.force, ref.stiffness, s, tol
    )
    if split is None:
        return diag
    K_engine = sp.csr_matrix(out.stiffness)

    def matches(f: np.ndarray, K: sp.csr_matrix, allowance: float = 0.0) -> float:
        """The engine's larger error against the prediction (f, K), inf unless it is within the
        tolerance and the prediction is not the oracle's own (a piece this law lacks). A
        numerical prediction (differences) may leave a stiffness error up to ``allowance`` times
        the prediction's own distance from the oracle (its term's size; why:
        :data:`conformance.diagnosis.spatial_variants.NUMERICAL`).
        """
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(K.data))):
            return float("inf")
        d = errors(f, K, None, ref.force, ref.stiffness, 0.0, s)
        if tol.within(d, energy=False):
            return float("inf")
        e = errors(out.force, K_engine, None, f, K, 0.0, s)
        if tol.within(e, energy=False) or (
            e.force <= tol.force and e.stiffness <= allowance * d.stiffness
        ):
            return max(e.force, e.stiffness)
        return float("inf")

    with np.errstate(all="ignore"):
        t = cell_tensors(*cell_piola(split), split.F)
        fit = law_fit(t, _nearby(cache, ci, s, tol))
        found = [] if fit is None else piece_findings(split, t, matches, fit=fit)
        found += singular_value_findings(split, t, fit, matches)
        found += voigt_stress_findings(split, t.S, matches)
        found += spatial_findings(split, t.S, t.J, matches)
        found += spatial_variant_findings(split, t, matches, tol.stiffness)
        found += fibre_piece_findings(split, t, ci.model, matches)
        if not found:
            found = piece_fit_findings(split, t, K_engine, matches)
        if not found:
            found = deviatoric_piece_findings(split, t, K_engine, matches)
        if not found:
            found = unsymmetrised_product_findings(
                split, t, K_engine, matches, _parameters(ci.model)
            )
        if not found:
            found = isotropic_fit_findings(split, t, K_engine, matches, _parameters(ci.model))
    if not found:
        return diag
    found = ambiguous(found, "their predictions differ by less than the tolerance here")
    rest = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*found, *rest])


def nearby_force_reading(diag, cache, ci, probe_results, s: Scales):
    """``diag`` (force and stiffness right here, the force wrong at the kit's probes near this
    state: "force-wrong-nearby") with the force-changing pieces that the engine's force matches
    at every probe named first; unchanged when none does. probe_results: [(positions (n, 3),
    force (n, 3), energy)] the engine's outputs at the probes.
    """
    if not probe_results or not any(f.code == "force-wrong-nearby" for f in diag.findings):
        return diag
    if ci.cells.shape[0] > MAX_CELLS:
        return diag
    tol = diag.tolerances
    common = None
    for positions, force, _ in probe_results:
        near = replace(ci, positions=np.asarray(positions, dtype=np.float64))
        try:
            r = cache.reference(near)
        except ValueError:  # the oracle cannot evaluate the probe
            return diag
        split = element_split(
            near.model, near.points, near.cells, near.positions, r.force, r.stiffness, s, tol
        )
        if split is None:
            return diag

        def matches(f, K, r=r, force=force) -> float:
            """The engine's force error at the probe against f; inf unless within the
            tolerance and f is not the oracle's own force there.
            """
            if not np.all(np.isfinite(f)):
                return float("inf")
            if errors(f, r.stiffness, None, r.force, r.stiffness, 0.0, s).force <= tol.force:
                return float("inf")
            e = errors(np.asarray(force), r.stiffness, None, f, r.stiffness, 0.0, s).force
            return e if e <= tol.force else float("inf")

        with np.errstate(all="ignore"):
            t = cell_tensors(*cell_piola(split), split.F)
            # only the force is compared at a probe: a written factor (scaled=True) would be
            # named from the force alone, where it claims the geometric term too
            found = piece_findings(split, t, matches, _nearby(cache, near, s, tol), scaled=False)
            found += voigt_stress_findings(split, t.S, matches)
            found += piola_force_findings(split, t.S, matches)
            found += probe_force_findings(near.model, near.points, split, matches)
            if not found:
                found = voigt_map_findings(
                    split, force, r.stiffness, r.force, r.stiffness, s, tol, stiffness_known=False
                )
        codes = {f.code: f for f in found}
        common = codes if common is None else {c: codes[c] for c in common if c in codes}
        if not common:
            return diag
    named = [
        replace(
            f,
            evidence=f"at each of the kit's {len(probe_results)} probes near this state (where "
            "the force is wrong; here it is right): " + f.evidence,
        )
        for f in common.values()
    ]
    named = ambiguous(named, "their predictions differ by less than the tolerance at the probes")
    return replace(diag, findings=[*named, *diag.findings])


def tangent_term_reading(diag, ci, out, ref, s: Scales):
    """``diag`` (the force right, nothing named) with a hand-derived tangent term of a
    material's own form named first: Ogden's coaxial tangent
    (:mod:`conformance.diagnosis.spectral_tangent`, with the oracle's per-cell stress from the
    element split where it adds up) or its shear (a != b) terms with the wrong sign or divisor,
    or its -2 tau_a n_a^4 term taken wrong,
    Costa's d2Q not symmetrised
    (:mod:`conformance.diagnosis.fibre_tangent`); unchanged when neither fits.
    """
    from conformance.diagnosis.fibre_tangent import fibre_tangent_findings
    from conformance.diagnosis.spectral_tangent import (
        power_exponent,
        shear_term_findings,
        spectral_findings,
        stress_term_findings,
    )

    tol = diag.tolerances
    if diag.errors.force > tol.force:
        return diag
    args = (ci.model, ci.points, ci.cells, ci.positions, out.stiffness, ref.stiffness)
    S = split = None
    if power_exponent(ci.model) is not None and ci.cells.shape[0] <= MAX_CELLS:
        split = element_split(*args[:4], ref.force, ref.stiffness, s, tol)
        if split is not None:
            S = np.linalg.inv(split.F) @ cell_piola(split)[0]
    with np.errstate(all="ignore"):
        found = spectral_findings(*args, tol.stiffness, S) + fibre_tangent_findings(
            *args, tol.stiffness
        )
        if split is not None:
            found += shear_term_findings(ci.model, split, *args[4:], tol.stiffness)
            found += stress_term_findings(ci.model, split, *args[4:], tol.stiffness)
    if not found:
        return diag
    rest = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*ambiguous(found), *rest])
