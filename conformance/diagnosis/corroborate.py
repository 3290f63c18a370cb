"""A cause belongs to the engine, not to one state: each named cause is held against the kit's
other cases of the same engine, model and mesh.

One engine ran every case of the kit, and a mistake is in its code, so the cause of one case's
failure must also account for the others'. A state can fail to separate two mistakes: on a
uniaxial stretch F and S are diagonal, so the first Piola stress P is symmetric and "P^T used as
P" predicts exactly what an engine with Teran's 2x2 SVD blocks exchanged computes. There the
reading explains its case, and it is still the wrong road. The other case, a general state, shows
it: the same reading ran there and explained nothing.

So: where a case of the group failed on its force or stiffness and nothing explains it, a cause
named on another case of the group is not named. Nor is a cause that explains its case fully
where another case of the group is explained only partly, and by another cause (a general state
whose force one reading predicts, the stiffness left over, against a uniaxial state where a
fitted stress coefficient explains both: the fit is what the uniaxial state cannot separate).
That case's diagnosis then leads with an "uncorroborated" observation (which cause fits it,
which case it leaves unexplained), and the cause is kept below it as an observation, never as
"explains". A case whose error a reading fits exactly but cannot tell from another cause (a
homogeneous state's single J fits the volumetric tangent U''(J) and any other term along
C^-1 (x) C^-1 alike) does not contradict that reading named on a case that tells them apart:
it is consistent with it (:func:`fits_codes`), and is given that cause, with the case that
told it apart (:func:`extend_consistent`). A case that passed, failed only through its
energy or the engine's own consistency, or was not read for causes (``--verdict-only``)
contradicts nothing.
"""

from __future__ import annotations

from dataclasses import replace
from typing import List, Optional, Sequence

from conformance.diagnosis.findings import FULL, OBSERVED, PARTIAL, Finding

__all__ = [
    "corroborate",
    "extend_consistent",
    "extend_covered",
    "fits_codes",
    "left_unexplained",
]

_ONLY = "(this case only) "
_AMBIGUOUS = "(ambiguous) "


def _as_observations(findings) -> list:
    """``findings`` with each cause named in full kept as an observation of this case only."""
    return [
        replace(f, strength=OBSERVED, title=_ONLY + f.title) if f.strength == FULL else f
        for f in findings
    ]


def left_unexplained(diagnosis) -> bool:
    """True when the case failed against the oracle's force or stiffness and no cause was read
    (its headline says "unexplained").
    """
    d = diagnosis
    if d is None or d.passed or d.causes or not d.findings:
        return False
    if d.findings[0].code != "unexplained":
        return False  # not read (--verdict-only), or an observation that is not "nothing fits"
    return not d.tolerances.within(d.errors, energy=False)


def corroborate(
    diagnoses: Sequence[Optional[object]], groups: Sequence[Sequence[int]], case_ids: Sequence[str]
) -> List:
    """``diagnoses`` (one per case, None where there is none) with every cause that leaves
    another case of its group unexplained turned into an observation; the others unchanged.

    groups: indices of the cases sharing engine, model and mesh (one kit's run is one engine).
    """
    out = list(diagnoses)
    for group in groups:
        for i in group:
            d = diagnoses[i]
            if d is None or not d.causes:
                continue
            codes = {f.code for f in d.causes}
            full = any(f.strength == FULL for f in d.causes)
            open_cases = [
                j
                for j in group
                if j != i
                and not any(_fits(f, fits_codes(diagnoses[j])) for f in d.causes)
                and (
                    left_unexplained(diagnoses[j])
                    or (full and _partly_otherwise(diagnoses[j], codes))
                )
            ]
            if not open_cases:
                continue
            named = d.causes
            others = ", ".join(case_ids[j] for j in open_cases)
            lead = Finding(
                "uncorroborated",
                "cause not named: "
                + " | ".join(f.title.removeprefix(_AMBIGUOUS) for f in named)
                + (" fit" if len(named) > 1 else " fits")
                + f" this case, but not the kit's case(s) {others} (same engine, model and "
                "mesh), which nothing explains fully",
                OBSERVED,
                "a mistake in the engine's code shows on every state it touches; a reading that "
                "explains this case and leaves another case of the same engine unexplained "
                "describes what this state cannot tell apart, not the cause (the fit here: "
                + "; ".join(f.evidence for f in named)
                + ")",
                {
                    "codes": [f.code for f in named],
                    "unexplained_cases": [case_ids[j] for j in open_cases],
                },
            )
            kept = _as_observations(d.findings)
            out[i] = replace(d, findings=[lead, *kept])
    return out


def fits_codes(diagnosis) -> set:
    """The causes (finding codes) that fit an unexplained case exactly but that the case cannot
    tell from other causes (a homogeneous state's single J: U''(J) or another term along
    C^-1 (x) C^-1). Such a case is consistent with one of them named on another case of its
    group, where the state tells them apart: it does not contradict that cause.
    """
    d = diagnosis
    if d is None or not d.findings:
        return set()
    head = d.findings[0]
    if head.code == "unexplained" or (head.code == "volumetric" and head.strength == FULL):
        # a J-only energy named on a single J is one of the causes that state cannot separate
        return set(head.figures.get("fits_codes", ()))
    return set()


def _fits(cause: Finding, fits: set) -> bool:
    """True when ``cause`` is one of the codes ``fits`` lists: its code, or "code:X" for a cause
    whose reading names the invariant X (figures["invariant"]; "stress-derivative-rewritten:J":
    a hand-written derivative in J only, not in I1).
    """
    return cause.code in fits or f"{cause.code}:{cause.figures.get('invariant')}" in fits


def _partly_otherwise(diagnosis, codes) -> bool:
    """True when the case failed, nothing explains it fully, and its headline explains it
    partly by a cause that is not one of ``codes``.
    """
    d = diagnosis
    if d is None or d.passed or d.causes or not d.findings:
        return False
    lead = d.findings[0]
    return lead.strength == PARTIAL and lead.code not in codes


def _named_elsewhere(diagnoses, group, j: int, accept) -> Optional[tuple]:
    """(i, cause): the first cause named in full on a case i != j of ``group`` that ``accept``
    takes; None where there is none.
    """
    return next(
        (
            (i, c)
            for i in group
            if i != j and diagnoses[i] is not None
            for c in diagnoses[i].causes
            if c.strength == FULL and accept(c)
        ),
        None,
    )


def extend_consistent(
    diagnoses: Sequence[Optional[object]], groups: Sequence[Sequence[int]], case_ids: Sequence[str]
) -> List:
    """``diagnoses`` with every unexplained case that a reading fits exactly but cannot tell
    apart (:func:`fits_codes`) given the cause of that reading that another case of its group
    names in full (after :func:`corroborate`): one engine, one mistake, identified where the
    state separates the candidates and predicting this case too. Others unchanged.
    """
    out = list(diagnoses)
    for group in groups:
        for j in group:
            fits = fits_codes(diagnoses[j])
            if not fits:
                continue
            source = _named_elsewhere(diagnoses, group, j, lambda f, fits=fits: _fits(f, fits))
            if source is None:
                continue
            i, cause = source
            d = diagnoses[j]
            head = d.findings[0]
            found = Finding(
                cause.code,
                cause.title,
                FULL,
                f"named on the kit's case {case_ids[i]} (same engine, model and mesh), where the "
                "state tells it apart; here an error of its kind fits the engine exactly (its "
                "size at this state fitted, not predicted from that case), but this state alone "
                f"cannot tell it from another cause ({head.evidence})",
                {**cause.figures, "named_on": case_ids[i]},
            )
            out[j] = replace(d, findings=[found, *d.findings[1:]])
    return out


def _covered(finding: Finding, cause: Finding) -> bool:
    """True when ``cause`` (named on another case) covers ``finding``: it lists finding's code
    under figures["covers"], names the same parameter, and the finding's value differs from the
    declared one by at most figures["covers_relative"] of it (one number standing for a factor
    per cell that a homogeneous state makes the same in every cell).
    """
    if finding.code not in cause.figures.get("covers", ()):
        return False
    if finding.code == "term-coefficients" and "exponent" in cause.figures:
        return _power_covered(finding, cause)
    name = finding.figures.get("parameter")
    if name is None or name != cause.figures.get("parameter"):
        return False
    value, declared = finding.figures.get("value"), finding.figures.get("declared")
    if value is None or not declared:
        return False
    return abs(value / declared - 1.0) <= cause.figures.get("covers_relative", 0.0)


def _power_covered(finding: Finding, cause: Finding) -> bool:
    """True when ``finding`` (terms refitted on a state of one J) is ``cause``'s factor J^q on
    its parameter's term at that J, every other term at 1 (to 1e-6): a factor per cell that is
    a power of J (:mod:`conformance.diagnosis.part_powers`) is one number where J is one.
    """
    J = finding.figures.get("one_j")
    terms = finding.figures.get("terms", ())
    coefficients = finding.figures.get("coefficients", ())
    if J is None or J <= 0.0 or len(terms) != len(coefficients):
        return False
    name, q = cause.figures.get("parameter"), cause.figures["exponent"]
    predicted = [J**q if list(t) == [name] else 1.0 for t in terms]
    if all(p == 1.0 for p in predicted):
        return False
    return all(abs(a - p) <= 1e-6 * abs(p) for a, p in zip(coefficients, predicted))


def extend_covered(
    diagnoses: Sequence[Optional[object]], groups: Sequence[Sequence[int]], case_ids: Sequence[str]
) -> List:
    """``diagnoses`` with every case whose causes another case of its group covers
    (:func:`_covered`: a parameter off by float32's size where that case names a scalar of the
    parameter's part rounded per cell; a term's coefficient equal to J^q at the state's one J
    where that case names the term's part multiplied per cell by J^q) given that cause, its own
    kept below as observations. On a state whose cells are all alike the per-cell factor is one
    number and a refit fits it; the state with distinct cells shows what it is. Others
    unchanged.
    """
    out = list(diagnoses)
    for group in groups:
        for j in group:
            d = out[j]
            if d is None or not d.causes:
                continue
            source = _named_elsewhere(
                out, group, j, lambda c, d=d: all(_covered(f, c) for f in d.causes)
            )
            if source is None:
                continue
            i, cause = source
            own = "; ".join(f"{f.title} ({f.evidence})" for f in d.causes)
            if "exponent" in cause.figures:
                why = (
                    "where J differs from cell to cell and the factor is seen to be a power of "
                    f"J; here it fits as one number ({own}), that power at this state's one J"
                )
            else:
                why = (
                    "where the cells differ and the factor is seen drawn per cell; here it fits "
                    f"as one number ({own}): the cells of this state are alike and round alike"
                )
            found = Finding(
                cause.code,
                cause.title,
                FULL,
                f"named on the kit's case {case_ids[i]} (same engine, model and mesh), {why}",
                {**cause.figures, "named_on": case_ids[i]},
            )
            kept = _as_observations(d.findings)
            out[j] = replace(d, findings=[found, *kept])
    return out
