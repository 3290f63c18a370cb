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
"explains". A case that passed, failed only through its energy or the engine's own
consistency, or was not read for causes (``--verdict-only``) contradicts nothing.
"""

from __future__ import annotations

from dataclasses import replace
from typing import List, Optional, Sequence

from conformance.diagnosis.findings import FULL, OBSERVED, PARTIAL, Finding

__all__ = ["corroborate", "left_unexplained"]

_ONLY = "(this case only) "
_AMBIGUOUS = "(ambiguous) "


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
            kept = [
                replace(f, strength=OBSERVED, title=_ONLY + f.title) if f.strength == FULL else f
                for f in d.findings
            ]
            out[i] = replace(d, findings=[lead, *kept])
    return out


def _partly_otherwise(diagnosis, codes) -> bool:
    """True when the case failed, nothing explains it fully, and its headline explains it
    partly by a cause that is not one of ``codes``.
    """
    d = diagnosis
    if d is None or d.passed or d.causes or not d.findings:
        return False
    lead = d.findings[0]
    return lead.strength == PARTIAL and lead.code not in codes
