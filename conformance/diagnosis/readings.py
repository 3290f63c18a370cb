"""Which energy does the engine compute? The hypotheses tested by evaluating the oracle on other
energies, once no correction of the output explains a failure:

1. the energy's terms with other coefficients (:mod:`conformance.diagnosis.term_fit`);
2. a rewritten formula (:mod:`conformance.diagnosis.variants`);
3. a kinematic mistake (:mod:`conformance.diagnosis.kinematics`).

Every hypothesis is tried (none stops the others), and a cause is named only when it brings the
engine's force and stiffness within the case's tolerance. Readings that predict the same force
and stiffness are one cause said in several ways; readings that explain equally but predict
differently are all shown, as ambiguous: this case cannot tell them apart.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from typing import Any, Callable, List, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import FULL, OBSERVED, PARTIAL, Finding
from conformance.judge.compare import Scales, Tolerances, errors

__all__ = ["Reading", "read", "term_case", "merge_readings", "kit_term_reading"]

#: Two predictions closer than this (relative, force and stiffness) are the same reading.
_SAME = 1e-9


@dataclass(frozen=True)
class Reading:
    """A finding with the force (n, 3) and stiffness the hypothesis predicts (None: none)."""

    finding: Finding
    force: Optional[np.ndarray] = None
    stiffness: Optional[sp.csr_matrix] = None


def _model_key(model: Any) -> str:
    from conformance.kit.spec import model_to_manifest

    return json.dumps(model_to_manifest(model), sort_keys=True)


def _evaluate(cache, ci, spec):
    """The oracle's Reference for ``ci.model`` evaluated as ``spec`` says."""
    from conformance.diagnosis.energy_terms import TransformedEnergy

    return cache.evaluate_model(
        ci, TransformedEnergy(ci.model, spec), _model_key(ci.model) + spec.key()
    )


def term_case(cache, ci, out, ref, s: Scales, tol: Tolerances):
    """(labels, TermCase) of one case, or None when the energy has no formula or its terms do not
    add up to the oracle's energy (then nothing is claimed from them).
    """
    from conformance.diagnosis.energy_terms import Spec, has_formula
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
    return labels, TermCase(
        [r.force for r in refs],
        [r.stiffness for r in refs],
        np.asarray(out.force),
        sp.csr_matrix(out.stiffness),
        s.force,
        s.stiffness,
        tol.force,
        tol.stiffness,
    )


def term_reading(
    labels, cases, params, worst: float, scope: str = "this case"
) -> Optional[Reading]:
    """The term fit over ``cases`` (TermCase) as a reading, or None when it explains nothing."""
    from conformance.diagnosis.term_fit import describe_fit, fit_terms

    fit = fit_terms(cases)
    if fit is None:
        return None
    figs = {
        "coefficients": [float(a) for a in fit.coefficients],
        "terms": [list(p) for p in labels],
        "residual": fit.residual,
        "identified": fit.identified,
        "cases": len(cases),
    }
    combo = " + ".join(
        f"{a:.9g} x [{' '.join(p) or 'term'}]" for a, p in zip(fit.coefficients, labels)
    )
    if fit.agrees and not fit.identified:
        coupled = ", ".join(" ".join(labels[i]) or "a term" for i in fit.coupled)
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
            names, readings = describe_fit(fit, labels, params)
            return Reading(
                Finding(
                    "term-coefficients",
                    f"mostly the energy's terms with other coefficients: {names}",
                    PARTIAL,
                    f"f, K = {combo} leaves {fit.residual:.1e} (above the tolerance)",
                    figs,
                )
            )
        return None
    names, readings = describe_fit(fit, labels, params)
    if not readings:
        return None
    a = fit.coefficients
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
            f"{fit.residual:.1e}; terms not at 1: {names}",
            figs,
        ),
        f,
        K,
    )


def _params(model: Any) -> dict:
    import dataclasses

    from reference_fem.user_energy import UserEnergy

    if isinstance(model, UserEnergy):
        return dict(model.params)
    out = {}
    for fl in dataclasses.fields(model):
        v = getattr(model, fl.name)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v):
            out[fl.name] = float(v)
    return out


def _matching(out, s: Scales, tol: Tolerances, candidates) -> List[Reading]:
    """The candidates the engine matches: each is (evaluate () -> Reference, code, title, words,
    figures); a candidate the oracle cannot evaluate at this state (ValueError) is skipped.
    """
    found = []
    for evaluate, code, title, words, figures in candidates:
        try:
            r = evaluate()
        except ValueError:  # not finite at this state, or not a formula the oracle takes
            continue
        e = errors(out.force, out.stiffness, None, r.force, r.stiffness, 0.0, s)
        if tol.within(e, energy=False):
            evidence = (
                f"{words}against that energy, differentiated by the oracle: force error "
                f"{e.force:.1e}, stiffness error {e.stiffness:.1e}"
            )
            figs = {**figures, "residual": max(e.force, e.stiffness)}
            found.append(Reading(Finding(code, title, FULL, evidence, figs), r.force, r.stiffness))
    return found


def _kinematic_readings(cache, ci, out, s: Scales, tol: Tolerances) -> List[Reading]:
    """The kinematic variants of :mod:`conformance.diagnosis.kinematics` that the engine matches."""
    from conformance.diagnosis.kinematics import kinematic_variants

    return _matching(
        out,
        s,
        tol,
        (
            (
                lambda v=v: cache.evaluate_model(
                    ci, v.oracle_model(ci.model), _model_key(ci.model) + v.key()
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
                lambda v=v: cache.reference(replace(ci, model=v.model)),
                "energy-variant",
                f"your engine matches W' = {v.expression}",
                f"{v.rewrite.words}: ",
                {"variant": v.rewrite.code, "expression": v.expression},
            )
            for v in variants(ci.model)
        ),
    )


def _same(a: Reading, b: Reading, s: Scales) -> bool:
    if a.force is None or b.force is None:
        return False
    e = errors(a.force, a.stiffness, None, b.force, b.stiffness, 0.0, s)
    return max(e.force, e.stiffness) <= _SAME


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
    if len(causes) > 1:
        lead = Finding(
            "ambiguous",
            f"ambiguous: {len(causes)} causes explain this case equally",
            OBSERVED,
            "each brings force and stiffness within tolerance and they predict different values, "
            "but not differently enough for this case to tell them apart: "
            + " | ".join(c.title for c in causes)
            + " (check a state or mesh that separates them)",
            {"codes": [c.code for c in causes]},
        )
        causes = [lead] + [replace(c, title="(ambiguous) " + c.title) for c in causes]
    return causes


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
            keep_terms((*tc, _params(ci.model)))
        r = term_reading(labels, [case], _params(ci.model), worst)
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
    causes = merge_readings(full, s)
    if causes:
        rest = [f for f in diag.findings if f.code != "unexplained"]
        return replace(diag, findings=[*causes, *observed, *rest])
    tried = (
        "; nor the energy's terms refitted"
        + ("" if tc is not None else " (no formula to split)")
        + ", its kinematic variants or its rewritten formulas (evaluated by the oracle)"
    )
    head = [
        replace(f, evidence=f.evidence + tried) for f in diag.findings if f.code == "unexplained"
    ]
    rest = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*head, *observed, *partial, *rest])


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
        out.append(replace(d, findings=[r.finding, *rest]))
    return out
