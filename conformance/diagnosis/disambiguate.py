"""Ambiguity settled by another case of the same kit.

A case may not separate two causes (a uniaxial stretch, where B = C and the gradients of I1b
and I2b are parallel): both explain it and the diagnosis says "ambiguous". The same engine ran
the kit's other cases of the same model and mesh; where one of them names a single cause, and
that cause is among those that explain the ambiguous case, the ambiguous case is given that
cause: it explains this case within tolerance, and it is the only one that explains the other.
Nothing is named when the other cases name no single cause, or one that does not explain this
case.
"""

from __future__ import annotations

from dataclasses import replace
from typing import List, Optional, Sequence

from conformance.diagnosis.findings import FULL, PARTIAL, Finding

__all__ = ["settle_ambiguity"]

_MARK = "(ambiguous) "


def _single_cause(findings: Sequence[Finding]) -> Optional[Finding]:
    if findings and "restates" in findings[0].figures:
        return findings[0]  # one term's finding restated (a difference step, a small error)
    if not findings or findings[0].strength != FULL:
        return None
    causes = [f for f in findings if f.strength == FULL]
    return causes[0] if len(causes) == 1 else None


def settle_ambiguity(diagnoses: List, groups: List[List[int]], case_ids: List[str]) -> List:
    """``diagnoses`` (one per case, None for cases without one) with each ambiguous one settled
    by another case of its group (indices of cases sharing model and mesh) that names a single
    cause; the others unchanged.
    """
    out = list(diagnoses)
    for group in groups:
        named = {}
        for i in group:
            d = diagnoses[i]
            cause = None if d is None else _single_cause(d.findings)
            if cause is not None:
                named.setdefault(cause.figures.get("restates", cause.title), (cause, i))
        for i in group:
            d = diagnoses[i]
            if d is None or not d.findings or d.findings[0].code != "ambiguous":
                continue
            options = {
                f.title[len(_MARK) :]: f
                for f in d.findings[1:]
                if f.strength == FULL and f.title.startswith(_MARK)
            }
            hits = [(options[t], named[t][1]) for t in options if t in named]
            if len(hits) != 1:
                continue
            mine, j = hits[0]
            other = named[mine.title[len(_MARK) :]][0]
            if "restates" in other.figures:
                # The other case restated this term (a difference step, a small error): said
                # here as the other case's reading, partly: this case alone does not show it.
                settled = replace(
                    other,
                    strength=PARTIAL,
                    evidence=f"this case cannot tell the term from {len(options) - 1} other "
                    f"cause(s) ({' | '.join(t for t in options if t != mine.title[len(_MARK) :])})"
                    f"; the kit's case {case_ids[j]} (same engine, model and mesh) is explained by "
                    f"it alone, and there: {other.evidence}",
                )
                rest = [
                    f for f in d.findings if f.code != "ambiguous" and not f.title.startswith(_MARK)
                ]
                out[i] = replace(d, findings=[settled, *rest])
                continue
            settled = replace(
                mine,
                title=mine.title[len(_MARK) :],
                evidence=mine.evidence
                + f"; this case cannot tell it from {len(options) - 1} other cause(s) "
                f"({' | '.join(t for t in options if t != mine.title[len(_MARK) :])}), but the "
                f"kit's case {case_ids[j]} (same engine, model and mesh) is explained by it "
                "alone",
            )
            rest = [
                f for f in d.findings if f.code != "ambiguous" and not f.title.startswith(_MARK)
            ]
            out[i] = replace(d, findings=[settled, *rest])
    return out
