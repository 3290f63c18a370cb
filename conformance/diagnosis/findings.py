"""What the diagnosis reports: findings, each with the figure that supports it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Dict, List

__all__ = ["Finding", "FULL", "PARTIAL", "OBSERVED", "ambiguous", "named_first"]

FULL = "explains"  # applying the correction brings force and stiffness within tolerance
PARTIAL = "partly explains"  # the correction reduces the error but leaves more than the tolerance
OBSERVED = "observed"  # a measured fact (e.g. the engine's own consistency), not a correction


@dataclass(frozen=True)
class Finding:
    """One named cause or fact.

    code: stable identifier, e.g. "force-sign", "dof-order", "tangent-part" (tests key on it).
    title: the mistake in words, e.g. "force sign flipped (f = +dW/dx)".
    strength: FULL, PARTIAL or OBSERVED.
    evidence: the figures in words, e.g. "after flipping: force error 3e-16, stiffness 2e-16".
    figures: the same figures as numbers (JSON).
    """

    code: str
    title: str
    strength: str
    evidence: str
    figures: Dict[str, Any] = field(default_factory=dict)

    def text(self) -> str:
        return f"{self.title} [{self.strength}]: {self.evidence}"

    def to_dict(self) -> dict:
        """Strict JSON: non-finite figures become null, listed under ``not_finite``."""
        figures = {k: _finite(v) for k, v in self.figures.items()}
        bad = [k for k, v in self.figures.items() if _finite(v) is None and v is not None]
        if bad:
            figures["not_finite"] = bad
        return {
            "code": self.code,
            "title": self.title,
            "strength": self.strength,
            "evidence": self.evidence,
            "figures": figures,
        }


def _finite(v: Any) -> Any:
    """A float that is NaN or infinite -> None; lists element-wise; anything else unchanged."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    return v


def ambiguous(found: List[Finding], why: str = "") -> List[Finding]:
    """``found`` unchanged when it holds at most one cause; else led by an "ambiguous" finding
    (observed: it names none) and each cause marked "(ambiguous)". why: what makes them alike.
    """
    if len(found) <= 1:
        return found
    lead = Finding(
        "ambiguous",
        f"ambiguous: {len(found)} causes explain this case equally",
        OBSERVED,
        "each brings force and stiffness within tolerance"
        + (f" ({why})" if why else "")
        + ": "
        + " | ".join(x.title for x in found)
        + " (check a state or mesh that separates them)",
        {"codes": [x.code for x in found]},
    )
    return [lead] + [
        Finding(x.code, "(ambiguous) " + x.title, x.strength, x.evidence, x.figures) for x in found
    ]


def named_first(diag: Any, found: List[Finding]) -> Any:
    """``diag`` (a case's diagnosis) with ``found`` named first and its "unexplained" finding
    dropped; ``diag`` itself when nothing was found.
    """
    if not found:
        return diag
    rest = [f for f in diag.findings if f.code != "unexplained"]
    return replace(diag, findings=[*found, *rest])
