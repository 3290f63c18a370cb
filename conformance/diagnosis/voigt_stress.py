"""A Voigt stress vector built like the strain vector: its shear components doubled.

With engineering shear strains in the Voigt strain vector (2 E_12, 2 E_23, 2 E_13), the stress
vector holds the tensor components S_12, S_23, S_13; an engine that doubles them there
(2 S_12, ...) computes the internal force f = -V0 B^T s of S with its off-diagonal doubled,
while its stiffness (the tangent matrix and the geometric part, written from S) stays right.
Tested on the oracle's per-cell stress (:mod:`conformance.diagnosis.invariant_pieces`).
"""

from __future__ import annotations

from typing import Callable, List

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble
from conformance.diagnosis.findings import FULL, Finding

__all__ = ["WORDS", "voigt_stress_findings"]

WORDS = (
    "the shear components of the stress doubled in your force (Voigt stress vector built like "
    "the strain vector: 2 S_12, 2 S_23, 2 S_13 where engineering shear strains need S_12, "
    "S_23, S_13)"
)


def voigt_stress_findings(
    split: ElementSplit, S: np.ndarray, matches: Callable[[np.ndarray, sp.csr_matrix], float]
) -> List[Finding]:
    """The finding when the engine's force is that of S (m, 3, 3) with its off-diagonal
    doubled and its stiffness the oracle's; matches(f, K) as in invariant_pieces.
    """
    off = S - np.einsum("mii->mi", S)[:, :, None] * np.eye(3)
    fe = split.fe - split.V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", split.F, off, split.D)
    f, K = assemble(split.cells, split.n, fe, split.Ke)
    left = matches(f, K)
    if not np.isfinite(left):
        return []
    return [
        Finding(
            "voigt-stress-shear",
            WORDS,
            FULL,
            "the oracle's stress per cell (from the element forces) with S_12, S_23, S_13 "
            f"doubled in the force, the stiffness kept: errors against your engine {left:.1e}",
            {"residual": left},
        )
    ]
