"""A linear least-squares fit that says when its unknowns are not determined.

Readings that fit a few coefficients over an assembled system (the pieces of a spatial tangent,
the stress-side pieces of the energy's terms) must not name a coefficient that the case cannot
separate from another: the columns are scaled to unit norm and the fit refused when a column is
zero or the smallest singular value falls below a ratio of the largest.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

__all__ = ["determined_lstsq"]


def determined_lstsq(A: np.ndarray, y: np.ndarray, ratio: float) -> Optional[np.ndarray]:
    """The x minimising ||A x - y|| for A (n, k) and y (n,) or (n, r): x (k,) or (k, r);
    None when a column of A is zero or the unit-scaled columns are not separated (smallest
    singular value below ``ratio`` times the largest).
    """
    norms = np.linalg.norm(A, axis=0)
    if not np.all(norms > 0):
        return None
    scaled = A / norms
    sv = np.linalg.svd(scaled, compute_uv=False)
    if sv[-1] < ratio * sv[0]:
        return None
    x = np.linalg.lstsq(scaled, y, rcond=None)[0]
    return x / (norms[:, None] if x.ndim == 2 else norms)
