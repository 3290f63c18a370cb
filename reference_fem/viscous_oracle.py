"""UFL oracle for one visco-hyperelastic (Prony) time step at fixed history.

Written from the paper's formulas (section 3.1) and nothing of mjed's:

    S_h = 2 dW/dC = F^-1 dW/dF            (W from reference_fem.energies, dW/dF by ufl.diff),
    gamma_i^n = a_i S_h + b_i gamma_i^(n-1),  a_i = dt alpha_i / (dt + tau_i), b_i = tau_i / (dt +
    tau_i),
    S_v = S_h - sum_i gamma_i^n,
    R[v] = int (F S_v) : grad v dx,        K = dR/du [du]  (UFL derivative, history fixed).

The history gamma_i^(n-1) is one DG0 tensor field per Prony term; dt and the coefficients are
dolfinx Constants. Results come back in the input numbering, with the project's signs:
force = -R, stiffness = K. One-point quadrature is exact on P1 (everything is constant per
cell). Serial only.
"""

from __future__ import annotations

from typing import Any, Sequence, Tuple

import numpy as np
import scipy.sparse as sp
import ufl

from reference_fem import compat
from reference_fem.energies import strain_energy_density
from reference_fem.numbering import build_mesh, compute_numbering
from reference_fem.sparse_map import CSRRenumbering
from reference_fem.validation import check_cells, check_points, check_positions

__all__ = ["ViscousUFLOracle"]


class ViscousUFLOracle:
    """Force and stiffness of one Prony step for ``material`` on (points, cells).

    Args:
        points: (n, 3) rest positions; cells: (m, 4) positively oriented P1 tetrahedra.
        material: a material dataclass (its type picks the UFL energy); a Costa frame
            must be None or one constant rotation.
        alphas, taus: the Prony series (read as plain numbers).
    """

    def __init__(
        self, points, cells, material: Any, alphas: Sequence[float], taus: Sequence[float]
    ):
        self._X = check_points(points)
        self._cells = check_cells(cells, self._X)
        self._alphas = np.asarray(alphas, dtype=float).ravel()
        self._taus = np.asarray(taus, dtype=float).ravel()
        if self._alphas.shape != self._taus.shape or self._alphas.size == 0:
            raise ValueError(
                f"alphas and taus must be non-empty and of equal length, got {alphas!r} and "
                f"{taus!r}"
            )
        self._material = material
        self.n_nodes, self.n_cells = len(self._X), len(self._cells)

        compat.import_dolfinx()
        self._mesh = build_mesh(self._X, self._cells)
        V = compat.vector_p1_space(self._mesh)
        self._numbering = compute_numbering(self._mesh, V, self._X, self._cells)
        T = compat.tensor_dg0_space(self._mesh)
        # Row-major 3x3 block of each dolfinx cell in a DG0 tensor function's array.
        self._cell_block = compat.cell_dofs(T, 1)[:, 0]

        self._u = compat.function(V, "u")
        self._history = [compat.function(T, f"gamma_{i}") for i in range(self._alphas.size)]
        self._dt = compat.constant(self._mesh, 1.0)

        F = ufl.variable(ufl.Identity(3) + ufl.grad(self._u))
        # Parameters as Constants: the compiled forms then serve every parameter set (FFCx cache).
        W = strain_energy_density(material, F, constant=self._constant)
        S_h = ufl.inv(F) * ufl.diff(W, F)  # = 2 dW/dC, since dW/dF = F S
        gammas = []
        for alpha_value, tau_value, previous in zip(self._alphas, self._taus, self._history):
            alpha, tau = self._constant(alpha_value), self._constant(tau_value)
            a = self._dt * alpha / (self._dt + tau)
            b = tau / (self._dt + tau)
            gammas.append(a * S_h + b * previous)
        S_v = S_h - sum(gammas)
        dx = ufl.Measure("dx", domain=self._mesh, metadata={"quadrature_degree": 1})
        R = ufl.inner(F * S_v, ufl.grad(ufl.TestFunction(V))) * dx
        K = ufl.derivative(R, self._u, ufl.TrialFunction(V))
        self._R, self._K = compat.compile_form(R), compat.compile_form(K)
        self._b, self._A = compat.create_vector(self._R), compat.create_matrix(self._K)
        self._renumber = CSRRenumbering(self._numbering.input_dof_of_dof, 3 * self.n_nodes)

    def _constant(self, value):
        return compat.constant(self._mesh, np.asarray(value, dtype=np.float64))

    def force_and_stiffness(self, x, history, dt: float) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Force (n, 3) and stiffness CSR (3n, 3n) at positions x (n, 3).

        Args:
            history: gamma_i^(n-1), (p, m, 3, 3), in the input cell order.
            dt: the step size (> 0).
        """
        history = np.asarray(history, dtype=np.float64)
        if (
            history.shape != (self._alphas.size, self.n_cells, 3, 3)
            or not np.isfinite(history).all()
        ):
            raise ValueError(
                f"history must be finite with shape ({self._alphas.size}, {self.n_cells}, 3, 3), "
                f"got {history.shape}"
            )
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        x = check_positions(x, self.n_nodes)
        self._u.x.array[:] = self._numbering.to_dof_order(x - self._X)
        compat.scatter_forward(self._u)
        for field, gamma in zip(self._history, history):
            field.x.array.reshape(-1, 9)[self._cell_block] = gamma[
                self._numbering.input_cell_of_cell
            ].reshape(-1, 9)
            compat.scatter_forward(field)
        self._dt.value = float(dt)

        compat.assemble_vector_into(self._b, self._R)
        compat.accumulate_ghosts(self._b)
        residual = self._b.array_r.copy()
        compat.assemble_matrix_into(self._A, self._K)
        K = self._renumber(*self._A.getValuesCSR())
        if not (np.isfinite(residual).all() and np.isfinite(K.data).all()):
            raise ValueError(
                "viscous UFL oracle: non-finite force or stiffness for "
                f"{type(self._material).__name__}"
            )
        return -self._numbering.to_input_order(residual), K
