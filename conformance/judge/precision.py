"""Tolerances at single precision, from float32 round-off and each case's conditioning.

An engine that computes in float32 (GPU and real-time engines commonly do) cannot agree with
the oracle to 1e-10: its inputs alone are rounded to u = 2^-24 = 6.0e-8 of their magnitude,
and the force and stiffness amplify that by the case's conditioning (coordinates large against
the thinnest cell's height, a stiff exponential energy, strongly compressed cells). The
tolerances of a case at single precision are therefore measured on the case:

    sensitivity_q = || q_oracle(X', x') - q_oracle(X, x) || / scale_q        (q = f, K, W)

with X' = X (1 + u xi), x' = x (1 + u eta), xi and eta seeded uniform in [-1, 1] per
coordinate: how far the exact answer moves when the case's own numbers carry float32's
relative round-off. The engine's arithmetic adds round-off of the same kind at every step
(each operation is exact up to a relative u), so the tolerance is

    tol_q = SAFETY x max(sensitivity_q, u)

with SAFETY = 100: a few hundred float32 operations per cell, their errors adding at random,
grow like their square root (about 20 u), and the perturbed oracle is one sample of a random
error. A real mistake (a missing term, a factor, a transposed block) is an error of 1e-3 or
far more; it still fails. A tolerance is never above CAP = 1e-2: on a cap of quality 1e-3
under a strong random field, float32 round-off of the coordinates moves the stiffness by 1 %,
and such a case is said to be beyond what float32 resolves rather than passed with a limit of
0.85.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from conformance.judge.compare import Errors, Scales, Tolerances, errors

__all__ = ["U32", "SAFETY", "CAP", "single_tolerances", "sensitivity_of", "perturbed"]

#: Unit round-off of IEEE float32.
U32 = 2.0**-24

#: Tolerance = SAFETY x max(measured sensitivity, U32) (module docstring).
SAFETY = 100.0

#: No single-precision tolerance above this: a case float32 cannot resolve to 1 % is said so.
CAP = 1e-2


def perturbed(a: np.ndarray, seed: int) -> np.ndarray:
    """A (any shape) with every entry moved by a seeded relative amount in [-U32, U32]."""
    rng = np.random.default_rng(seed)
    return a * (1.0 + U32 * rng.uniform(-1.0, 1.0, size=a.shape))


def single_tolerances(sensitivity: Errors) -> Tolerances:
    """Tolerances at single precision from the relative change of the oracle's energy, force and
    stiffness when the case's coordinates carry float32 round-off (:func:`sensitivity_of`),
    each at most CAP: where float32 cannot resolve a case better than that, a looser limit would
    pass anything, and the basis says so.
    """
    energy = U32 if sensitivity.energy is None else sensitivity.energy
    raw = {
        q: SAFETY * max(v, U32)
        for q, v in (
            ("force", sensitivity.force),
            ("stiffness", sensitivity.stiffness),
            ("energy", energy),
        )
    }
    capped = [q for q, v in raw.items() if v > CAP]
    basis = (
        f"{SAFETY:g} x max(float32 round-off u = {U32:.1e}, the oracle's relative change "
        f"when the coordinates carry u): force {sensitivity.force:.1e}, stiffness "
        f"{sensitivity.stiffness:.1e}, energy {energy:.1e}"
    )
    if capped:
        basis += (
            f"; capped at {CAP:g} for the {' and '.join(capped)}: float32 cannot resolve "
            "this case better than that, so a float32 engine may fail it"
        )
    limits = (min(raw[q], CAP) for q in ("force", "stiffness", "energy"))
    return Tolerances(*limits, "single", basis, tuple(capped))


def sensitivity_of(
    evaluate: Callable[[np.ndarray, np.ndarray], tuple],
    points: np.ndarray,
    positions: np.ndarray,
    reference: tuple,
    s: Scales,
) -> Errors:
    """The oracle's relative change under float32 round-off of the coordinates.

    evaluate(points, positions) -> (energy, force (n, 3), stiffness (3n, 3n)) is the oracle on a
    mesh with those rest points; reference = the same at the case's own coordinates; s: the
    case's error scales.
    """
    W1, f1, K1 = evaluate(perturbed(points, 11), perturbed(positions, 12))
    W0, f0, K0 = reference
    return errors(f1, K1, W1, f0, K0, W0, s)
