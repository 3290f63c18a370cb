"""Which energy does the engine compute? The hypotheses tested by evaluating the oracle on other
energies, once no correction of the output explains a failure:

1. the energy's terms with other coefficients (:mod:`conformance.diagnosis.term_fit`);
2. a rewritten formula (:mod:`conformance.diagnosis.variants`);
3. a kinematic mistake (:mod:`conformance.diagnosis.kinematics`);
4. two parameters exchanged, or one with another value (:mod:`conformance.diagnosis.parameters`);
5. an exponent of J with another value (:mod:`conformance.diagnosis.constants`).

Every hypothesis is tried (none stops the others), and a cause is named only when it brings the
engine's force and stiffness within the case's tolerance. Readings that predict the same force
and stiffness are one cause said in several ways; readings that explain equally but predict
differently are all shown, as ambiguous: this case cannot tell them apart.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from typing import Any, Callable, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import FULL, OBSERVED, PARTIAL, Finding, ambiguous
from conformance.diagnosis.fractions import simple_fraction
from conformance.diagnosis.parameters import scalar_parameters
from conformance.judge.compare import Scales, Tolerances, errors, grown
from conformance.judge.consistency import safe_norm

__all__ = [
    "Reading",
    "read",
    "refine_volumetric",
    "stress_only",
    "term_case",
    "merge_readings",
    "kit_term_reading",
    "model_key",
]

#: Two predictions closer than this (relative, force and stiffness) are the same reading.
_SAME = 1e-9


@dataclass(frozen=True)
class Reading:
    """A finding with the force (n, 3) and stiffness the hypothesis predicts (None: none)."""

    finding: Finding
    force: Optional[np.ndarray] = None
    stiffness: Optional[sp.csr_matrix] = None


def model_key(model: Any) -> str:
    """The model as its manifest says it (JSON, sorted): one key for one material and values."""
    from conformance.kit.spec import model_to_manifest

    return json.dumps(model_to_manifest(model), sort_keys=True)


def _evaluate(cache, ci, spec):
    """The oracle's Reference for ``ci.model`` evaluated as ``spec`` says."""
    from conformance.diagnosis.transformed import TransformedEnergy

    return cache.evaluate_model(
        ci, TransformedEnergy(ci.model, spec), model_key(ci.model) + spec.key()
    )


def _target(out, s: Scales, tol: Tolerances):
    """The engine's output, the case's scales and tolerances, as a refit aims at them."""
    from conformance.diagnosis.refit import Target

    return Target(
        np.asarray(out.force),
        sp.csr_matrix(out.stiffness),
        s.force,
        s.stiffness,
        tol.force,
        tol.stiffness,
    )


def term_case(cache, ci, out, ref, s: Scales, tol: Tolerances):
    """(labels, TermCase) of one case, or None when the energy has no formula or its terms do not
    add up to the oracle's energy (then nothing is claimed from them).
    """
    from conformance.diagnosis.energy_terms import Spec, has_formula, term_names
    from conformance.diagnosis.term_fit import TermCase, term_labels

    if not has_formula(ci.model):
        return None
    try:
        labels = term_labels(ci.model)
    except Exception:  # noqa: BLE001 - a formula the split cannot read: no term fit
        return None
    if len(labels) < 1:
        return None
    refs = [_evaluate(cache, ci, Spec(term=t)) for t in range(len(labels))]
    fs = sum(r.force for r in refs)
    Ks = sp.csr_matrix(sum(r.stiffness for r in refs))
    e = errors(fs, Ks, None, ref.force, ref.stiffness, 0.0, s)
    if max(e.force, e.stiffness) > 1e-11:
        return None
    try:
        names = tuple(term_names(ci.model))
    except Exception:  # noqa: BLE001 - no written formula to match: the terms by parameters
        names = ()
    if len(names) != len(labels):
        names = ()
    from conformance.diagnosis.elements import cell_kinematics

    t = _target(out, s, tol)
    J = np.linalg.det(cell_kinematics(ci.points, ci.cells, ci.positions)[2])
    one_j = bool(np.ptp(J) <= 1e-6 * float(np.mean(np.abs(J))))
    return labels, TermCase(
        [r.force for r in refs],
        [r.stiffness for r in refs],
        t.f,
        t.K,
        t.s_force,
        t.s_stiffness,
        t.tol_force,
        t.tol_stiffness,
        names,
        one_j=one_j,
        j_value=float(np.mean(J)) if one_j else None,
    )


def term_reading(
    labels, cases, params, worst: float, scope: str = "this case"
) -> Optional[Reading]:
    """The term fit over ``cases`` (TermCase) as a reading, or None when it explains nothing."""
    from conformance.diagnosis.term_fit import describe_fit, fit_terms

    fit = fit_terms(cases)
    if fit is None:
        return None
    names = cases[0].names
    figs = {
        "coefficients": [float(a) for a in fit.coefficients],
        "terms": [list(p) for p in labels],
        "term_names": list(names),
        "residual": fit.residual,
        "identified": fit.identified,
        "coupled": [int(i) for i in fit.coupled],
        "cases": len(cases),
    }
    if len(cases) == 1 and cases[0].j_value is not None:
        figs["one_j"] = cases[0].j_value
    combo = " + ".join(
        f"{a:.9g} x [{' '.join(p) or 'term'}]" for a, p in zip(fit.coefficients, labels)
    )
    if fit.agrees and not fit.identified:
        coupled = ", ".join(
            (names[i] if i < len(names) and names[i] else " ".join(labels[i]) or "a term")
            for i in fit.coupled
        )
        return Reading(
            Finding(
                "term-coefficients-ambiguous",
                "ambiguous: a combination of the energy's terms explains the error, but the terms "
                f"{coupled} have the same force and stiffness on {scope}",
                OBSERVED,
                f"f, K = {combo} leaves force and stiffness errors of {fit.residual:.1e}; which of "
                "those terms is off cannot be told here (check a state that separates them, e.g. "
                "a random one)",
                figs,
            )
        )
    if not fit.agrees:
        if fit.residual < 0.1 * worst and fit.identified:
            differs, readings = describe_fit(fit, labels, params, names=names)
            return Reading(
                Finding(
                    "term-coefficients",
                    f"mostly the energy's terms with other coefficients: {differs}",
                    PARTIAL,
                    f"f, K = {combo} leaves {fit.residual:.1e} (above the tolerance)",
                    figs,
                )
            )
        return None
    differs, readings = describe_fit(fit, labels, params, names=names)
    if not readings:
        return None
    a = fit.coefficients
    volumetric = [
        names[i]
        for i in range(len(a))
        if i < len(names) and names[i] and "volumetric term" in names[i] and abs(a[i] - 1.0) > 1e-6
    ]
    if len(volumetric) > 1 and all(c.one_j for c in cases):
        # Two J-only terms scaled apart span any (U', U'') at one J: a sign lost in U'(J), a
        # wrong U''(J), fit as two factors with no meaning (seen: - mu ln J x -0.475 and
        # lam/2 (ln J)^2 x 1.22 for a sign slipped in d(mu ln J)/dJ).
        return Reading(
            Finding(
                "term-coefficients-ambiguous",
                "ambiguous: the volumetric terms "
                + " and ".join(volumetric)
                + " with other factors explain the error, but J is the same in every cell here, "
                "where any change of U'(J) and U''(J) is such a combination",
                OBSERVED,
                f"f, K = {combo} leaves force and stiffness errors of {fit.residual:.1e}; a state "
                "where J varies from cell to cell tells a wrong term factor from a wrong "
                "derivative of U(J)",
                figs,
            )
        )
    c0 = cases[0]
    f = sum(ai * fi for ai, fi in zip(a, c0.forces))
    K = sp.csr_matrix(sum(ai * sp.csr_matrix(Ki) for ai, Ki in zip(a, c0.stiffnesses)))
    return Reading(
        Finding(
            "term-coefficients",
            "; ".join(readings),
            FULL,
            f"the engine's force and stiffness are the oracle's per-term ones combined as {combo} "
            f"(least squares over {scope}): after the fit force and stiffness errors "
            f"{fit.residual:.1e}; terms not at 1: {differs}",
            figs,
        ),
        f,
        K,
    )


def _force_may_match(out, f_c: np.ndarray, s: Scales, tol: Tolerances) -> bool:
    """False only where a candidate with force ``f_c`` cannot pass :func:`_matching`'s test
    whatever its stiffness K_c: that test scales the force by max(s.force k, |f_c|) with
    k = max(1, |K_c| / s.stiffness), and a matching K_c is within tol.stiffness of the engine's
    K, so |K_c| <= |K| / (1 - tol.stiffness): k is bounded by the engine's own stiffness.
    NaN or infinite figures bound nothing (True).
    """
    if not (0.0 < s.stiffness and tol.stiffness < 1.0):
        return True
    k_max = max(1.0, safe_norm(out.stiffness) / ((1.0 - tol.stiffness) * s.stiffness))
    bound = tol.force * max(s.force * k_max, safe_norm(f_c)) * (1.0 + 1e-9)
    miss = safe_norm(np.asarray(out.force) - f_c)
    return not (np.isfinite(k_max) and np.isfinite(bound) and miss > bound)


def _matching(out, s: Scales, tol: Tolerances, candidates) -> List[Reading]:
    """The candidates the engine matches: each is (evaluate () -> Reference, code, title, words,
    figures); a candidate the oracle cannot evaluate at this state (ValueError) is skipped.
    """
    found = []
    for evaluate, code, title, words, figures in candidates:
        try:
            r = evaluate()
            if not _force_may_match(out, r.force, s, tol):
                continue  # its stiffness (compiled on first reading) is never needed
            e = errors(
                out.force,
                out.stiffness,
                None,
                r.force,
                r.stiffness,
                0.0,
                grown(s, r.force, r.stiffness),
            )
        except ValueError:  # not finite at this state, or not a formula the oracle takes
            continue
        if tol.within(e, energy=False):
            evidence = (
                f"{words}against that energy, differentiated by the oracle: force error "
                f"{e.force:.1e}, stiffness error {e.stiffness:.1e}"
            )
            figs = {**figures, "residual": max(e.force, e.stiffness)}
            found.append(Reading(Finding(code, title, FULL, evidence, figs), r.force, r.stiffness))
    return found


def _signed(r, sign: float):
    """The reference ``r`` with its force times ``sign`` (energy and stiffness as they are,
    still read lazily).
    """
    from conformance.judge.oracle import Reference

    if sign == 1.0:
        return r
    return Reference(lambda: r.energy, sign * r.force, lambda: r.stiffness)


def _kinematic_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """The kinematic variants of :mod:`conformance.diagnosis.kinematics` that the engine matches
    (the variant's force times its force_sign).
    """
    from conformance.diagnosis.kinematics import kinematic_variants

    return _matching(
        out,
        s,
        tol,
        (
            (
                lambda v=v: _signed(
                    cache.evaluate_model(
                        ci, v.oracle_model(ci.model), model_key(ci.model) + v.key(), lazy=True
                    ),
                    v.force_sign,
                ),
                f"kinematic-{v.code}",
                f"your engine matches the energy with {v.title}",
                "",
                {"variant": v.code},
            )
            for v in kinematic_variants(ci.model)
        ),
    )


def _formula_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """The rewritten formulas of :mod:`conformance.diagnosis.variants` that the engine matches."""
    from conformance.diagnosis.variants import variants

    return _matching(
        out,
        s,
        tol,
        (
            (
                lambda v=v: cache.reference(replace(ci, model=v.model), lazy=True),
                "energy-variant",
                f"your engine matches W' = {v.expression}",
                f"{v.rewrite.words}: ",
                {"variant": v.rewrite.code, "expression": v.expression},
            )
            for v in variants(ci.model)
        ),
    )


def _single_j(ci) -> float:
    """The J of every cell of the case when the state has one (else NaN)."""
    from conformance.diagnosis.elements import cell_kinematics

    J = np.linalg.det(cell_kinematics(ci.points, ci.cells, ci.positions)[2])
    return float(J[0]) if J.size and np.ptp(J) <= 1e-9 * np.abs(J).max() else float("nan")


def _single_j_factor(J: float, ratio: float) -> str:
    """Words for a parameter's factor that is the state's one J (:func:`_single_j`; or 1/J):
    the same change as that parameter's terms integrated over the deformed volume (or divided
    by J); "" if not.
    """
    if not np.isfinite(J) or abs(J - 1.0) < 1e-3 or not np.isfinite(ratio):
        return ""
    if abs(ratio - J) <= 1e-6 * J:
        return "times J (integrated over the deformed volume J V)"
    if abs(ratio - 1.0 / J) <= 1e-6 / J:
        return "divided by J"
    return ""


def _parameter_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """Parameters exchanged, or one with another value (:mod:`conformance.diagnosis.parameters`),
    that the engine matches.
    """
    from conformance.diagnosis.parameters import (
        convention_words,
        elastic_convention_words,
        exchanges,
        with_value,
    )
    from conformance.diagnosis.refit import refit

    found = _matching(
        out,
        s,
        tol,
        (
            (
                lambda x=x: cache.reference(replace(ci, model=x.model)),
                "parameters-exchanged",
                x.title(),
                x.words(),
                {"parameters": [x.p, x.q]},
            )
            for x in exchanges(ci.model)
        ),
    )
    values = scalar_parameters(ci.model)
    found += _float32_parameter_readings(cache, ci, out, s, tol, values)
    one_j = _single_j(ci)
    for name, v0 in values.items():

        def evaluate(v, name=name):
            r = cache.evaluate_once(ci, with_value(ci.model, **{name: float(v[0])}))
            return r.force, r.stiffness

        # From the declared value, then from a unit conversion away (a parameter in kPa for
        # Pa, or a dimensionless one converted with the moduli), which a local fit of a
        # parameter inside an exponential does not reach from v0.
        for start in (v0, v0 * 1e-3, v0 * 1e3):
            fit = refit(evaluate, [start], _target(out, s, tol))
            if fit is not None and fit.agrees:
                break
        if fit is None or not fit.agrees:
            continue
        v = fit.values[0]
        if abs(v - v0) <= 1e-9 * max(abs(v0), 1e-300):
            continue
        same = [q for q, vq in values.items() if q != name and abs(v - vq) <= 1e-6 * abs(vq)]
        also = f" (the value of {same[0]}: {same[0]} used for {name})" if same else ""
        also = also or convention_words(ci.model, name, v, v0)
        elastic = bool(elastic_convention_words(ci.model, name, v, v0))
        volume = _single_j_factor(one_j, v / v0 if v0 else float("nan"))
        if volume and not also:
            also = (
                f" or, equally on this state, {name}'s terms {volume}: the state has one "
                f"J = {one_j:.6g}, which cannot tell a value from a volume"
            )
        also = also or _ratio_words(name, v / v0 if v0 else float("nan"))
        found.append(
            Reading(
                Finding(
                    "parameter-value",
                    f"parameter {name} = {v:.9g} in your engine where the case has {v0:g}{also}",
                    FULL,
                    f"the oracle with {name} = {v:.9g} (fitted; relative change "
                    f"{v / v0 - 1 if v0 else v:+.3e}): force error {fit.force:.1e}, stiffness "
                    f"error {fit.stiffness:.1e}",
                    {
                        "parameter": name,
                        "value": v,
                        "declared": v0,
                        "residual": fit.residual,
                        "elastic_convention": elastic,
                    },
                ),
                *fit.prediction,
            )
        )
    return (
        found
        or _permutation_readings(cache, ci, out, s, tol)
        or _reordered_readings(cache, ci, out, s, tol)
    )


#: The most parameters refitted together, and how closely the case must pin each (relative):
#: the refit's residual over its sensitivity (the least change of the relative errors per unit
#: relative change of any combination of the parameters) bounds how far they could move.
JOINT_MOST = 10
JOINT_PINNED = 1e-7


def _joint_parameter_readings(
    cache, ci, out, s: Scales, tol: Tolerances, consistent: List[str]
) -> List[Reading]:
    """Two or more parameters with other values at once (a law with fewer parameters reading
    the case's: a transversely isotropic law taking Costa's b_sn as b_ss and b_fn as b_fs; two
    moduli in other units): every scalar parameter refitted together from the declared values
    (Gauss-Newton through the oracle). Named when the oracle at the fitted values matches the
    engine, the case pins every parameter (:data:`JOINT_PINNED`) and at least two
    changed; each changed value said with the parameter whose value it is, if any. Not on a
    state whose cells are alike, where a few parameters moved together fit many single slips:
    there a fit adds its code to ``consistent`` (the causes this case cannot tell apart).
    """
    from conformance.diagnosis.parameters import with_value
    from conformance.diagnosis.refit import refit

    values = scalar_parameters(ci.model)
    names = list(values)
    if not 2 <= len(names) <= JOINT_MOST:
        return []
    # cells in one state: several parameters moved together can mimic a single slip of the
    # tangent there (a second derivative by differences: W1 kept, W11 moved), so a fit is only
    # consistent with the cause a case whose cells differ names (corroborate.fits_codes)
    from conformance.diagnosis.elements import alike_cells, cell_kinematics

    alike = alike_cells(cell_kinematics(ci.points, ci.cells, ci.positions)[2])

    def evaluate(v):
        r = cache.evaluate_once(ci, with_value(ci.model, **dict(zip(names, map(float, v)))))
        return r.force, r.stiffness

    fit = refit(evaluate, [values[n] for n in names], _target(out, s, tol), steps=12)
    if fit is None or not fit.agrees:
        return []
    if alike:
        consistent.append("parameter-values")
        return []
    pinned = max(fit.residual, 1e-15) / fit.sensitivity if fit.sensitivity > 0 else np.inf
    if not pinned <= JOINT_PINNED:  # NaN (no step taken) too
        return []
    changed = [
        (n, v, values[n])
        for n, v in zip(names, fit.values)
        if abs(v - values[n]) > 1e-6 * max(abs(values[n]), 1e-300)
    ]
    if len(changed) < 2:
        return []
    said = []
    for n, v, v0 in changed:
        same = [q for q, vq in values.items() if q != n and abs(v - vq) <= 1e-6 * abs(vq)]
        how = f"the value of {same[0]}: {same[0]} used for {n}" if same else ""
        how = how or _ratio_words(n, v / v0 if v0 else float("nan")).strip(" ()")
        said.append(f"{n} = {v:.9g} where the case has {v0:g}" + (f" ({how})" if how else ""))
    return [
        Reading(
            Finding(
                "parameter-values",
                f"{len(changed)} parameters with other values in your engine: " + "; ".join(said),
                FULL,
                f"the oracle with the parameters refitted together ({fit.steps} Gauss-Newton "
                f"steps; the case pins each to {pinned:.0e} of its value): force error "
                f"{fit.force:.1e}, stiffness error {fit.stiffness:.1e}; no parameter refitted "
                "alone explains it",
                {
                    "parameters": [n for n, _, _ in changed],
                    "values": [v for _, v, _ in changed],
                    "declared": [v0 for _, _, v0 in changed],
                    "residual": fit.residual,
                },
            ),
            *fit.prediction,
        )
    ]


def _float32_parameter_readings(
    cache, ci, out, s: Scales, tol: Tolerances, values: dict
) -> List[Reading]:
    """Every scalar parameter (``values``, by name) rounded to single precision (a parameter
    struct in float32, the rest of the engine in double): named when the oracle with those
    values, and not with the case's, matches the engine. Not tried when rounding changes no
    parameter.
    """
    from conformance.diagnosis.parameters import with_value

    rounded = {k: float(np.float32(v)) for k, v in values.items()}
    changed = {k: v for k, v in rounded.items() if v != values[k]}
    if not changed:
        return []
    said = ", ".join(f"{k} = {v:.9g} for {values[k]:.9g}" for k, v in changed.items())
    return _matching(
        out,
        s,
        tol,
        (
            (
                lambda: cache.evaluate_once(ci, with_value(ci.model, **rounded)),
                "parameters-float32",
                "your engine's material parameters are rounded to single precision (float32): "
                f"{said} (parameters held in float32, the rest computed in double)",
                "",
                {"parameters": sorted(changed)},
            ),
        ),
    )


def _reordered_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """The case's parameter list read by position in another order, units regardless
    (:func:`conformance.diagnosis.parameters.reorderings`), that the engine matches. Tried only
    when no exchange, single value or same-unit permutation explains the engine.
    """
    from conformance.diagnosis.parameters import reorderings

    return _matching(
        out,
        s,
        tol,
        (
            (
                lambda x=x: cache.evaluate_once(ci, x.model),
                "parameters-reordered",
                x.title(),
                x.words(),
                {"parameters": [x.names[i] for i in x.moved()], "order": list(x.order)},
            )
            for x in reorderings(ci.model)
        ),
    )


def _permutation_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """Three or more parameters of one unit given each other's values (a list read by position
    in another order): the group refitted jointly from its declared values (each evaluation
    reuses the compiled form), named when the engine matches and the values are the declared
    ones rearranged. Tried only when no single parameter explains the engine.
    """
    from conformance.diagnosis.parameters import permutation_words, unit_groups, with_value
    from conformance.diagnosis.refit import refit

    values = scalar_parameters(ci.model)
    found = []
    for names in unit_groups(ci.model):
        declared = [values[n] for n in names]

        def evaluate(v, names=names):
            model = with_value(ci.model, **{n: float(x) for n, x in zip(names, v)})
            r = cache.evaluate_once(ci, model)
            return r.force, r.stiffness

        try:
            fit = refit(evaluate, declared, _target(out, s, tol))
        except (ValueError, TypeError):  # a trial value the model refuses
            continue
        words = fit and fit.agrees and permutation_words(names, fit.values, declared)
        if not words:
            continue
        found.append(
            Reading(
                Finding(
                    "parameters-permuted",
                    words,
                    FULL,
                    "the oracle with "
                    + ", ".join(f"{n} = {v:.9g}" for n, v in zip(names, fit.values))
                    + f" (refitted together): force error {fit.force:.1e}, stiffness error "
                    + f"{fit.stiffness:.1e}",
                    {"parameters": list(names), "values": list(fit.values)},
                ),
                *fit.prediction,
            )
        )
    return found


def _shear_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """The shear coefficients of the strain form scaled by one factor
    (:mod:`conformance.diagnosis.shear_coefficients`), that the engine matches.
    """
    from conformance.diagnosis.shear_coefficients import shear_variants

    return _matching(
        out,
        s,
        tol,
        (
            (
                lambda v=v: cache.evaluate_once(ci, v),
                "shear-coefficients",
                words,
                f"the oracle with b_fs, b_fn, b_sn times {factor:g}: ",
                {"factor": factor},
            )
            for factor, v, words in shear_variants(ci.model)
        ),
    )


def _extra_term_readings(ci, out, ref, s: Scales, tol: Tolerances) -> List[Reading]:
    """One simple invariant term more or less than the oracle's energy
    (:mod:`conformance.diagnosis.extra_terms`), a simple multiple of a parameter.
    """
    from conformance.diagnosis.extra_terms import extra_terms
    from conformance.diagnosis.variants import energy_expression

    params = scalar_parameters(ci.model)
    if not params:
        return []
    expression = energy_expression(ci.model)
    found = extra_terms(
        ci.points,
        ci.cells,
        ci.positions,
        out.force,
        out.stiffness,
        np.asarray(ref.force),
        ref.stiffness,
        s,
        tol,
        params,
        expression[0] if expression else "",
    )
    return [
        Reading(
            Finding(
                "extra-term",
                title,
                FULL,
                f"the oracle's force and stiffness plus {figs['coefficient']:.9g} times those of "
                f"{figs['term']} (mjed's, one coefficient fitted) match the engine",
                figs,
            ),
            f_p,
            K_p,
        )
        for title, figs, f_p, K_p in found
    ]


def _constant_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """The exponents of J refitted (:mod:`conformance.diagnosis.constants`): a reading when the
    engine matches the formula with some of them changed.
    """
    from conformance.diagnosis.constants import (
        describe_exponent,
        fit_exponents,
        written_exponent,
    )
    from conformance.diagnosis.energy_terms import Spec, has_formula, j_exponents
    from conformance.diagnosis.transformed import TransformedEnergy

    if not has_formula(ci.model):
        return []
    try:
        exponents = j_exponents(ci.model)
    except Exception:  # noqa: BLE001 - a formula this module cannot read: nothing to fit
        return []

    def evaluate(factors):
        r = cache.evaluate_once(ci, TransformedEnergy(ci.model, Spec(j_exponents=factors)))
        return r.force, r.stiffness

    found = fit_exponents(exponents, evaluate, _target(out, s, tol))
    if found is None or not found.fit.agrees or not found.changed():
        return []
    changed = found.changed()
    factors = ", ".join(
        f"{r:.9g} on J^({written_exponent(k)})" for r, (k, _) in zip(found.fit.values, exponents)
    )
    return [
        Reading(
            Finding(
                "formula-constant",
                "a power of J differs from the formula's: "
                + "; ".join(describe_exponent(*c) for c in changed),
                FULL,
                f"the oracle with the exponents of J fitted (factors {factors}): force error "
                f"{found.fit.force:.1e}, stiffness error {found.fit.stiffness:.1e}",
                {
                    "exponents": [k for k, _ in found.exponents],
                    "declared": [p for _, p in found.exponents],
                    "engine": [r * p for r, (_, p) in zip(found.fit.values, found.exponents)],
                    "residual": found.fit.residual,
                },
            ),
            *found.fit.prediction,
        )
    ]


def _same(a: Reading, b: Reading, s: Scales) -> bool:
    if a.force is None or b.force is None:
        return False
    e = errors(a.force, a.stiffness, None, b.force, b.stiffness, 0.0, s)
    return max(e.force, e.stiffness) <= _SAME


def terms_scaled_unequally(finding: Finding) -> bool:
    """Whether a term-coefficients finding scales several terms by different factors (e.g. the
    terms of a series each by its own power of a ratio): then it describes the symptom term by
    term, and a parameter refit that agrees (:func:`_parameter_readings`) says the cause.
    """
    if finding.code != "term-coefficients":
        return False
    a = np.asarray(finding.figures.get("coefficients", []), dtype=float)
    off = a[np.abs(a - 1.0) > 1e-6]
    return off.size > 1 and float(np.ptp(off)) > 1e-6 * float(np.max(np.abs(off)))


#: The readings of the parameters themselves (a value, two exchanged, the list in another order):
#: where one agrees with a term fit that scales several terms unequally, it says the cause.
PARAMETER_CODES = (
    "parameter-value",
    "parameters-exchanged",
    "parameters-permuted",
    "parameters-reordered",
)


def _parameters_first(full: List[Reading]) -> List[Reading]:
    """``full`` with the parameter readings (:data:`PARAMETER_CODES`) ahead of a term reading
    that scales several terms unequally, or of any reading when a refit is an elastic-constant
    convention: the same prediction is then headed by the parameter's value (merge_readings
    keeps the first of equal readings as the head), not by one term "scaled".
    """
    # A parameter read in another elastic-constant convention says the cause (the term fit
    # says only "scaled by 0.93") and heads its equals too.
    if not any(
        terms_scaled_unequally(r.finding) or r.finding.figures.get("elastic_convention")
        for r in full
    ):
        return full
    first = [r for r in full if r.finding.code in PARAMETER_CODES]
    return first + [r for r in full if r.finding.code not in PARAMETER_CODES]


def merge_readings(full: List[Reading], s: Scales) -> List[Finding]:
    """The named causes: readings with the same prediction merged into one (the others said as
    'equivalently'); several distinct ones shown as ambiguous, each of them.
    """
    groups: List[List[Reading]] = []
    for r in full:
        for g in groups:
            if _same(g[0], r, s):
                g.append(r)
                break
        else:
            groups.append([r])
    causes = []
    for g in groups:
        head = g[0].finding
        if len(g) > 1:
            also = "; ".join(x.finding.title for x in g[1:])
            head = replace(
                head,
                evidence=head.evidence + f"; equivalently (the same force and stiffness): {also}",
            )
        causes.append(head)
    return ambiguous(
        causes,
        "they predict different values, but not differently enough for this case to tell them "
        "apart",
    )


def stress_only(causes: List[Finding], diag) -> List[Finding]:
    """``causes`` (readings of another energy: its terms, formula, parameters) said of the
    force and stiffness only where the engine's own energy denies an energy mistake: it is the
    oracle's within tolerance, or the probes found the force not its derivative. The readings
    compare force and stiffness alone; the energy says the formula's energy is right there.
    """
    e = diag.errors.energy
    energy_right = e is not None and e <= diag.tolerances.energy
    if energy_right:
        why = "your energy is the oracle's, so only its derivatives are computed so"
    elif any(f.code == "inconsistent-force" for f in diag.findings):
        why = "your force is not the derivative of your energy (the probes)"
    else:
        return causes
    out = []
    for c in causes:
        if c.strength != FULL:
            out.append(c)
        elif energy_right and c.code == "term-coefficients":
            said = _term_stresses(c)
            out.append(said if said is not None else _stress_only_title(c, why))
        else:
            out.append(_stress_only_title(c, why))
    return out


def _stress_only_title(c: Finding, why: str) -> Finding:
    return replace(c, title=f"{c.title} [in the stress and tangent only: {why}]")


def _term_stresses(c: Finding) -> Optional[Finding]:
    """A term fit said of the stress (the energy right): the terms whose force and stiffness
    are off, by their factors, as derivatives written wrongly. A parameter's value, its units
    or its order would change the energy too, which is right; so the parameter stories the fit
    also fits are kept in the evidence only, as what the force and stiffness alone allow.
    """
    from conformance.diagnosis.term_fit import factor_words

    g = c.figures or {}
    names, coefficients = g.get("term_names") or [], g.get("coefficients") or []
    if not names or len(names) != len(coefficients):
        return None
    off = []
    for name, a in zip(names, coefficients):
        if name and abs(a - 1.0) > 1e-6:
            words = factor_words(a, 1e-6)
            words = words.split(" (")[0] if words and not words.startswith("scaled") else None
            off.append(f"{name} {words or 'scaled'} (x {a:.6g})")
    if not off:
        return None
    title = (
        "the stress and tangent of "
        + "; of ".join(off)
        + ", your energy right: the derivative of that term is written wrongly (its "
        "parameter's value would change the energy too)"
    )
    return replace(
        c,
        title=title,
        evidence=f"{c.evidence}; in the force and stiffness alone the fit also reads: {c.title}",
    )


def read(
    diag,
    cache,
    ci,
    out,
    ref,
    s: Scales,
    keep_terms: Optional[Callable[[Any], None]] = None,
):
    """``diag`` (a failed case that nothing explained) with what the energy hypotheses find:
    named causes first (the 'unexplained' finding dropped), a partial reading otherwise.
    keep_terms((labels, TermCase, parameters)) receives the case's term system, for a fit over
    the kit (:func:`kit_term_reading`).
    """
    tol = diag.tolerances
    worst = max(diag.errors.force, diag.errors.stiffness)
    full: List[Reading] = []
    partial: List[Finding] = []
    observed: List[Finding] = []
    tc = term_case(cache, ci, out, ref, s, tol)
    if tc is not None:
        labels, case = tc
        if keep_terms is not None:
            keep_terms((*tc, scalar_parameters(ci.model)))
        r = term_reading(labels, [case], scalar_parameters(ci.model), worst)
        if r is not None:
            bucket = {FULL: full, PARTIAL: None, OBSERVED: None}[r.finding.strength]
            if bucket is not None:
                bucket.append(r)
            elif r.finding.strength == PARTIAL:
                partial.append(r.finding)
            else:
                observed.append(r.finding)
    # The rewritten formulas first: where a kinematic variant is the same energy, the formula
    # says it exactly (W' = ...) and the kinematic reading follows as "equivalently".
    full += _formula_readings(cache, ci, out, s, tol)
    full += _kinematic_readings(cache, ci, out, s, tol)
    full += _parameter_readings(cache, ci, out, s, tol)
    full += _constant_readings(cache, ci, out, s, tol)
    full += _shear_readings(cache, ci, out, s, tol)
    full += _extra_term_readings(ci, out, ref, s, tol)
    consistent: List[str] = []
    if not full:  # last, and only then: it asks the oracle most
        full += _joint_parameter_readings(cache, ci, out, s, tol, consistent)
    full, untold = _untold_parameters(full, observed)
    observed += untold
    causes = stress_only(merge_readings(_parameters_first(full), s), diag)
    if causes:
        rest = [f for f in diag.findings if f.code != "unexplained"]
        return replace(diag, findings=[*causes, *observed, *rest])
    tried = (
        "; nor the energy's terms refitted"
        + ("" if tc is not None else " (no formula to split)")
        + ", its kinematic variants, its rewritten formulas, its parameters exchanged or refitted "
        "one at a time, the exponents of J refitted (evaluated by the oracle)"
    )
    head = [
        replace(
            f,
            evidence=f.evidence + tried,
            figures=(
                {**f.figures, "fits_codes": [*f.figures.get("fits_codes", ()), *consistent]}
                if consistent
                else f.figures
            ),
        )
        for f in diag.findings
        if f.code == "unexplained"
    ]
    rest = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*head, *observed, *partial, *rest])


#: The title's prefix of a parameter value a case cannot tell apart (kept as an observation).
_UNTOLD = "(not told apart here) "


def _untold_parameters(
    full: List[Reading], observed: List[Finding]
) -> Tuple[List[Reading], List[Finding]]:
    """(full, demoted): a parameter's fitted value is no cause where the term fit found that
    parameter's term among terms this case cannot tell apart (one of them refitted alone fits
    as well as any other: c10 for c30 on a uniaxial stretch); such readings are kept as
    observations.
    """
    coupled_params = set()
    for f in observed:
        if f.code != "term-coefficients-ambiguous":
            continue
        labels = f.figures.get("terms", [])
        for i in f.figures.get("coupled", []):
            if i < len(labels):
                coupled_params.update(labels[i])
    if not coupled_params:
        return full, []
    kept, demoted = [], []
    for r in full:
        f = r.finding
        if f.code == "parameter-value" and f.figures.get("parameter") in coupled_params:
            demoted.append(
                replace(
                    f,
                    strength=OBSERVED,
                    title=_UNTOLD + f.title,
                    evidence=f.evidence
                    + "; but its term has the same force and stiffness here as others whose "
                    "parameters would fit as well (see the term fit)",
                )
            )
        else:
            kept.append(r)
    return kept, demoted


def refine_volumetric(diag, cache, ci, out, s: Scales):
    """``diag`` whose head cause is a J-only energy difference (the per-cell fit of
    :mod:`conformance.diagnosis.diagnose`, true but unspecific: it recognised no variant) made
    specific by the one rewritten formula of :mod:`conformance.diagnosis.variants` that the
    engine matches, or else the one parameter value (with its convention, e.g. a bulk modulus
    given as Abaqus' D1), said in its title and evidence; unchanged when none or several
    distinct ones match.
    """
    if not diag.causes or diag.causes[0].code != "volumetric":
        return diag
    v = diag.causes[0]
    if v.figures.get("variant"):
        return diag  # the per-cell fit already names the bulk term
    what = "formula"
    causes = merge_readings(_formula_readings(cache, ci, out, s, diag.tolerances), s)
    if len(causes) != 1:  # no rewritten formula: one parameter with another value (conventions)?
        what = "parameter"
        causes = merge_readings(_parameter_readings(cache, ci, out, s, diag.tolerances), s)
    if len(causes) != 1:
        return diag
    (w,) = causes
    said = "the rewritten formula" if what == "formula" else "the parameter"
    head = replace(
        v,
        title=f"{v.title}: {w.title}",
        evidence=f"{v.evidence}; {said}: {w.evidence}",
        figures={**v.figures, what: w.figures},
    )
    return replace(diag, findings=[head if f is v else f for f in diag.findings])


def kit_term_reading(diagnoses: list, entries: list) -> Optional[list]:
    """The term fit over several failed cases of one model (``entries``: (index, labels,
    TermCase, parameters) as :func:`read` kept them; ``diagnoses``: the cases' diagnoses, in
    that order). Only for cases that no cause explains on their own, or whose terms they could
    not tell apart; returns their new diagnoses (None when the fit over the kit does not agree
    or names nothing).
    """
    open_ = [
        j
        for j, d in enumerate(diagnoses)
        if not d.causes or any(f.code == "term-coefficients-ambiguous" for f in d.findings)
    ]
    if not open_ or len(entries) < 2:
        return None
    labels = entries[0][1]
    if any(e[1] != labels for e in entries):
        return None
    cases = [e[2] for e in entries]
    r = term_reading(labels, cases, entries[0][3], float("inf"), "the kit's failed cases")
    if r is None or r.finding.strength != FULL:
        return None
    out = []
    for j, d in enumerate(diagnoses):
        if j not in open_:
            out.append(d)
            continue
        rest = [
            f
            for f in d.findings
            if f.code not in ("unexplained", "term-coefficients-ambiguous", "systematic-small")
        ]
        named = [f for f in rest if f.code in PARAMETER_CODES and f.strength == FULL]
        if not named and terms_scaled_unequally(r.finding):
            # a value this case could not tell apart, named where another case does: the kit
            # tells it apart (its term fit agrees over every case)
            told = [_told_over_kit(f, diagnoses) for f in rest]
            named = [f for f in told if f is not None]
            rest = [f for f, t in zip(rest, told) if t is None]
        if named and terms_scaled_unequally(r.finding):  # the case's parameter value says it
            out.append(
                replace(d, findings=[*named, r.finding, *(f for f in rest if f not in named)])
            )
            continue
        out.append(replace(d, findings=[*stress_only([r.finding], d), *rest]))
    return out


def _told_over_kit(f: Finding, diagnoses: list) -> Optional[Finding]:
    """``f`` (a parameter value this case could not tell apart, :func:`_untold_parameters`) as a
    cause where another case of the kit names the same parameter with the same value (1e-9)
    in full; None otherwise.
    """
    if f.code != "parameter-value" or not f.title.startswith(_UNTOLD):
        return None
    name, value = f.figures.get("parameter"), f.figures.get("value")
    if name is None or value is None:
        return None
    for d in diagnoses:
        for c in d.causes:
            v = c.figures.get("value")
            if (
                c.code == "parameter-value"
                and c.strength == FULL
                and c.figures.get("parameter") == name
                and v is not None
                and abs(v - value) <= 1e-9 * max(abs(value), 1e-300)
            ):
                return replace(
                    f,
                    strength=FULL,
                    title=f.title.removeprefix(_UNTOLD),
                    evidence=f.evidence + "; told apart over the kit: another of its cases names "
                    "the same value, and the term fit over the kit's cases agrees",
                )
    return None


#: A refitted parameter's ratio to the case's value, as said when it is one of these.
_RATIOS = {0.5: "halved", 2.0: "doubled", -1.0: "with its sign flipped"}


def _ratio_words(name: str, r: float) -> str:
    """' (name halved: half the case's value)' for a simple ratio r of a refitted parameter to
    the case's (denominator at most 4, 1e-6); '' otherwise.
    """
    if not np.isfinite(r):
        return ""
    q = simple_fraction(r, 4, 1e-6)
    if q is None or q in (0, 1):
        return ""
    said = _RATIOS.get(float(q), f"times {q}")
    return f" ({name} {said}: {q} times the case's value)"
