"""UFL oracle of the porous liver model: Hencky volumetric energy with tangent substitution,
optionally on top of a hyperelastic material, and the work of a fixed fluid pressure field.

Written from the formulas of the paper's section 3.2 (nothing here imports mjed):

    J* = (f_w + J - 1) / f_w,   sigma(J) = K0 f_w ln J*   (volumetric Cauchy stress),
    sigma replaced below J0 by its tangent line at J0,
    J0 = 1 - f_w + K0 / K_lim ("paper") or 1 - f_w + f_w K0 / K_lim ("slope").

A volumetric energy U(J) per rest volume has Cauchy stress dU/dJ, so U is the integral of
sigma from 1 to J:

    U = K0 f_w^2 (J* ln J* - J* + 1)                                   J > J0
    U = U(J0) + sigma(J0) (J - J0) + sigma'(J0) (J - J0)^2 / 2          J <= J0

A fluid pressure P (a P1 field held fixed) adds the Cauchy stress -P Id, i.e. the energy
density -P J: its first variation is the virtual work of -P Id on the current configuration.

The oracle assembles Pi = int (W_base + U + (-P J)) dX and lets UFL differentiate it, with
the base material's W from :mod:`reference_fem.energies` ("replace" means the base's bulk
term is dropped: its k0 is set to zero).
"""

from __future__ import annotations

import math
from typing import Any, Tuple

import numpy as np
import scipy.sparse as sp
import ufl

from reference_fem import compat
from reference_fem.diffusion_oracle import scalar_input_node_of_dof
from reference_fem.energies import strain_energy_density
from reference_fem.numbering import build_mesh, compute_numbering
from reference_fem.sparse_map import CSRRenumbering
from reference_fem.validation import check_cells, check_points, check_positions

__all__ = ["substitution_point", "porous_energy_density", "PorousOracle"]


def substitution_point(f_w: float, K0: float, K_lim: float, tangent: str = "paper") -> float:
    """J0 of the tangent substitution."""
    if tangent == "paper":
        return 1.0 - f_w + K0 / K_lim
    if tangent == "slope":
        return 1.0 - f_w + f_w * K0 / K_lim
    raise ValueError(f"tangent must be 'paper' or 'slope', got {tangent!r}")


def porous_energy_density(J, f_w: float, K0: float, K_lim: float, tangent: str = "paper"):
    """U(J) as a UFL expression (J a UFL scalar)."""
    J0 = substitution_point(f_w, K0, K_lim, tangent)
    # Numbers at J0, from the formula (plain floats).
    Js0 = (f_w + J0 - 1.0) / f_w
    U0 = K0 * f_w**2 * (Js0 * math.log(Js0) - Js0 + 1.0)
    s0 = K0 * f_w * math.log(Js0)
    k0 = K0 * f_w / (f_w + J0 - 1.0)
    # The log branch sees max(J, J0), so it stays finite where the linear branch is chosen.
    Js = (f_w + ufl.max_value(J, J0) - 1.0) / f_w
    U_log = K0 * f_w**2 * (Js * ufl.ln(Js) - Js + 1.0)
    U_lin = U0 + s0 * (J - J0) + 0.5 * k0 * (J - J0) ** 2
    return ufl.conditional(ufl.gt(J, J0), U_log, U_lin)


def _bulk_overrides(material: Any, mode: str) -> dict:
    """Parameter overrides of the base material: none to add, k0 = 0 to replace its bulk term
    (the material itself is not changed).
    """
    if mode == "add":
        return {}
    if mode != "replace":
        raise ValueError(f"mode must be 'add' or 'replace', got {mode!r}")
    if not hasattr(material, "k0"):
        raise ValueError(
            "replace mode needs a material with a bulk modulus k0, not "
            f"{type(material).__qualname__}"
        )
    return {"k0": 0.0}


class PorousOracle:
    """Energy, force (-dPi/dx) and stiffness of the porous model, in input numbering.

    Args:
        points, cells: the rest mesh (positively oriented P1 tetrahedra).
        porous: an object with attributes f_w, K0, K_lim and optionally tangent ("paper" by
            default), read by name (mjed's PorousVolume works), or None for no porous term.
        base: a material understood by :func:`reference_fem.strain_energy_density`, or None
            for the porous energy alone.
        mode: "add" or "replace" (base's k0 dropped).
        with_pressure: include the -P J term; set P with :meth:`set_pressure`.
    """

    def __init__(
        self,
        points,
        cells,
        *,
        porous: Any = None,
        base: Any = None,
        mode: str = "add",
        with_pressure: bool = False,
    ):
        self._X = check_points(points)
        self._cells = check_cells(cells, self._X)
        n = len(self._X)
        self._mesh = build_mesh(self._X, self._cells)
        self._V = compat.vector_p1_space(self._mesh)
        self._numbering = compute_numbering(self._mesh, self._V, self._X, self._cells)
        self._u = compat.function(self._V, "u")
        F = ufl.Identity(3) + ufl.grad(self._u)
        J = ufl.det(F)
        W = 0.0
        if porous is not None:
            law = [float(getattr(porous, k)) for k in ("f_w", "K0", "K_lim")]
            W = porous_energy_density(J, *law, getattr(porous, "tangent", "paper"))
        if base is not None:
            W = W + strain_energy_density(base, F, overrides=_bulk_overrides(base, mode))
        if porous is None and base is None and not with_pressure:
            raise ValueError(
                "PorousOracle: nothing to assemble (no porous law, base material or pressure)"
            )
        self._P = None
        if with_pressure:
            Q = compat.scalar_p1_space(self._mesh)
            self._P = compat.function(Q, "P")
            self._p_node = scalar_input_node_of_dof(self._mesh, Q, self._X)
            W = W - self._P * J  # the work of the Cauchy stress -P Id
        dx = ufl.Measure(
            "dx", domain=self._mesh, metadata={"quadrature_degree": 1}
        )  # integrand linear per cell: exact
        Pi = W * dx
        R = ufl.derivative(Pi, self._u, ufl.TestFunction(self._V))
        K = ufl.derivative(R, self._u, ufl.TrialFunction(self._V))
        self._Pi, self._R, self._K = (compat.compile_form(f) for f in (Pi, R, K))
        self._b = compat.create_vector(self._R)
        self._A = compat.create_matrix(self._K)
        self._renumber = CSRRenumbering(self._numbering.input_dof_of_dof, 3 * n)

    def set_pressure(self, P) -> None:
        """Nodal pressure (n,) in input order."""
        if self._P is None:
            raise ValueError(
                "this oracle was built without the pressure term (with_pressure=False)"
            )
        P = np.asarray(P, dtype=float)
        if P.shape != (len(self._X),):
            raise ValueError(f"pressure must have shape ({len(self._X)},), got {P.shape}")
        self._P.x.array[:] = P[self._p_node]
        compat.scatter_forward(self._P)

    def _set(self, x) -> None:
        xx = check_positions(x, len(self._X))
        self._u.x.array[:] = self._numbering.to_dof_order(xx - self._X)
        compat.scatter_forward(self._u)

    def energy(self, x) -> float:
        self._set(x)
        return compat.assemble_scalar_local(self._Pi)  # serial: the local part is the total

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """(f (n, 3), K CSR (3n, 3n)) with f = -dPi/dx and K = d2Pi/dx2."""
        self._set(x)
        compat.assemble_vector_into(self._b, self._R)
        compat.accumulate_ghosts(self._b)
        f = -self._numbering.to_input_order(self._b.array_r.copy())
        compat.assemble_matrix_into(self._A, self._K)
        return f, self._renumber(*self._A.getValuesCSR())
