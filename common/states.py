"""Deformation states of the equivalence study.

Each state maps rest positions X (n, 3) to current positions x (n, 3). The homogeneous ones
are taken about the mesh's centroid so that they do not depend on where the mesh sits.
"""

from __future__ import annotations

from typing import Callable, Dict, Optional, Tuple

import numpy as np

from common.frames import mid_wall_frame
from meshes import signed_volumes

__all__ = [
    "STATES",
    "state_names",
    "apply_state",
    "smooth_random",
    "min_volume_ratio",
    "max_stretch",
]


def _affine(A: np.ndarray) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    def apply(X: np.ndarray, cells: np.ndarray) -> np.ndarray:
        c = X.mean(axis=0)
        return c + (X - c) @ A.T

    return apply


def min_volume_ratio(X: np.ndarray, x: np.ndarray, cells: np.ndarray) -> float:
    """Smallest J = (current signed volume) / (rest signed volume) over the cells."""
    return float((signed_volumes(x, cells) / signed_volumes(X, cells)).min())


def max_stretch(X: np.ndarray, x: np.ndarray, cells: np.ndarray) -> float:
    """Largest principal stretch (singular value of F) over the cells; X, x (n, 3), cells (m, 4)."""
    from mjed.mesh import shape_vectors

    _, D = shape_vectors(X, cells)
    F = np.einsum("mai,maj->mij", x[cells], D)
    return float(np.linalg.svd(F, compute_uv=False)[:, 0].max())


def smooth_random(
    X: np.ndarray,
    cells: np.ndarray,
    *,
    seed: int = 0,
    min_J: float = 0.2,
    stretch_limit: Optional[float] = None,
) -> np.ndarray:
    """A seeded smooth random deformation: a rotation of X plus a sum of sine modes.

    The amplitude starts at 15 % of the mesh size and is halved until every cell keeps
    J > min_J (and, with ``stretch_limit``, no principal stretch above it: on a cap or a
    sliver a smooth field strains the thin cell far more than the mesh), so the state is always
    admissible and reproducible for a given seed.
    """
    rng = np.random.default_rng(seed)
    c = X.mean(axis=0)
    size = float(np.ptp(X, axis=0).max())
    Y = (X - c) / size
    k = rng.uniform(0.5, 2.0, size=(4, 3))  # wave vectors (cycles per mesh size)
    phase = rng.uniform(0, 2 * np.pi, size=4)
    amp = rng.standard_normal((4, 3))
    u = np.sin(2 * np.pi * Y @ k.T + phase) @ amp / np.sqrt(4.0)  # (n, 3), O(1)
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    R = _quaternion_to_rotation(q)
    scale = 0.15
    for _ in range(30):
        x = c + (X - c + scale * size * u) @ R.T
        stretched_ok = stretch_limit is None or max_stretch(X, x, cells) <= stretch_limit
        if min_volume_ratio(X, x, cells) > min_J and stretched_ok:
            return x
        scale *= 0.5
    raise RuntimeError(
        "could not find an admissible random perturbation"
    )  # unreachable for valid meshes


def _quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _fibre_states() -> Tuple[np.ndarray, np.ndarray]:
    """Deformation gradients (3, 3) of a stretch along the mid-wall fibre f0 (1.25) and of a shear
    in the mid-wall fibre-sheet plane (x += 0.4 (s0 . X) f0; J = 1 since f0 is normal to s0).

    The fibre frame turns through the wall (common/frames.py), so no homogeneous state follows the
    fibre of every cell; these follow the mid-wall one, where an engine that ignores, transposes
    or globalises the frame sees a fibre energy different from the true one, in force and in
    stiffness alike.
    """
    R0 = mid_wall_frame()
    f0, s0 = R0[:, 0], R0[:, 1]
    return np.eye(3) + 0.25 * np.outer(f0, f0), np.eye(3) + 0.4 * np.outer(f0, s0)


_FIBRE_STRETCH, _FIBRE_SHEAR = _fibre_states()

#: name -> (description, function(X, cells) -> x)
STATES: Dict[str, Tuple[str, Callable[[np.ndarray, np.ndarray], np.ndarray]]] = {
    "rest": ("x = X", lambda X, cells: X.copy()),
    "uniaxial": ("stretch 1.3 along x (J = 1.3)", _affine(np.diag([1.3, 1.0, 1.0]))),
    "compression": ("compression 0.8 along x (J = 0.8)", _affine(np.diag([0.8, 1.0, 1.0]))),
    "shear": (
        "simple shear, amount 0.4 (x += 0.4 y)",
        _affine(np.array([[1.0, 0.4, 0.0], [0, 1, 0], [0, 0, 1]])),
    ),
    "triaxial": (
        "stretches 1.25, 0.9, 0.8: distinct principal stretches, J = 0.9",
        _affine(np.diag([1.25, 0.9, 0.8])),
    ),
    "fibre-stretch": (
        "stretch 1.25 along the mid-wall fibre of the default frame field, J = 1.25",
        _affine(_FIBRE_STRETCH),
    ),
    "fibre-shear": (
        "shear 0.4 in the mid-wall fibre-sheet plane of the default frame field",
        _affine(_FIBRE_SHEAR),
    ),
    "random": (
        "seeded smooth random field with a rotation, J > 0.2",
        lambda X, cells: smooth_random(X, cells),
    ),
}


def state_names() -> Tuple[str, ...]:
    return tuple(STATES)


def apply_state(name: str, X: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Current positions (n, 3) of the named state."""
    try:
        return STATES[name][1](X, cells)
    except KeyError:
        raise ValueError(f"unknown state {name!r}; known states: {', '.join(STATES)}") from None
