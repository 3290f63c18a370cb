"""The viscous and the porous models with their state on the device, for
:class:`mjed.cuda.integrator.DeviceImplicitEuler`.

:func:`device_plan` reads a list of host force models and says which runs where: one body
on the device (a :class:`mjed.cuda.CudaForceField`, alone or as the body of a
:class:`mjed.viscous.ViscoHyperelasticForceField`) and optionally the fluid pressure of the
porous model (:class:`mjed.darcy.FluidPressureForce`, its solid U(J) a
:class:`mjed.porous.PorousVolume` or none), or why they cannot stay there.

:class:`DeviceViscous` holds the Prony history gamma_i (p, m, 3, 3) on the device: at each
evaluation the field's force and stiffness are scaled by c = 1 - sum a_i and the constant
stress -Q = -sum b_i gamma_i adds its force and stiffness; an accepted step's S_h is computed
by the field on the device and the history updated there. :class:`DeviceFluid` holds the
nodal pressure P and the cells' accepted J on the device: its coupling force and stiffness
(with the porous solid's U) are added at each evaluation; an accepted step's Darcy update
(source, right-hand side, matrix M / K_lim + dt kappa L laid out once on the node pattern)
is solved by the device CG (:class:`mjed.cuda.solvers.DeviceCG`) to :data:`PRESSURE_TOL`,
where the host factorises it. Kernels: :mod:`mjed.cuda.model_kernels`.

The host model objects keep the state they had when the integrator was built until
:meth:`sync` (``DeviceImplicitEuler.sync_models``) copies the device state into them.
Importing this module does not import Numba; building an adapter does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence, Union

import numpy as np

from mjed.cuda.threads import REDUCTION_BLOCKS, THREADS_PER_BLOCK, blocks_for

__all__ = ["DevicePlan", "DeviceFluid", "DeviceViscous", "PRESSURE_TOL", "device_plan"]

#: Relative residual to which the device CG solves the Darcy step (the host factorises it):
#: the pressure then agrees with the host's to about this times the system's condition number.
PRESSURE_TOL = 1e-12

#: The Darcy CG's iteration cap: at least this many, or the number of nodes if larger.
PRESSURE_MAX_ITERATIONS = 2000


@dataclass(frozen=True)
class DevicePlan:
    """What a device step runs: the cuda field, the viscous model over it (or None), the fluid
    (or None), and the index of each in the models' list (for the step's timings).
    """

    field: object
    viscous: object
    fluid: object
    body_index: int
    fluid_index: Optional[int]


def _has_device_field(model) -> bool:
    return callable(getattr(model, "device_force_and_stiffness", None))


def device_plan(models: Sequence) -> Union[DevicePlan, str]:
    """The plan of a device step for these force models, or why they cannot stay on the
    device (a sentence).
    """
    from mjed.darcy import FluidPressureForce
    from mjed.porous import PorousVolume
    from mjed.viscous import ViscoHyperelasticForceField

    body, viscous, fluid, body_index, fluid_index = None, None, None, None, None
    for k, model in enumerate(models):
        name = type(model).__name__
        if isinstance(model, FluidPressureForce):
            if fluid is not None:
                return "two fluid pressure models (the device step takes one)"
            if model.solid is not None and not isinstance(model.solid, PorousVolume):
                return (
                    f"the fluid's solid U(J) is a {type(model.solid).__name__}, not a "
                    "PorousVolume (the only one with a device kernel)"
                )
            fluid, fluid_index = model, k
        elif isinstance(model, ViscoHyperelasticForceField):
            if not _has_device_field(model.field):
                return (
                    f"the viscous field's body {type(model.field).__name__} has no "
                    "device_force_and_stiffness (not a CudaForceField)"
                )
            if body is not None:
                return f"{len(models)} force models with two bodies (the device step takes one)"
            body, viscous, body_index = model.field, model, k
        elif _has_device_field(model):
            if any(hasattr(model, hook) for hook in ("prepare_step", "accept_step")):
                return f"the force model {name} updates a history on the host at each step"
            if body is not None:
                return f"{len(models)} force models with two bodies (the device step takes one)"
            body, body_index = model, k
        elif any(hasattr(model, hook) for hook in ("prepare_step", "accept_step")):
            return f"the force model {name} updates a history on the host at each step"
        else:
            return (
                f"the force model {name} has no device_force_and_stiffness (not a CudaForceField)"
            )
    if body is None:
        return "no force model with device_force_and_stiffness (a CudaForceField)"
    if fluid is not None:
        mesh = body.mesh
        if fluid.mesh.n_nodes != mesh.n_nodes or not np.array_equal(fluid.mesh.cells, mesh.cells):
            return "the fluid pressure's mesh is not the force field's"
    return DevicePlan(body, viscous, fluid, body_index, fluid_index)


class Geometry:
    """The mesh in float64 on the device and the field's block map, shared by the models."""

    def __init__(self, field, cuda):
        launcher = field.launcher
        mesh = field.mesh
        self.cells, self.blk, self.rowlen = launcher.cells, launcher.blk, launcher.rowlen
        if launcher.dtype == np.float64:
            self.D, self.V = launcher.D, launcher.V0
        else:
            self.D = cuda.to_device(np.ascontiguousarray(mesh.D, dtype=np.float64))
            self.V = cuda.to_device(np.ascontiguousarray(mesh.volumes, dtype=np.float64))
        self.grid = blocks_for(mesh.n_cells)


class DeviceViscous:
    """The Prony history of a :class:`mjed.viscous.ViscoHyperelasticForceField` on the device
    (module docstring): same equations as the host model, which it leaves untouched until
    :meth:`sync`.
    """

    THREADS = THREADS_PER_BLOCK

    def __init__(self, model, field, geometry: Geometry, cuda):
        from mjed.cuda import model_kernels

        self.model, self.field, self.geometry, self._cuda = model, field, geometry, cuda
        self._k = model_kernels
        m = field.mesh.n_cells
        self.gammas = cuda.to_device(np.ascontiguousarray(model.gammas, dtype=np.float64))
        self._pending = cuda.device_array(model.gammas.shape)
        self._Q = cuda.device_array((m, 3, 3))
        self._S = cuda.device_array((m, 3, 3), dtype=field.dtype)
        self.steps = model.steps
        self.scale = 1.0
        self._coefficients = {}  # dt -> (scale, a, b on the device): uploaded once per dt
        self._dt = None
        self._q_valid = False

    def prepare_step(self, dt: float) -> None:
        """The coefficients of a step of dt; Q = sum b_i gamma_i when dt or the history changed."""
        from mjed.viscous import prony_coefficients

        dt = float(dt)
        if dt not in self._coefficients:
            a, b = prony_coefficients(self.model.prony, dt)
            self._coefficients[dt] = (
                1.0 - float(a.sum()),
                self._cuda.to_device(a),
                self._cuda.to_device(b),
            )
        if dt != self._dt:
            self._q_valid = False
        self._dt = dt
        self.scale = self._coefficients[dt][0]
        if not self._q_valid:
            g = self.geometry
            self._k.prony_stress[g.grid, self.THREADS](
                self.gammas, self._coefficients[dt][2], self._Q
            )
            self._q_valid = True

    def add(self, x0, ue, f, K) -> None:
        """F += the force of -Q at x0 + ue, K += its stiffness (f, K float64 on the device,
        already holding c times the field's).
        """
        g = self.geometry
        self._k.history_force_stiffness[g.grid, self.THREADS](
            x0, ue, g.cells, g.D, g.V, self._Q, g.blk, g.rowlen, f, K
        )

    def advance(self, x1_field, dt: float) -> None:
        """The history of the accepted step ending at x1 (n, 3) in the field's dtype, pending
        until :meth:`commit`.
        """
        _, a, b = self._coefficients[float(dt)]
        self.field.device_stress(x1_field, out=self._S)
        self._k.prony_update[self.geometry.grid, self.THREADS](
            self.gammas, self._S, a, b, self._pending
        )

    def commit(self) -> None:
        self.gammas, self._pending = self._pending, self.gammas
        self.steps += 1
        self._q_valid = False

    def save_history(self):
        """A device copy of the history (nothing crosses to the host)."""
        saved = self._cuda.device_array(self.gammas.shape)
        saved.copy_to_device(self.gammas)
        return saved, self.steps

    def restore_history(self, saved) -> None:
        gammas, steps = saved
        self.gammas.copy_to_device(gammas)
        self.steps = steps
        self._q_valid = False

    def sync(self) -> None:
        """The host model's history := the device's (p m 9 x 8 bytes back)."""
        from mjed.viscous import ViscousHistory

        self.model.restore_history(ViscousHistory(self.gammas.copy_to_host(), self.steps))


class DeviceFluid:
    """The fluid pressure of a :class:`mjed.darcy.FluidPressureForce` on the device (module
    docstring): P and the accepted J there, its force and stiffness and the Darcy update; the
    host model is left untouched until :meth:`sync`.
    """

    THREADS = THREADS_PER_BLOCK

    def __init__(self, model, geometry: Geometry, cuda):
        from mjed.cuda import model_kernels, step_kernels
        from mjed.cuda.solvers import DeviceCG, DeviceCSR
        from mjed.linear_system import values_on_pattern

        self.model, self.geometry, self._cuda = model, geometry, cuda
        self._k, self._step_k = model_kernels, step_kernels
        solver = model.solver
        n = model.mesh.n_nodes
        L = solver.L.tocsr()
        L.sort_indices()
        mass = values_on_pattern(solver.M, L.indptr, L.indices, L.shape)
        if mass is None:  # the Laplacian holds every pair of a cell's nodes
            raise ValueError("DeviceFluid: the P1 mass is not inside the Laplacian's pattern")
        self._A = DeviceCSR(L.indptr, L.indices, cuda.device_array(L.nnz))
        self._mass = cuda.to_device(mass)
        self._laplacian = cuda.to_device(np.ascontiguousarray(L.data, dtype=np.float64))
        drained = np.zeros(n, dtype=np.uint8)
        drained[solver.drained] = 1
        self._drained = cuda.to_device(drained)
        self.K_lim, self.kappa = float(solver.params.K_lim), float(solver.params.kappa)
        law = model.solid
        if law is None:
            self._law = (False, 1.0, 0.0, 0.0, 0.0, 0.0)
        else:
            J0 = law.J0
            s0 = law.K0 * law.f_w * np.log((law.f_w + J0 - 1.0) / law.f_w)
            self._law = (True, law.f_w, law.K0, J0, float(s0), law.tangent_slope)
        self.P = cuda.to_device(np.asarray(model.P, dtype=np.float64))
        self.J = cuda.to_device(np.asarray(model.J_accepted, dtype=np.float64))
        self._P_new, self._J_new = cuda.device_array(n), cuda.device_array(model.mesh.n_cells)
        self._s, self._rhs = cuda.device_array(n), cuda.device_array(n)
        self._sums = cuda.device_array(2)
        self._cg = DeviceCG(n)
        self._matrix_dt = None
        self._rows = blocks_for(n)
        self._reduce_grid = blocks_for(n, REDUCTION_BLOCKS)
        self.max_iterations = max(PRESSURE_MAX_ITERATIONS, n)
        self.last_iterations = 0

    def add(self, x0, ue, f, K) -> None:
        """F += the coupling force at x0 + ue, K += its stiffness (float64 on the device)."""
        g = self.geometry
        self._k.fluid_force_stiffness[g.grid, self.THREADS](
            x0, ue, g.cells, g.D, g.V, self.P, *self._law, g.blk, g.rowlen, f, K
        )

    def advance(self, J_new, dt: float, step: int, t1: float) -> None:
        """P after the accepted step whose cells' J are J_new (device, (m,)), pending until
        :meth:`commit`.

        Raises:
            ValueError: as the host (:func:`mjed.darcy.cell_source`) for a J <= 0.
            IntegrationError: the Darcy CG did not converge (its reason ``pressure_cg_<why>``).
        """
        from mjed.darcy import cell_source
        from mjed.errors import IntegrationError

        k, sk, T, g = self._k, self._step_k, self.THREADS, self.geometry
        dt = float(dt)
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        sk.fill_zero[self._rows, T](self._s)
        sk.clear[1, 1](self._sums)
        k.darcy_source[g.grid, T](g.cells, g.V, self.J, J_new, self._s, self._sums)
        if self._sums.copy_to_host()[0]:  # the host's check names the cells (J copied back)
            cell_source(self.model.mesh, self.J.copy_to_host(), J_new.copy_to_host())
        A = self._A
        k.darcy_rhs[self._rows, T](
            A.indptr, A.indices, self._mass, self.P, self._s, self._drained, self.K_lim,
            self._rhs, self._P_new,
        )  # fmt: skip
        if self._matrix_dt != dt:
            k.darcy_matrix[self._rows, T](
                A.indptr, A.indices, self._mass, self._laplacian, self._drained, self.K_lim,
                dt * self.kappa, A.data,
            )  # fmt: skip
            self._matrix_dt = dt
        sk.clear[1, 1](self._sums)
        sk.norm_and_non_finite[self._reduce_grid, T](self._rhs, self._rhs, self._sums)
        rr, bad = self._sums.copy_to_host()
        if bad:
            raise IntegrationError(
                step, t1, "non_finite", "the Darcy right-hand side is not finite"
            )
        self.last_iterations = 0
        if rr == 0.0:
            sk.fill_zero[self._rows, T](self._P_new)
        else:
            iterations, converged, reason, res = self._cg.solve(
                A, self._rhs, self._P_new, float(np.sqrt(rr)), tol=PRESSURE_TOL,
                max_iterations=self.max_iterations,
            )  # fmt: skip
            self.last_iterations = iterations
            if not converged:
                raise IntegrationError(
                    step,
                    t1,
                    f"pressure_cg_{reason}",
                    f"the Darcy pressure's CG stopped on {reason.replace('_', ' ')} after "
                    f"{iterations} iterations (relative residual {res:.3g}, tolerance "
                    f"{PRESSURE_TOL:g})",
                )
        self._J_new.copy_to_device(J_new)

    def commit(self) -> None:
        self.P, self._P_new = self._P_new, self.P
        self.J, self._J_new = self._J_new, self.J

    def save_history(self):
        """Device copies of P and J (nothing crosses to the host)."""
        P, J = self._cuda.device_array(self.P.shape), self._cuda.device_array(self.J.shape)
        P.copy_to_device(self.P)
        J.copy_to_device(self.J)
        return P, J

    def restore_history(self, saved) -> None:
        P, J = saved
        self.P.copy_to_device(P)
        self.J.copy_to_device(J)

    def sync(self) -> None:
        """The host model's P and accepted J := the device's ((n + m) x 8 bytes back)."""
        self.model.restore_history((self.P.copy_to_host(), self.J.copy_to_host()))
