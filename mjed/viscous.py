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
c = 1 - sum_i a_i, plus the force of the constant stress -Q:
f_a = -V (c F S_h D_a - F Q D_a), K_ab = c K_h,ab - V (D_a . Q D_b) I.

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

from mjed.edge_blocks import edge_blocks_to_element_matrices
from mjed.evaluation import CellEvaluation, Want
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
            raise ValueError(f"alphas and taus must have equal lengths, got {len(alphas)} and {len(taus)}")
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
        return 1.0 - sum(a * (dt / tau) / (1.0 + dt / tau - z) for a, tau in zip(self.alphas, self.taus))


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


class ViscoHyperelasticForceField:
    """A hyperelastic body whose S_h is relaxed by a Prony series (backward Euler history).

    Args:
        field: a HyperelasticForceField, or a TetMesh together with ``material``.
        material: the material when ``field`` is a mesh.
        prony: the Prony series.
        dt: optional step size; otherwise set by ``prepare_step(dt)`` before evaluating.
        regularize, allow_inverted: passed to HyperelasticForceField when built from a mesh.

    The history gamma_i is per cell, (p, m, 3, 3), zero at construction (the body starts
    relaxed at rest).
    """

    def __init__(self, field, material: Optional[Material] = None, *, prony: Prony, dt: Optional[float] = None,
                 regularize: bool = False, allow_inverted: bool = False):
        if isinstance(field, TetMesh):
            if material is None:
                raise ValueError("give a material with a mesh (or a HyperelasticForceField alone)")
            field = HyperelasticForceField(field, material, regularize=regularize, allow_inverted=allow_inverted)
        elif not isinstance(field, HyperelasticForceField):
            raise TypeError(f"field must be a HyperelasticForceField or a TetMesh, got {type(field).__name__}")
        elif material is not None:
            raise ValueError("material is given by the HyperelasticForceField; do not pass it again")
        if not isinstance(prony, Prony):
            raise TypeError(f"prony must be a Prony, got {type(prony).__name__}")
        self.field = field
        self.mesh = field.mesh
        self.prony = prony
        self.gammas = np.zeros((len(prony.alphas), self.mesh.n_cells, 3, 3))
        self.steps = 0
        self._saved: Optional[ViscousHistory] = None
        self._cache: Optional[Tuple[np.ndarray, CellEvaluation]] = None  # (x, evaluation) of the last accepted state
        # Rest shape vectors in the engine's component-major layout (3, 4, m) (mjed.layout).
        self._Dt = np.ascontiguousarray(self.mesh.D.transpose(2, 1, 0))
        self.dt: Optional[float] = None
        self._a = self._b = None
        if dt is not None:
            self.prepare_step(dt)

    # ---------------------------------------------------------------- time stepping
    def prepare_step(self, dt: float) -> None:
        """Set the step size of the coming step (the coefficients a_i, b_i depend on it)."""
        self._a, self._b = prony_coefficients(self.prony, dt)
        self.dt = float(dt)

    def accept_step(self, x, dt: Optional[float] = None) -> None:
        """Commit gamma_i^n = a_i S_h(x) + b_i gamma_i^(n-1) at the accepted positions x (n, 3)."""
        if dt is not None and dt != self.dt:
            self.prepare_step(dt)
        a, b = self._coefficients()
        x = self._check_positions(x)
        ev = self._hyperelastic(x)
        S = ev.pk2  # (m, 3, 3)
        self.gammas = a[:, None, None, None] * S[None] + b[:, None, None, None] * self.gammas
        self.steps += 1
        self._cache = (x.copy(), ev)  # the next step starts from x: its evaluation is reused

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
            raise ValueError(f"saved history has shape {saved.gammas.shape}, expected {self.gammas.shape}")
        self.gammas = saved.gammas.copy()
        self.steps = saved.steps

    def viscous_stress(self) -> np.ndarray:
        """Q = sum_i b_i gamma_i^(n-1), the history's stress in the coming step, (m, 3, 3)."""
        _, b = self._coefficients()
        return np.einsum("p,pmij->mij", b, self.gammas)

    # ---------------------------------------------------------------- forces
    def force(self, x) -> np.ndarray:
        """Nodal forces of S_v at fixed history, (n, 3)."""
        return self.field.assemble_force(self._gradient_and_blocks(x, stiffness=False)[0])

    def stiffness(self, x) -> sp.csr_matrix:
        """Consistent tangent at fixed history, CSR (3n, 3n)."""
        return self.field.assemble_stiffness(self._gradient_and_blocks(x, stiffness=True)[1])

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        grad, blocks = self._gradient_and_blocks(x, stiffness=True)
        return self.field.assemble_force(grad), self.field.assemble_stiffness(blocks)

    def element_forces(self, x) -> np.ndarray:
        """Per-cell nodal forces, (m, 4, 3)."""
        return -np.ascontiguousarray(self._gradient_and_blocks(x, stiffness=False)[0].transpose(2, 1, 0))

    def element_stiffness(self, x) -> np.ndarray:
        """Per-cell tangents at fixed history, (m, 12, 12)."""
        return edge_blocks_to_element_matrices(self._gradient_and_blocks(x, stiffness=True)[1].transpose(3, 2, 0, 1))

    def stress(self, x) -> np.ndarray:
        """S_v at x with the current history, per cell (m, 3, 3)."""
        a, _ = self._coefficients()
        return (1.0 - a.sum()) * self._hyperelastic(self._check_positions(x)).pk2 - self.viscous_stress()

    # ---------------------------------------------------------------- internals
    def _gradient_and_blocks(self, x, *, stiffness: bool):
        """dW_v/dx per cell (3, 4, m) and the edge blocks (3, 3, 6, m) (None if not asked), in
        the engine's component-major layout ([k, a, cell] and [r, c, edge, cell])."""
        a, _ = self._coefficients()
        c = 1.0 - a.sum()
        x = self._check_positions(x)
        ev = self._hyperelastic(x, stiffness=stiffness)
        Q = self.viscous_stress()  # (m, 3, 3)
        Dt, V = self._Dt, self.mesh.volumes
        # Everything component-major (contiguous (3, 3, m) and (3, 4, m)): the cell axis is the
        # inner loop of each product, several times faster than small (m, 3, 3) matrices.
        Q_t = np.ascontiguousarray(np.moveaxis(Q, 0, -1))
        F_t = np.ascontiguousarray(np.moveaxis(ev.F, 0, -1))
        FQ_t = np.einsum("ikm,kjm->ijm", F_t, Q_t)
        FQD = np.einsum("ijm,jam->iam", FQ_t, Dt)  # F Q D_a, (3, 4, m)
        grad = c * ev.gradient
        grad -= V * FQD
        if not stiffness:
            return grad, None
        # Geometric stiffness of the constant stress -Q: -V (D_a . Q D_b) I on each edge (a, b).
        QD = np.einsum("ijm,jam->iam", Q_t, Dt)  # (3, 4, m)
        DQD = np.einsum("iem,iem->em", Dt[:, EDGES[:, 0]], QD[:, EDGES[:, 1]])  # (6, m)
        DQD *= V
        blocks = c * ev.blocks  # (3, 3, 6, m)
        for r in range(3):
            blocks[r, r] -= DQD
        return grad, blocks

    def _hyperelastic(self, x: np.ndarray, stiffness: bool = True) -> CellEvaluation:
        """The hyperelastic field's gradient, S_h and (if asked) edge blocks at x (fresh
        arrays: the last accepted state's evaluation is kept and reused)."""
        if self._cache is not None and np.array_equal(self._cache[0], x):
            ev = self._cache[1]
            if ev.blocks is not None or not stiffness:
                return ev
        want = Want.GRADIENT | Want.STRESS | (Want.STIFFNESS if stiffness else Want(0))
        return self.field.evaluate(x, want=want)

    def _coefficients(self):
        if self._a is None:
            raise ValueError("the step size is not set: pass dt= or call prepare_step(dt) first")
        return self._a, self._b

    def _check_positions(self, x) -> np.ndarray:
        return checked_positions(x, self.mesh.n_nodes)
