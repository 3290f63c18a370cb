"""Visco-hyperelasticity by a Prony series on the second Piola-Kirchhoff stress (paper, 3.1).

The relaxation function is alpha(t) = alpha_inf + sum_i alpha_i exp(-t / tau_i), with
alpha_inf + sum_i alpha_i = 1. The paper writes the visco-hyperelastic stress as

    S_v = S_h - sum_i gamma_i,
    gamma_i(t) = int_0^t alpha_i (1 - exp((t' - t) / tau_i)) dS_h/dt' dt',

and discretises gamma_i by backward Euler (tau_i dgamma_i/dt + gamma_i = alpha_i S_h):

    gamma_i^n = a_i S_h^n + b_i gamma_i^(n-1),  a_i = dt alpha_i / (dt + tau_i),
                                               b_i = tau_i / (dt + tau_i).

Within a step the history gamma_i^(n-1) is fixed, so

    S_v = (1 - sum_i a_i) S_h - Q,    Q = sum_i b_i gamma_i^(n-1)   (per cell, (3, 3)),

and the nodal force and consistent tangent are those of the hyperelastic body scaled by
c = 1 - sum_i a_i, plus those of the constant stress -Q:
f_a = -V (c F S_h D_a - F Q D_a), K_ab = c K_h,ab - V (D_a . Q D_b) I.

The second body's energy, -V Q : E, is quadratic in x (F is linear in x), so its tangent K_Q
(blocks -V (D_a . Q D_b) I) is constant within a step and its force is exactly -K_Q x:

    f_v = c f_h(x) - K_Q x,    K_v = c K_h(x) + K_Q.

K_Q is assembled once per step. The hyperelastic body is any field with the force,
stiffness and per-cell stress methods of :class:`mjed.HyperelasticForceField` (the NumPy
engine, or :class:`mjed.compiled.CompiledForceField`), used only through those methods.

The paper applies the series to the whole hyperelastic S_h (its S_h is the full second
Piola-Kirchhoff stress of W_h, volumetric part included; the Fig. 3 rheometer is St
Venant-Kirchhoff, whose S_h has no deviatoric/volumetric split), and so does this module.
The history moves only when a step is accepted (``accept_step``); it can be saved and
restored, e.g. to retry a failed step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np
import scipy.sparse as sp

from mjed.forcefield import HyperelasticForceField, checked_positions
from mjed.materials.base import Material
from mjed.mesh import TetMesh
from mjed.sparse import EDGES

__all__ = ["Prony", "ViscousHistory", "ViscoHyperelasticForceField", "prony_coefficients"]


@dataclass(frozen=True)
class Prony:
    """Normalised Prony series: alphas (alpha_i >= 0, sum < 1, dimensionless) and taus (s, > 0).

    alpha_inf = 1 - sum(alphas) is the fraction of S_h left at equilibrium; G(t) / G0 =
    alpha_inf + sum_i alpha_i exp(-t / tau_i).
    """

    alphas: Tuple[float, ...]
    taus: Tuple[float, ...]

    def __post_init__(self):
        alphas = tuple(float(a) for a in np.atleast_1d(np.asarray(self.alphas, dtype=float)))
        taus = tuple(float(t) for t in np.atleast_1d(np.asarray(self.taus, dtype=float)))
        if len(alphas) != len(taus):
            raise ValueError(
                f"alphas and taus must have equal lengths, got {len(alphas)} and {len(taus)}"
            )
        if not alphas:
            raise ValueError("a Prony series needs at least one term (alphas is empty)")
        for i, (a, t) in enumerate(zip(alphas, taus)):
            if not (np.isfinite(a) and a >= 0):
                raise ValueError(f"alphas[{i}] must be finite and >= 0, got {a!r}")
            if not (np.isfinite(t) and t > 0):
                raise ValueError(f"taus[{i}] must be finite and > 0, got {t!r}")
        if not sum(alphas) < 1.0:
            raise ValueError(f"sum(alphas) must be < 1 (alpha_inf > 0), got {sum(alphas)!r}")
        object.__setattr__(self, "alphas", alphas)
        object.__setattr__(self, "taus", taus)

    @property
    def alpha_inf(self) -> float:
        return 1.0 - sum(self.alphas)

    def relaxation(self, t) -> np.ndarray:
        """G(t) / G0 = alpha_inf + sum alpha_i exp(-t / tau_i), same shape as t."""
        t = np.asarray(t, dtype=float)
        return self.alpha_inf + sum(a * np.exp(-t / tau) for a, tau in zip(self.alphas, self.taus))

    def complex_modulus(self, omega) -> np.ndarray:
        """Continuous G*(omega) / G0 = 1 - sum alpha_i / (1 + i omega tau_i)."""
        w = np.asarray(omega, dtype=float)
        return 1.0 - sum(a / (1.0 + 1j * w * tau) for a, tau in zip(self.alphas, self.taus))

    def discrete_modulus(self, omega, dt: float) -> np.ndarray:
        """G*(omega) / G0 of the backward-Euler recursion sampled every dt (steady state).

        With z = exp(-i omega dt) and h_i = dt / tau_i: 1 - sum alpha_i h_i / (1 + h_i - z).
        Tends to complex_modulus as dt -> 0.
        """
        w = np.asarray(omega, dtype=float)
        z = np.exp(-1j * w * dt)
        return 1.0 - sum(
            a * (dt / tau) / (1.0 + dt / tau - z) for a, tau in zip(self.alphas, self.taus)
        )


def prony_coefficients(prony: Prony, dt: float) -> Tuple[np.ndarray, np.ndarray]:
    """a_i = dt alpha_i / (dt + tau_i) and b_i = tau_i / (dt + tau_i), each (p,)."""
    dt = float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    alphas, taus = np.asarray(prony.alphas), np.asarray(prony.taus)
    return dt * alphas / (dt + taus), taus / (dt + taus)


@dataclass(frozen=True)
class ViscousHistory:
    """A saved history: gammas (p, m, 3, 3) and the number of accepted steps behind it."""

    gammas: np.ndarray
    steps: int


#: What the viscous field asks of its hyperelastic body.
FIELD_METHODS = (
    "force",
    "stiffness",
    "force_and_stiffness",
    "stress",
    "force_stiffness_and_stress",
)


class ViscoHyperelasticForceField:
    """A hyperelastic body whose S_h is relaxed by a Prony series (backward Euler history).

    Args:
        field: a hyperelastic force field (:class:`mjed.HyperelasticForceField`, or any field
            with ``mesh``, ``pattern`` and the methods of FIELD_METHODS, e.g.
            ``mjed.make_force_field(mesh, material, backend="numba")``), or a TetMesh
            together with ``material`` (then the NumPy engine).
        material: the material when ``field`` is a mesh.
        prony: the Prony series.
        dt: optional step size; otherwise set by ``prepare_step(dt)`` before evaluating.
        regularize, allow_inverted: passed to HyperelasticForceField when built from a mesh.

    The history gamma_i is per cell, (p, m, 3, 3), zero at construction (the body starts
    relaxed at rest).
    """

    def __init__(
        self,
        field,
        material: Optional[Material] = None,
        *,
        prony: Prony,
        dt: Optional[float] = None,
        regularize: bool = False,
        allow_inverted: bool = False,
    ):
        if isinstance(field, TetMesh):
            if material is None:
                raise ValueError(
                    "give a material with a mesh (or a hyperelastic force field alone)"
                )
            field = HyperelasticForceField(
                field, material, regularize=regularize, allow_inverted=allow_inverted
            )
        elif material is not None:
            raise ValueError("material is given by the force field; do not pass it again")
        else:
            missing = [name for name in FIELD_METHODS if not callable(getattr(field, name, None))]
            if (
                missing
                or not isinstance(getattr(field, "mesh", None), TetMesh)
                or not hasattr(field, "pattern")
            ):
                raise TypeError(
                    "field must be a hyperelastic force field (mesh, pattern and "
                    f"{', '.join(FIELD_METHODS)}) or a TetMesh; {type(field).__name__} lacks "
                    f"{', '.join(missing) or 'a TetMesh mesh or a pattern'}"
                )
        if not isinstance(prony, Prony):
            raise TypeError(f"prony must be a Prony, got {type(prony).__name__}")
        self.field = field
        self.mesh = field.mesh
        self.prony = prony
        self.gammas = np.zeros((len(prony.alphas), self.mesh.n_cells, 3, 3))
        self.steps = 0
        self._saved: Optional[ViscousHistory] = None
        # (x, f_h, K_h) of the last accepted state: the next step starts there, so its first
        # force_and_stiffness is already computed (used once, then dropped).
        self._cache: Optional[Tuple[np.ndarray, np.ndarray, sp.csr_matrix]] = None
        self._KQ: Optional[sp.csr_matrix] = None  # the history's stiffness, rebuilt when Q changes
        self._Dt = np.ascontiguousarray(
            self.mesh.D.transpose(2, 1, 0)
        )  # rest shape vectors (3, 4, m)
        self.dt: Optional[float] = None
        self._a = self._b = None
        if dt is not None:
            self.prepare_step(dt)

    # ---------------------------------------------------------------- time stepping
    def prepare_step(self, dt: float) -> None:
        """Set the step size of the coming step (the coefficients a_i, b_i depend on it)."""
        a, b = prony_coefficients(self.prony, dt)
        if self.dt != float(dt):
            self._KQ = None
        self._a, self._b = a, b
        self.dt = float(dt)

    def accept_step(self, x, dt: Optional[float] = None) -> None:
        """Commit gamma_i^n = a_i S_h(x) + b_i gamma_i^(n-1) at the accepted positions x (n, 3)."""
        if dt is not None and dt != self.dt:
            self.prepare_step(dt)
        a, b = self._coefficients()
        x = self._check_positions(x)
        f, K, S = self.field.force_stiffness_and_stress(x)  # S: (m, 3, 3)
        self.gammas = a[:, None, None, None] * S[None] + b[:, None, None, None] * self.gammas
        self.steps += 1
        self._KQ = None
        self._cache = (x.copy(), f, K)

    def save_history(self) -> ViscousHistory:
        """A copy of the history (also kept, for restore_history() without an argument)."""
        self._saved = ViscousHistory(self.gammas.copy(), self.steps)
        return self._saved

    def restore_history(self, saved: Optional[ViscousHistory] = None) -> None:
        """Go back to a saved history (the last saved one by default)."""
        saved = self._saved if saved is None else saved
        if saved is None:
            raise ValueError("no saved history: call save_history() first")
        if saved.gammas.shape != self.gammas.shape:
            raise ValueError(
                f"saved history has shape {saved.gammas.shape}, expected {self.gammas.shape}"
            )
        self.gammas = saved.gammas.copy()
        self.steps = saved.steps
        self._KQ = None
        self._cache = None

    def viscous_stress(self) -> np.ndarray:
        """Q = sum_i b_i gamma_i^(n-1), the history's stress in the coming step, (m, 3, 3)."""
        _, b = self._coefficients()
        return np.einsum("p,pmij->mij", b, self.gammas)

    def history_stiffness(self) -> sp.csr_matrix:
        """L_Q, (n, n) CSR: the tangent of the constant stress -Q is K_Q = L_Q (x) Id, blocks
        -V (D_a . Q D_b) Id (mjed.sparse.CSRPattern.edge_scalar_matrix); its force is
        -K_Q x. Kept until the history or dt changes.
        """
        if self._KQ is None:
            # Component-major (cell axis last): each product runs over all cells at once, far
            # faster than an einsum over (m, 3, 3) matrices.
            Q = np.ascontiguousarray(np.moveaxis(self.viscous_stress(), 0, -1))  # (3, 3, m)
            Dt = self._Dt  # (3, 4, m)
            QD = sum(Q[:, j, None, :] * Dt[j, None] for j in range(3))  # (3, 4, m): Q D_a
            DQD = sum(Dt[k, EDGES[:, 0]] * QD[k, EDGES[:, 1]] for k in range(3))  # (6, m)
            DQD *= -self.mesh.volumes
            self._KQ = self.field.pattern.edge_scalar_matrix(DQD.T)
        return self._KQ

    # ---------------------------------------------------------------- forces
    def force(self, x) -> np.ndarray:
        """Nodal forces of S_v at fixed history, (n, 3)."""
        x = self._check_positions(x)
        return self._scale() * self.field.force(x) - self._history_force(x)

    def stiffness(self, x) -> sp.csr_matrix:
        """Consistent tangent at fixed history, CSR (3n, 3n)."""
        return self._combine(self.field.stiffness(self._check_positions(x)))

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        x = self._check_positions(x)
        cache, self._cache = self._cache, None
        if cache is not None and np.array_equal(cache[0], x):
            f, K = cache[1], cache[2]
        else:
            f, K = self.field.force_and_stiffness(x)
        return self._scale() * f - self._history_force(x), self._combine(K)

    def stress(self, x) -> np.ndarray:
        """S_v at x with the current history, per cell (m, 3, 3)."""
        return self._scale() * self.field.stress(self._check_positions(x)) - self.viscous_stress()

    # ---------------------------------------------------------------- internals
    def _scale(self) -> float:
        a, _ = self._coefficients()
        return 1.0 - float(a.sum())

    def _history_force(self, x: np.ndarray) -> np.ndarray:
        """K_Q x = L_Q x, (n, 3): minus the force of the constant stress -Q."""
        return self.history_stiffness() @ x

    def _combine(self, K: sp.csr_matrix) -> sp.csr_matrix:
        """C K + K_Q, in place in K (a fresh matrix with the field's pattern)."""
        pattern = self.field.pattern
        if K.nnz != pattern.nnz or not np.array_equal(K.indptr, pattern.indptr):
            raise ValueError(
                f"the force field's stiffness does not have its pattern's structure ({K.nnz} "
                f"entries, pattern {pattern.nnz}); the viscous field adds its history in place"
            )
        K.data *= self._scale()
        pattern.add_scalar_blocks(K.data, self.history_stiffness())
        return K

    def _coefficients(self):
        if self._a is None:
            raise ValueError("the step size is not set: pass dt= or call prepare_step(dt) first")
        return self._a, self._b

    def _check_positions(self, x) -> np.ndarray:
        return checked_positions(x, self.mesh.n_nodes)
