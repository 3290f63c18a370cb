"""Is an error float32 round-off, or a systematic mistake that happens to be small?

"Small enough to be float32" is not evidence of float32: a double-precision engine with a
slightly wrong constant (a parameter off by 1e-5, an exponent written with six digits) has errors
of the same size. What tells them apart is the *structure* of the error:

- **Balance.** Any error that comes from an energy (a wrong formula, a wrong parameter, a wrong
  kinematic) keeps the balance laws of the discrete system exactly: the forces of a translation-
  invariant energy sum to zero, ``sum_a f_a = 0``, and each row of K sums to zero over the nodes,
  ``sum_b K[3a+i, 3b+j] = 0``. So the *error* of a systematic mistake sums to zero too, to the
  engine's double round-off. Rounding each stored value to float32 (or computing it in float32)
  breaks these sums by about the round-off of the values summed: ``sqrt(sum (u v)^2 / 3)``. The
  ratio of what is observed to what float32 rounding would leave is about 1 for a float32 engine
  and about 1e-8 for a systematic double-precision error.
- **Storage.** Values that are exactly representable in float32 were written (or computed) in
  float32. Reported as supporting evidence, not required (an engine may compute in float32 and
  accumulate in double).

:func:`signature` measures both; :attr:`Signature.float32_like` is the decision: float32 is named
only when the error breaks the balance as float32 rounding does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

__all__ = ["Signature", "signature", "BALANCE_RATIO", "EnergyPrecision", "energy_precision"]

#: Unit round-off of float32 (as in conformance.judge.precision, kept local: no import cycle).
_U32 = 2.0**-24

#: Observed imbalance / float32's expected imbalance above which the error looks like float32
#: rounding. Float32 rounding gives about 0.5 to 1; a systematic error in double about 1e-8.
BALANCE_RATIO = 0.05


@dataclass(frozen=True)
class Signature:
    """balance: RMS over the balance sums (force components, rows of K by column component) of
    the error's sum divided by what float32 rounding of the summed values would leave (about 1
    for float32 round-off, about 0 for a systematic error); samples: how many sums it pools;
    representable: fraction of the engine's nonzero values exactly representable in float32.
    """

    balance: float
    samples: int
    representable: float

    @property
    def float32_like(self) -> bool:
        return bool(np.isfinite(self.balance) and self.balance >= BALANCE_RATIO)

    def text(self) -> str:
        store = (
            f"{100 * self.representable:.0f} % of the engine's values are exactly float32 numbers"
        )
        if self.float32_like:
            return (
                f"the error breaks the balance of the forces and of K's rows as float32 rounding "
                f"does ({self.balance:.2g} of float32's expected imbalance over {self.samples} "
                f"sums); {store}"
            )
        return (
            f"the error keeps the balance of the forces and of K's rows (sum over the nodes) to "
            f"{self.balance:.1e} of what float32 rounding would break: it is systematic, a "
            f"mistake in the formula rather than round-off; {store}"
        )

    def to_dict(self) -> dict:
        return {
            "balance": float(self.balance),
            "samples": int(self.samples),
            "representable": float(self.representable),
        }


def _row_sums_by_component(K: sp.csr_matrix) -> np.ndarray:
    """(3n, 3): sum over nodes b of K[r, 3b + j] for each row r and column component j."""
    C = sp.coo_matrix(K)
    out = np.zeros((K.shape[0], 3))
    np.add.at(out, (C.row, C.col % 3), C.data)
    return out


def signature(f: np.ndarray, K: sp.spmatrix, f_o: np.ndarray, K_o: sp.spmatrix) -> Signature:
    """The balance and storage signature of the engine's error (f (n, 3), K (3n, 3n) against
    the oracle's f_o, K_o).
    """
    f = np.asarray(f, dtype=np.float64)
    f_o = np.asarray(f_o, dtype=np.float64)
    K = sp.csr_matrix(K, dtype=np.float64)
    K_o = sp.csr_matrix(K_o, dtype=np.float64)
    observed, expected = [], []
    # Forces: one sum per component.
    df = f - f_o
    observed.append(df.sum(axis=0))
    expected.append(_U32 * np.sqrt(np.sum(f_o**2, axis=0) / 3.0))
    # Stiffness: one sum per row and column component.
    D = (K - K_o).tocsr()
    observed.append(_row_sums_by_component(D).ravel())
    K2 = K_o.multiply(K_o).tocsr()
    expected.append(_U32 * np.sqrt(_row_sums_by_component(K2).ravel() / 3.0))
    obs = np.concatenate(observed)
    exp_ = np.concatenate(expected)
    keep = exp_ > 0
    if not np.any(keep):
        balance = float("nan")
    else:
        balance = float(np.sqrt(np.mean((obs[keep] / exp_[keep]) ** 2)))
    values = np.concatenate([f.ravel(), K.data])
    values = values[values != 0]
    representable = (
        float(np.mean(values.astype(np.float32).astype(np.float64) == values))
        if values.size
        else 0.0
    )
    return Signature(balance, int(np.count_nonzero(keep)), representable)


# ------------------------------------------------------------------ the energy alone
@dataclass(frozen=True)
class EnergyPrecision:
    """The energy's error against float32's rounding (force and stiffness right).

    relative: |W - W_o| / |W_o|; in_units: that in float32 unit round-offs (2^-24);
    representable: W is exactly a float32 number (a double result is one with odds 2^-29).
    """

    relative: float
    in_units: float
    representable: bool

    @property
    def float32(self) -> bool:
        """Stored as float32 and off by float32's rounding of a sum (at most 10 u32, more than
        double's): named. A float32 number off by more is a mistake stored in float32.
        """
        return self.representable and 1e-12 < self.relative <= 10 * _U32

    @property
    def float32_size(self) -> bool:
        """Not stored as float32, but off by float32's rounding size (u32/10 to 10 u32)."""
        return not self.representable and _U32 / 10 <= self.relative <= 10 * _U32


def energy_precision(W: float, W_o: float) -> EnergyPrecision:
    """Whether the energy W's error against W_o (J) is float32's rounding."""
    W, W_o = float(W), float(W_o)
    rel = abs(W - W_o) / abs(W_o) if W_o else float("inf")
    return EnergyPrecision(rel, rel / _U32, bool(np.float64(np.float32(W)) == W))
