"""The fluid phase of the porous liver model (paper, section 3.2, eq. 6).

A nodal (P1) fluid pressure P on the rest mesh obeys the linear Darcy law

    (1/K_lim) dP/dt = kappa laplacian P - (dJ/dt) / J,

so compressing the tissue (dJ/dt < 0) raises P, which then diffuses. The fluid adds the
volumetric Cauchy stress -P Id to the solid's: sigma_p = sigma - P.

Discretisation (total Lagrangian: kappa and the Laplacian live on the rest mesh, so both
matrices are built once, as the paper keeps kappa constant "to decrease the computational
cost"). Galerkin P1 in space, semi-implicit in time: implicit diffusion, explicit source
from the change of each cell's J over the accepted step,

    (M / K_lim + dt kappa L) P^{n+1} = (M / K_lim) P^n - s,    s_i = sum_c (V_c / 4) ln(J_c^{n+1} /
    J_c^n),

with M the P1 mass matrix (consistent, or lumped), L the P1 stiffness (Laplacian) matrix and
ln(J^{n+1}/J^n) the exact integral over the step of dJ/dt / J; the cellwise source lands on
its four nodes with weight V_c/4, which is its exact P1 load vector.

Boundary conditions: zero flux (grad P . n = 0, the natural condition) everywhere by default,
i.e. a sealed capsule; P = 0 on ``drained_nodes`` (e.g. where blood leaves through the vena
cava, or the free top of a Terzaghi column).

Coupling force. At fixed P, the pressure's contribution to the energy is -sum_c V_c Pbar_c J_c
(Pbar_c the mean of the cell's four nodal pressures, the exact cell integral of the P1 field),
whose Cauchy stress is -P Id. Its force is f_a = sum_c V_c Pbar_c dJ_c/dx_a and its stiffness
-sum_c V_c Pbar_c d2J_c/dx_a dx_b. It is declared as the MJED term -Pbar_c (J - 1)
(:class:`LinearJ` with a per-cell coefficient) and evaluated by the generic engine;
:class:`FluidPressureForce` is an integrator model that gives both and advances P when a
step is accepted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, Optional, Tuple, Union

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mjed.forcefield import HyperelasticForceField
from mjed.kinematics import deformation_gradient
from mjed.materials.base import Material
from mjed.mesh import TetMesh
from mjed.terms import JFunction, Term, TermGroup, Unity

__all__ = [
    "DarcyParameters",
    "p1_mass_matrix",
    "p1_stiffness_matrix",
    "cell_source",
    "PressureSolver",
    "FluidPressureForce",
    "cell_jacobians",
    "LinearJ",
]


@dataclass(frozen=True)
class DarcyParameters:
    """K_lim: the fluid's bulk modulus (Pa, > 0); kappa: permeability (m^4 / (N s), >= 0,
    0 is undrained: no diffusion).
    """

    K_lim: float
    kappa: float

    def __post_init__(self):
        for name, lower, strict in (("K_lim", 0.0, True), ("kappa", 0.0, False)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise ValueError(
                    f"DarcyParameters: parameter {name} must be a finite real number, got {v!r}"
                )
            if v < lower or (strict and v == lower):
                raise ValueError(
                    f"DarcyParameters: parameter {name} must be {'>' if strict else '>='} 0, got "
                    f"{v!r}"
                )


# ------------------------------------------------------------------------- P1 matrices
def _scalar_assemble(cells: np.ndarray, n: int, element: np.ndarray) -> sp.csr_matrix:
    """Sum (m, 4, 4) element matrices into CSR (n, n)."""
    rows = np.broadcast_to(cells[:, :, None], element.shape).ravel()
    cols = np.broadcast_to(cells[:, None, :], element.shape).ravel()
    A = sp.coo_matrix((element.ravel(), (rows, cols)), shape=(n, n)).tocsr()
    A.sum_duplicates()
    return A


def p1_mass_matrix(mesh: TetMesh, *, lumped: bool = False) -> sp.csr_matrix:
    """M_ij = int N_i N_j dX on the rest mesh, CSR (n, n).

    Exact P1 element mass: V/20 (1 + delta_ab). ``lumped``: row sums on the diagonal (V/4 per
    cell and node).
    """
    V = mesh.volumes
    if lumped:
        diag = np.bincount(
            mesh.cells.ravel(), weights=np.repeat(V / 4.0, 4), minlength=mesh.n_nodes
        )
        return sp.diags(diag, format="csr")
    local = (np.ones((4, 4)) + np.eye(4)) / 20.0
    return _scalar_assemble(mesh.cells, mesh.n_nodes, V[:, None, None] * local)


def p1_stiffness_matrix(mesh: TetMesh) -> sp.csr_matrix:
    """L_ij = int grad N_i . grad N_j dX on the rest mesh, CSR (n, n): V D_a . D_b per cell."""
    element = mesh.volumes[:, None, None] * np.einsum("mai,mbi->mab", mesh.D, mesh.D)
    return _scalar_assemble(mesh.cells, mesh.n_nodes, element)


def cell_jacobians(mesh: TetMesh, x: np.ndarray) -> np.ndarray:
    """J per cell at positions x (n, 3), (m,)."""
    return np.linalg.det(deformation_gradient(np.asarray(x, dtype=float)[mesh.cells], mesh.D))


def cell_source(mesh: TetMesh, J_old: np.ndarray, J_new: np.ndarray) -> np.ndarray:
    """s_i = sum_c (V_c / 4) ln(J_new / J_old) over the cells of node i, (n,).

    Raises:
        ValueError: a non-finite or non-positive J (an inverted cell has no volume ratio).
    """
    for name, J in (("J_old", J_old), ("J_new", J_new)):
        J = np.asarray(J)
        if J.shape != (mesh.n_cells,):
            raise ValueError(f"{name} must have shape ({mesh.n_cells},), got {J.shape}")
        bad = np.flatnonzero(~(np.isfinite(J) & (J > 0)))
        if len(bad):
            raise ValueError(
                f"{name}: {len(bad)} cell(s) with J <= 0 or non-finite; first is cell {bad[0]} (J "
                f"= {J[bad[0]]!r})"
            )
    r = np.log(np.asarray(J_new) / np.asarray(J_old)) * (mesh.volumes / 4.0)
    return np.bincount(mesh.cells.ravel(), weights=np.repeat(r, 4), minlength=mesh.n_nodes)


# ------------------------------------------------------------------------- the solver
class PressureSolver:
    """The semi-implicit Darcy step on one mesh (see the module docstring).

    Args:
        mesh: the rest mesh.
        params: K_lim and kappa.
        drained_nodes: node indices where P = 0 (Dirichlet); None or empty: zero flux everywhere.
        lumped_mass: lump the mass matrix (diagonal) instead of the consistent P1 mass.

    Attributes:
        M, L: the P1 mass and stiffness (Laplacian) matrices, CSR (n, n).
    """

    def __init__(
        self,
        mesh: TetMesh,
        params: DarcyParameters,
        *,
        drained_nodes=None,
        lumped_mass: bool = False,
    ):
        if not isinstance(params, DarcyParameters):
            raise TypeError(f"params must be DarcyParameters, got {type(params).__name__}")
        self.mesh = mesh
        self.params = params
        n = mesh.n_nodes
        drained = np.unique(
            np.asarray([] if drained_nodes is None else drained_nodes, dtype=np.int64).ravel()
        )
        if len(drained) and (drained.min() < 0 or drained.max() >= n):
            raise ValueError(
                f"drained_nodes must lie in [0, {n}), got range [{drained.min()}, {drained.max()}]"
            )
        self.drained = drained
        free = np.ones(n, dtype=bool)
        free[drained] = False
        self._free = np.flatnonzero(free)
        self.M = p1_mass_matrix(mesh, lumped=lumped_mass)
        self.L = p1_stiffness_matrix(mesh)
        self._Mf = self.M[self._free][:, self._free].tocsc()
        self._Lf = self.L[self._free][:, self._free].tocsc()
        self._solvers: Dict[float, Callable[[np.ndarray], np.ndarray]] = {}

    def _solve_with(self, dt: float) -> Callable[[np.ndarray], np.ndarray]:
        # One factorisation per time step size, kept: the integrator's dt rarely changes.
        if dt not in self._solvers:
            A = self._Mf / self.params.K_lim + (dt * self.params.kappa) * self._Lf
            self._solvers[dt] = spla.factorized(A.tocsc())
        return self._solvers[dt]

    def step(self, P: np.ndarray, J_old: np.ndarray, J_new: np.ndarray, dt: float) -> np.ndarray:
        """P^{n+1} from P^n (n,) and the cells' J before and after the step (m,). Pure.

        Raises:
            ValueError: dt not finite and > 0, P of the wrong shape or not finite, invalid J.
        """
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        P = np.asarray(P, dtype=float)
        if P.shape != (self.mesh.n_nodes,) or not np.all(np.isfinite(P)):
            raise ValueError(f"P must be a finite array of shape ({self.mesh.n_nodes},)")
        s = cell_source(self.mesh, J_old, J_new)
        out = np.zeros_like(P)
        f = self._free
        rhs = self._Mf @ P[f] / self.params.K_lim - s[f]
        if len(f):
            out[f] = self._solve_with(float(dt))(rhs)
        return out


# ------------------------------------------------------------------------- the coupling force
@dataclass(frozen=True, eq=False)
class LinearJ(JFunction):
    """f = c (J - 1): a volumetric term linear in J, zero at rest, of Cauchy pressure c.

    Args:
        coefficient: c, a float or a per-cell (m,) array. An array is held by reference, not
            copied: whoever owns it may rewrite it in place between evaluations (how
            :class:`FluidPressureForce` makes the term follow the pressure without rebuilding
            the engine).
    """

    coefficient: Union[float, np.ndarray]

    def __call__(self, J):
        c = self.coefficient
        return c * (J - 1.0), c, 0.0  # f'' is the scalar 0: the engine then skips d_a (x) d_b


@dataclass(frozen=True, eq=False)
class _CallableJ(JFunction):
    """Any callable J -> (U, U', U'') as a JFunction (the ``solid`` argument's protocol)."""

    function: Callable

    def __call__(self, J):
        return self.function(J)


@dataclass(frozen=True, eq=False)
class _PressureCoupling(Material):
    """sum of V_c (-Pbar_c (J_c - 1) + U(J_c)): the fluid's energy at fixed P, plus the porous
    solid's U when given, as one term group (one engine pass).
    """

    pressure: LinearJ
    solid: Optional[JFunction] = None

    def decomposition(self) -> Tuple[TermGroup, ...]:
        terms = (Term(self.pressure, Unity()),)
        if self.solid is not None:
            terms += (Term(self.solid, Unity()),)
        return (TermGroup(terms),)


class FluidPressureForce:
    """The fluid phase as an integrator model: the force of a fixed nodal pressure P, and the
    Darcy update of P each time a step is accepted.

    Force and stiffness come from the MJED engine (:class:`mjed.HyperelasticForceField`) with
    the per-cell term -Pbar_c (J - 1) (:class:`LinearJ`, its coefficient rewritten whenever P
    is set), so the pressure is a declared term like any other, not a separate assembler.

    Args:
        mesh: the rest mesh.
        params: K_lim and kappa.
        solid: optionally the porous solid's volumetric energy U(J) (a
            :class:`mjed.porous.PorousVolume`, or any function of J returning U, U', U''),
            evaluated in the same pass: the model's energy is then sum_c V_c (U(J_c) - Pbar_c J_c),
            the whole volumetric stress sigma_p = sigma - P of the paper.
        drained_nodes: P = 0 there (see :class:`PressureSolver`); default zero flux everywhere.
        x0: positions at which P = 0 initially (the rest state by default); its J is the
            reference of the first step's source.
        lumped_mass: lumped instead of consistent mass in the pressure step.

    Attributes:
        P: (n,) current nodal pressure (Pa); read-only array, assign a new one to change it.
        solver: the :class:`PressureSolver`.
        field: the :class:`mjed.HyperelasticForceField` of the coupling term (and U).
    """

    def __init__(
        self,
        mesh: TetMesh,
        params: DarcyParameters,
        *,
        solid=None,
        drained_nodes=None,
        x0: Optional[np.ndarray] = None,
        lumped_mass: bool = False,
    ):
        if solid is not None and not isinstance(solid, JFunction):
            if not callable(solid):
                raise TypeError(
                    "solid must be a function of J returning (U, U', U''), got "
                    f"{type(solid).__name__}"
                )
            solid = _CallableJ(solid)
        self.mesh = mesh
        self.solid = solid
        self.solver = PressureSolver(
            mesh, params, drained_nodes=drained_nodes, lumped_mass=lumped_mass
        )
        self._coefficient = np.zeros(
            mesh.n_cells
        )  # -Pbar_c, the LinearJ's array (rewritten in place)
        # J <= 0 is evaluated, not refused, as the fluid's terms stay finite there; the solid
        # force field of the same integrator is the one that refuses inverted cells.
        self.field = HyperelasticForceField(
            mesh, _PressureCoupling(LinearJ(self._coefficient), solid), allow_inverted=True
        )
        self.P = np.zeros(mesh.n_nodes)
        self._J = cell_jacobians(mesh, mesh.points if x0 is None else x0)

    @property
    def P(self) -> np.ndarray:
        """(n,) current nodal pressure (Pa), read-only."""
        return self._P

    @P.setter
    def P(self, value) -> None:
        P = np.array(value, dtype=float)
        if P.shape != (self.mesh.n_nodes,) or not np.all(np.isfinite(P)):
            raise ValueError(
                f"P must be a finite array of shape ({self.mesh.n_nodes},), got shape {P.shape}"
            )
        P.setflags(write=False)  # an in-place edit would bypass the coefficient update below
        self._P = P
        # Pbar_c, the mean of the cell's nodal pressures, is the exact cell integral of P1 P.
        np.negative(P[self.mesh.cells].mean(axis=1), out=self._coefficient)

    @property
    def J_accepted(self) -> np.ndarray:
        """(m,) cell J at the last accepted state."""
        return self._J

    def force_and_stiffness(self, x: np.ndarray) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Force (n, 3) at positions x and the stiffness, at the current (fixed) pressure."""
        return self.field.force_and_stiffness(x)

    def save_history(self):
        """A copy of what accepted steps change (P and the accepted J), for restore_history:
        the integrator rolls the fluid back when a step it split into substeps still fails.
        """
        return (self._P.copy(), self._J.copy())

    def restore_history(self, saved) -> None:
        """Go back to a state returned by save_history()."""
        P, J = saved
        self.P = P
        self._J = np.array(J, dtype=float)

    def accept_step(self, x: np.ndarray, dt: float) -> None:
        """Advance P over the accepted step that ended at positions x."""
        J = cell_jacobians(self.mesh, x)
        self.P = self.solver.step(self.P, self._J, J, dt)
        self._J = J
