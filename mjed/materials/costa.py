"""Costa's orthotropic exponential law: W = a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from mjed.materials import classical_forms as forms
from mjed.materials.base import Material, require_finite
from mjed.materials.declaration import Declaration, declare
from mjed.terms import JLogJ, JPower, Term, TermGroup, Unity

__all__ = ["Costa"]

_B_NAMES = ("b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")


@dataclass(frozen=True, eq=False)
class Costa(Material):
    """W = a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1), Q = sum_ij B_ij (R^T E R)_ij^2.

    B = [[b_ff, b_fs, b_fn], [b_fs, b_ss, b_sn], [b_fn, b_sn, b_nn]]. frame R (columns fibre,
    sheet, normal): None for the global axes (SOFA's choice), one (3, 3) rotation, or one per
    cell (m, 3, 3). split: how B is written as a signed sum of rank-one terms for the tangent,
    "ldl" (SOFA's signed Cholesky, refuses a zero pivot) or "eigen" (always exists).

    Valid parameters (anything else raises ValueError naming the parameter and the reason):

    - every parameter a finite real number;
    - a > 0: a scales the whole fibre energy; a = 0 removes all resistance to isochoric
      deformation and a < 0 makes every strain lower the energy;
    - k0 > 0: the bulk modulus of k0 (J ln J - J + 1), the only resistance to volume change;
    - every b_ij >= 0: the six components of Ef are independent, so Q = sum B_ij Ef_ij^2 is
      >= 0 for every strain exactly when every b_ij is; a negative b_ij lets the strain
      component Ef_ij alone bring the energy below its rest value (the rest state would not
      be a minimum);
    - at least one b_ij > 0: with all six zero, Q = 0 and the body resists no isochoric
      deformation at all.

    (B itself may be an indefinite matrix: Q is an entrywise weighting, not x^T B x.)
    """

    a: float
    k0: float
    b_ff: float
    b_fs: float
    b_ss: float
    b_fn: float
    b_sn: float
    b_nn: float
    frame: Optional[np.ndarray] = None
    split: str = "ldl"

    def __post_init__(self):
        require_finite(self, "a", "k0", *_B_NAMES)
        if self.a <= 0:
            raise ValueError(
                "Costa: parameter a must be > 0 (it scales the fibre energy a/2 (exp(J^(-4/3) Q) "
                "- 1); a <= 0 leaves no resistance to isochoric deformation or reverses it), "
                f"got {self.a!r}"
            )
        if self.k0 <= 0:
            raise ValueError(
                f"Costa: parameter k0 must be > 0 (the bulk modulus, the only resistance to volume "
                f"change), got {self.k0!r}"
            )
        for name in _B_NAMES:
            if getattr(self, name) < 0:
                raise ValueError(
                    f"Costa: parameter {name} must be >= 0, got {getattr(self, name)!r}: "
                    "Q = sum B_ij Ef_ij^2 would be negative for a strain along that component "
                    "alone, bringing the energy below its rest value"
                )
        if all(getattr(self, name) == 0 for name in _B_NAMES):
            raise ValueError(
                "Costa: at least one of b_ff, b_fs, b_ss, b_fn, b_sn, b_nn must be > 0 "
                "(with all zero Q = 0: no resistance to isochoric deformation)"
            )
        if self.frame is not None:
            R = np.array(self.frame, dtype=float)
            if R.shape[-2:] != (3, 3) or R.ndim not in (2, 3):
                raise ValueError(
                    f"Costa: parameter frame must have shape (3, 3) or (m, 3, 3), got {R.shape}"
                )
            if not np.isfinite(R).all():
                raise ValueError("Costa: parameter frame has non-finite entries")
            err = (
                np.abs(np.einsum("...ki,...kj->...ij", R, R) - np.eye(3)).reshape(-1, 9).max(axis=1)
            )
            if (err > 1e-8).any():
                k = int(np.argmax(err))
                where = f" (cell {k})" if R.ndim == 3 else ""
                raise ValueError(
                    f"Costa: parameter frame is not orthonormal{where}: |R^T R - I| = {err[k]:.2e}"
                )
            R.setflags(write=False)
            object.__setattr__(self, "frame", R)
        # Fail now, not at the first evaluation, if the split cannot be made.
        from mjed.fibre import signed_split

        signed_split(self.B, self.split)

    @property
    def B(self) -> np.ndarray:
        return np.array(
            [
                [self.b_ff, self.b_fs, self.b_fn],
                [self.b_fs, self.b_ss, self.b_sn],
                [self.b_fn, self.b_sn, self.b_nn],
            ]
        )

    def decomposition(self):
        from mjed.fibre import FibreQuadratic

        R = np.eye(3) if self.frame is None else self.frame
        half_a = 0.5 * self.a
        return (
            TermGroup(
                (Term(JPower(-4.0 / 3.0), FibreQuadratic(self.B, R, self.split)),),
                exponential=True,
                coefficient=half_a,
            ),
            TermGroup((Term(JLogJ(self.k0, -half_a), Unity()),)),
        )


def energy(p, k):
    b = {n: p(n) for n in _B_NAMES}
    B = [
        [b["b_ff"], b["b_fs"], b["b_fn"]],
        [b["b_fs"], b["b_ss"], b["b_sn"]],
        [b["b_fn"], b["b_sn"], b["b_nn"]],
    ]
    R = k.frame
    Ef = R.T * k.E * R  # strain in the fibre frame
    Q = sum(B[i][j] * Ef[i, j] ** 2 for i in range(3) for j in range(3))
    return 0.5 * p("a") * (k.exp(k.J ** (-4.0 / 3.0) * Q) - 1.0) + p("k0") * (
        k.J * k.lnJ - k.J + 1.0
    )


def volumetric(p, k):
    return p("k0") * (k.J * k.lnJ - k.J + 1.0)


declare(
    Declaration(
        material=Costa,
        formula="a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1)",
        notes="`Q = sum_ij B_ij (Ef_ij)^2`, `Ef = R^T E R`",
        parameters="`a`, `k0` (Pa); `b_ff`, `b_fs`, `b_ss`, `b_fn`, `b_sn`, `b_nn` "
        "(dimensionless); a frame",
        # Fibre stiffer than sheet and normal, with shear couplings (Guccione-like ratios).
        default=Costa(
            a=800.0, k0=3.0e4, b_ff=18.5, b_fs=2.8, b_ss=3.6, b_fn=2.0, b_sn=1.6, b_nn=3.6
        ),
        energy=energy,
        volumetric=volumetric,
        volumetric_formula="k0 (J ln J - J + 1)",
        classical=lambda m: forms.FibreExponential(m.a, m.k0, m.B, m.frame),
        sofa=("Costa", ("a", "k0") + _B_NAMES),
        order=60,
        ranges={
            "a": (0.05, 20.0),
            "k0": (0.05, 20.0),
            "b_ff": (0.5, 5.0),
            # b_fs below sqrt(min b_ff * min b_ss) = 0.5: at the box's corner (0.5, 0.5, 0.5)
            # the split's second pivot b_ss - b_fs^2/b_ff is zero and the material is refused.
            "b_fs": (0.0, 0.45),
            "b_ss": (0.5, 5.0),
            "b_fn": (0.0, 0.5),
            "b_sn": (0.0, 0.5),
            "b_nn": (0.5, 5.0),
        },
        # CostaIndefinite: a B whose signed L D L^T split has a negative pivot
        examples={
            "Costa": Costa(
                a=0.9, k0=3.0, b_ff=1.0, b_fs=0.3, b_ss=0.8, b_fn=0.2, b_sn=0.1, b_nn=0.5
            ),
            "CostaIndefinite": Costa(
                a=0.9, k0=3.0, b_ff=1.0, b_fs=0.9, b_ss=0.5, b_fn=0.2, b_sn=0.1, b_nn=0.5
            ),
        },
    )
)
