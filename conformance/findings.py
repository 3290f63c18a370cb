"""What the diagnosis reports: findings, each with the figure that supports it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict

__all__ = ["Finding", "FULL", "PARTIAL", "OBSERVED"]

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
        return {
            "code": self.code,
            "title": self.title,
            "strength": self.strength,
            "evidence": self.evidence,
            "figures": dict(self.figures),
        }
