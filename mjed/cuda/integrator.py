"""Implicit Euler with the whole step on the device: :class:`DeviceImplicitEuler`.

:class:`mjed.integrator.ImplicitEuler` with ``LinearSolverOptions(solver="cuda-cg")`` solves
on the device but builds each step on the host: the field's forces and CSR values come back,
the step matrix and the right-hand side are formed with SciPy, and the free block of A, its
right-hand side and first guess go to the device for the CG and the solution comes back.
:class:`DeviceImplicitEuler` takes the same arguments, runs the same equations (see
:mod:`mjed.integrator`: one linearised solve per step or Newton, Rayleigh damping, gravity,
external loads, fixed, idle and prescribed nodes, substeps on failure, the inversion and
volume-change checks, the same :class:`mjed.integrator.StepReport`) and keeps every vector
and matrix on the device (:mod:`mjed.cuda.step_kernels`):

- positions x, velocities v and the cells' J live on the device; ``x``, ``v`` read them back
  (and writing them uploads), only when asked;
- the field's ``device_force_and_stiffness`` leaves f and K's CSR values on the device; the
  mass matrix is laid on K's pattern once per mesh, so A = (1 + dt r_M) M + (dt^2 + dt r_K) K
  is one pass over the nnz values, and the right-hand side one pass over the rows;
- the constrained dofs (fixed, idle and prescribed nodes) keep the velocity the host gives
  them, and their rows and columns of A are the identity's with a zero right-hand side, so
  that CG on the whole system runs the iterations of the host's CG on the free block;
- CG (Jacobi, :class:`mjed.cuda.solvers.DeviceCG`) starts from the previous step's solution;
- the new positions, their J (inverted cells, volume change) and the constraint reactions are
  computed on the device.

What crosses to the host per step: the minimum J and the energy of the force kernel (16
bytes), the right-hand side norm with a count of non-finite forces (16), the CG's scalars (16
at the start, 32 per iteration), the counts of non-finite values, inverted cells and volume
jumps (24), and the reactions of the constrained dofs (8 bytes per constrained dof: the
StepReport's reaction); to the device, an external load (8 bytes per dof, only with
``external_force``) and the prescribed positions (24 bytes per prescribed node). A failed
check copies J back to name the cells, as the host does. docs/studies/timing.md ("Implicit
Euler on the device") counts the bytes for the 100k-tet liver against the host-built step.

The step stays on the device for one body with ``device_force_and_stiffness`` (a
:class:`mjed.cuda.CudaForceField`, FP64 or FP32: f and K are read in their dtype, every
other quantity is FP64), alone or as the body of a
:class:`mjed.viscous.ViscoHyperelasticForceField`, optionally with the porous model's
:class:`mjed.darcy.FluidPressureForce`, solved by ``solver="cuda-cg"``: the Prony history, the
fluid pressure and its Darcy update live on the device (:mod:`mjed.cuda.device_models`; the
sums of f and K are then float64; what they add per step crossing to the host: 32 bytes for
the viscous stress kernel, 48 + 32 per Darcy CG iteration for the fluid), and
:meth:`DeviceImplicitEuler.sync_models` copies them back into the host models. Anything else
(a viscous field over a NumPy body, another U(J), several bodies, another solver) is refused
by this class with the reason (:func:`device_refusal`); :func:`implicit_euler` then gives the
host integrator.
Importing this module does not import Numba; building the integrator does.
"""

from __future__ import annotations

import math
import time
from typing import Optional

import numpy as np

from mjed.cuda.threads import REDUCTION_BLOCKS, blocks_for
from mjed.errors import IntegrationError, InvertedElementError
from mjed.integrator import ImplicitEuler, LinearSolverOptions, StepTally
from mjed.linear_system import values_on_pattern
from mjed.mesh import TetMesh

__all__ = ["DeviceImplicitEuler", "device_refusal", "implicit_euler"]


def device_refusal(models, solver: LinearSolverOptions) -> Optional[str]:
    """Why a step with these force models and this solver cannot stay on the device, or None
    (:func:`mjed.cuda.device_models.device_plan`).
    """
    from mjed.cuda.device_models import device_plan

    models = (models,) if hasattr(models, "force_and_stiffness") else tuple(models)
    if solver.solver != "cuda-cg":
        return f"the linear solver is {solver.solver!r}, not the device CG ('cuda-cg')"
    plan = device_plan(models)
    return plan if isinstance(plan, str) else None


def implicit_euler(mesh, models, density, **options):
    """A :class:`DeviceImplicitEuler` when the models and the solver allow it
    (:func:`device_refusal`), else a :class:`mjed.integrator.ImplicitEuler`; same arguments.
    """
    solver = options.get("solver", LinearSolverOptions())
    if device_refusal(models, solver) is None:
        return DeviceImplicitEuler(mesh, models, density, **options)
    return ImplicitEuler(mesh, models, density, **options)


class DeviceImplicitEuler(ImplicitEuler):
    """:class:`mjed.integrator.ImplicitEuler` with the step on the device (module docstring).

    Same arguments; ``models`` is one CudaForceField and ``solver`` a
    ``LinearSolverOptions(solver="cuda-cg")`` (ValueError with the reason otherwise, see
    :func:`device_refusal`). ``x`` and ``v`` are host copies of the device state: writing
    into them changes nothing, assigning them does.

    Raises:
        BackendUnavailable: no CUDA device (nor the simulator).
    """

    on_device = True

    def __init__(self, mesh: TetMesh, models, density, **options):
        if not isinstance(mesh, TetMesh):
            raise TypeError(f"mesh must be an mjed.TetMesh, got {type(mesh).__name__}")
        why = device_refusal(models, options.get("solver", LinearSolverOptions()))
        if why is not None:
            raise ValueError(f"DeviceImplicitEuler: {why}; use mjed.integrator.ImplicitEuler")
        from mjed.cuda.availability import require_cuda

        self._cuda = cuda = require_cuda()
        from mjed.cuda import model_kernels, step_kernels

        self._k, self._model_kernels = step_kernels, model_kernels
        n3, m = 3 * mesh.n_nodes, mesh.n_cells
        # the state, set by ImplicitEuler.__init__ through the properties below
        self._x_d, self._v_d, self._J_d = (cuda.device_array(k) for k in (n3, n3, m))
        super().__init__(mesh, models, density, **options)
        from mjed.cuda.device_models import device_plan

        self._plan = device_plan(self.models)
        self._allocate()

    # ---------------------------------------------------------------- the state, on the device
    @property
    def x(self) -> np.ndarray:
        return self._x_d.copy_to_host().reshape(-1, 3)

    @x.setter
    def x(self, value) -> None:
        self._x_d.copy_to_device(np.ascontiguousarray(value, dtype=np.float64).ravel())

    @property
    def v(self) -> np.ndarray:
        return self._v_d.copy_to_host().reshape(-1, 3)

    @v.setter
    def v(self, value) -> None:
        self._v_d.copy_to_device(np.ascontiguousarray(value, dtype=np.float64).ravel())

    @property
    def _J(self) -> np.ndarray:
        return self._J_d.copy_to_host()

    @_J.setter
    def _J(self, value) -> None:
        self._J_d.copy_to_device(np.ascontiguousarray(value, dtype=np.float64))

    @property
    def device_models(self) -> tuple:
        """The models whose state lives on the device (:mod:`mjed.cuda.device_models`: the
        viscous history, the fluid pressure), in the order of ``models``.
        """
        return self._extras

    def sync_models(self, *models) -> None:
        """Copy the device state of the given host models (all by default) into them: the
        viscous field's history (``gammas``, ``steps``), the fluid's ``P`` and accepted J. Until
        then the host models hold the state they had when the integrator was built.
        """
        for adapter in self._extras:
            if not models or any(adapter.model is m for m in models):
                adapter.sync()

    def max_displacement(self) -> float:
        """The largest nodal |x_a - X_a|, reduced on the device (8 bytes back)."""
        k, out = self._k, self._sums
        k.clear[1, 1](out)
        k.max_displacement[self._reduce_grid, k.THREADS](self._x_d, self._X_d, out)
        return float(out.copy_to_host()[0])

    # ---------------------------------------------------------------- set-up
    def _allocate(self) -> None:
        """Everything a step needs on the device, once per integrator."""
        from mjed.cuda.device_models import DeviceFluid, DeviceViscous, Geometry
        from mjed.cuda.solvers import DeviceCG, DeviceCSR

        cuda, mesh, plan = self._cuda, self.mesh, self._plan
        field = plan.field
        n, n3, m = mesh.n_nodes, 3 * mesh.n_nodes, mesh.n_cells
        p = field.pattern
        mass = values_on_pattern(self.M, p.indptr, p.indices, p.shape)
        if mass is None:  # CSRPattern holds every node's diagonal block: never for a P1 mass
            raise ValueError("DeviceImplicitEuler: the mass matrix is not inside K's pattern")
        self._field = field
        self._A = DeviceCSR(p.indptr, p.indices, cuda.device_array(p.nnz))
        self._mass = cuda.to_device(mass)
        self._K = cuda.device_array(p.nnz, dtype=field.dtype)
        self._f = cuda.device_array((n, 3), dtype=field.dtype)
        self._xe = cuda.device_array((n, 3), dtype=field.dtype)
        self._fext = cuda.to_device(self.gravity_force.ravel())
        self._fext_is_gravity = True
        self._constrained_d = cuda.to_device(self.constrained.astype(np.uint8))
        index = self._A.indptr.dtype
        dofs = np.flatnonzero(self.constrained)
        self._dofs, self._dofs_host = cuda.to_device(dofs.astype(index)), dofs
        self._nodes = cuda.to_device(self.prescribed_nodes.astype(index))
        self._cells = cuda.to_device(np.ascontiguousarray(mesh.cells, dtype=index))
        # the viscous history and the fluid pressure, on the device; with either, the step reads
        # the summed force and stiffness in float64 (as the host sums them)
        self._viscous = self._fluid = None
        extras = []
        if plan.viscous is not None or plan.fluid is not None:
            geometry = Geometry(field, cuda)
            if plan.viscous is not None:
                self._viscous = DeviceViscous(plan.viscous, field, geometry, cuda)
                extras.append((plan.body_index, self._viscous))
            if plan.fluid is not None:
                self._fluid = DeviceFluid(plan.fluid, geometry, cuda)
                extras.append((plan.fluid_index, self._fluid))
        self._extras = tuple(adapter for _, adapter in sorted(extras, key=lambda e: e[0]))
        if self._extras and field.dtype != np.float64:
            self._f_tot, self._K_tot = cuda.device_array(n3), cuda.device_array(p.nnz)
        else:
            self._f_tot, self._K_tot = self._f.reshape(-1), self._K
        # a retry rolls the device histories back (ImplicitEuler's rollback of its models)
        self._stateful = list(self._extras)
        self._rollback = True
        self._six_volume = cuda.to_device(6.0 * mesh.volumes)
        self._X_d = cuda.to_device(np.ascontiguousarray(mesh.points, dtype=np.float64).ravel())
        self._vref, self._ue, self._rhs, self._b, self._dv = (
            cuda.device_array(n3) for _ in "12345"
        )
        self._warm_d, self._x1 = cuda.device_array(n3), cuda.device_array(n3)
        self._saved_x, self._saved_v = cuda.device_array(n3), cuda.device_array(n3)
        self._J1, self._saved_J = cuda.device_array(m), cuda.device_array(m)
        self._reaction = cuda.device_array(max(1, len(dofs)))
        self._sums = cuda.device_array(2)
        self._warm_valid = False
        self._cg = DeviceCG(n3)
        self._rows = blocks_for(n3)
        self._reduce_grid = blocks_for(n3, REDUCTION_BLOCKS)
        self._cell_grid = blocks_for(m, REDUCTION_BLOCKS)

    # ---------------------------------------------------------------- checkpoints
    def _checkpoint(self) -> tuple:
        """The accepted state copied on the device (no host traffic), and t."""
        self._saved_x.copy_to_device(self._x_d)
        self._saved_v.copy_to_device(self._v_d)
        self._saved_J.copy_to_device(self._J_d)
        return (self.t,)

    def _restore(self, saved: tuple) -> None:
        self._x_d.copy_to_device(self._saved_x)
        self._v_d.copy_to_device(self._saved_v)
        self._J_d.copy_to_device(self._saved_J)
        (self.t,) = saved

    # ---------------------------------------------------------------- the step
    def _scalars(self, count: int = 2) -> np.ndarray:
        return self._sums.copy_to_host()[:count]

    def _single(self, dt: float, step: int, tally: StepTally) -> None:
        """One backward Euler step of size dt on the device (ImplicitEuler._single's
        equations); commits it on success.
        """
        k, T, rows = self._k, self._k.THREADS, self._rows
        t1 = self.t + dt
        if self._viscous is not None:
            self._viscous.prepare_step(dt)
        if self.external_force is not None or not self._fext_is_gravity:
            # a load: the only per-step upload of a vector (or gravity back, the load removed)
            self._fext.copy_to_device(self.external_forces(step, t1))
            self._fext_is_gravity = self.external_force is None
        k.start_velocity[rows, T](self._v_d, self._constrained_d, self._vref, self._ue)
        if self.prescribed is not None:
            self._prescribe(dt, step, t1)
        a_M, b_K = 1.0 + dt * self.rayleigh_mass, dt * dt + dt * self.rayleigh_stiffness
        c_stiff = dt * (dt + self.rayleigh_stiffness)
        cg_total, r0_norm, newton_res, solves, reaction = 0, 0.0, None, 0, None
        residual = 0.0
        for it in range(1, self.newton_iterations + 2):
            self._evaluate_device(it, step, t1, tally)
            clock = time.perf_counter()
            k.right_hand_side[rows, T](
                self._A.indptr, self._A.indices, self._mass, self._K_tot, self._f_tot,
                self._fext, self._vref, self._v_d, self._ue, self._constrained_d, dt, a_M,
                c_stiff, self._rhs, self._b,
            )  # fmt: skip
            k.clear[1, 1](self._sums)
            k.norm_and_non_finite[self._reduce_grid, T](self._b, self._f_tot, self._sums)
            rr, bad = self._scalars()
            tally.system_seconds += time.perf_counter() - clock
            if bad:
                raise IntegrationError(step, t1, "non_finite", "the internal forces are not finite")
            r_norm = math.sqrt(rr)
            if it == 1:
                r0_norm = r_norm
            else:
                newton_res = self.newton_residual(it, r_norm, r0_norm, step, t1)
                if newton_res <= self.newton_tol:
                    reaction = self._reactions(0.0, 0.0, dt)
                    break
            clock = time.perf_counter()
            k.system_matrix[rows, T](
                self._A.indptr, self._A.indices, self._mass, self._K_tot, self._constrained_d, a_M,
                b_K, self._A.data,
            )  # fmt: skip
            tally.system_seconds += time.perf_counter() - clock
            clock = time.perf_counter()
            try:
                iterations, residual = self._solve_device(it, r_norm, step, t1)
            finally:
                tally.solve_seconds += time.perf_counter() - clock
            cg_total += iterations
            solves += 1
            reaction = self._reactions(a_M, b_K, dt)
            k.advance_velocity[rows, T](self._vref, self._dv, self._ue, dt)
            if it == 1:
                self._warm_d.copy_to_device(self._dv)
                self._warm_valid = True
            if self.newton_iterations == 1:
                break
        self._commit(dt, step, t1, tally)
        tally.solves += solves
        tally.cg += cg_total
        tally.residual = residual
        tally.newton_residual = newton_res
        tally.reaction = reaction

    def _prescribe(self, dt: float, step: int, t1: float) -> None:
        """The prescribed nodes' velocity over the step (24 bytes per node to the device)."""
        target = self.prescribed_positions(step, t1)
        k = len(target)
        self._k.prescribe[blocks_for(k), self._k.THREADS](
            self._nodes, self._cuda.to_device(target), self._x_d, dt, self._vref
        )

    def _evaluate_device(self, it: int, step: int, t1: float, tally: StepTally) -> None:
        """F and K's values at x0 + ue into the device buffers (16 bytes back)."""
        k = self._k
        k.positions[self._rows, k.THREADS](self._x_d, self._ue, self._xe.reshape(-1))
        if it > 1:  # x0 is finite; a Newton iterate need not be
            k.clear[1, 1](self._sums)
            k.non_finite[self._reduce_grid, k.THREADS](self._xe.reshape(-1), self._sums)
            if self._scalars(1)[0]:
                raise IntegrationError(
                    step, t1, "non_finite", "a Newton iterate has non-finite positions"
                )
        clock = time.perf_counter()
        plan = self._plan
        try:
            self._field.device_force_and_stiffness(self._xe, out=(self._f, self._K))
        except InvertedElementError as exc:
            raise IntegrationError(step, t1, "inverted", str(exc), cells=exc.cells) from exc
        finally:
            tally.model_seconds[plan.body_index] += time.perf_counter() - clock
        if not self._extras:
            return
        # the viscous scale c = 1 - sum a_i, into the float64 sums; then the history's and the
        # fluid's force and stiffness added by their kernels
        clock = time.perf_counter()
        c = 1.0 if self._viscous is None else self._viscous.scale
        if c != 1.0 or self._K_tot is not self._K:
            n3, nnz = self._f_tot.shape[0], self._K_tot.shape[0]
            mk = self._model_kernels
            f = self._f.reshape(-1)
            mk.scale_into[blocks_for(n3), k.THREADS](f, c, self._f_tot)
            mk.scale_into[blocks_for(nnz), k.THREADS](self._K, c, self._K_tot)
        if self._viscous is not None:
            self._viscous.add(self._x_d, self._ue, self._f_tot, self._K_tot)
        tally.model_seconds[plan.body_index] += time.perf_counter() - clock
        if self._fluid is not None:
            clock = time.perf_counter()
            self._fluid.add(self._x_d, self._ue, self._f_tot, self._K_tot)
            tally.model_seconds[plan.fluid_index] += time.perf_counter() - clock

    def _accept_models(self, dt: float, step: int, t1: float, tally: StepTally) -> None:
        """The viscous history and the fluid pressure after the accepted step ending at x1:
        each computed (pending), then all committed, so that a failure changes none.
        """
        if not self._extras:
            return
        plan, k = self._plan, self._k
        if self._viscous is not None:
            clock = time.perf_counter()
            n3 = self._x1.shape[0]
            self._model_kernels.cast_into[blocks_for(n3), k.THREADS](self._x1, self._xe.reshape(-1))
            try:
                self._viscous.advance(self._xe, dt)
            except InvertedElementError as exc:
                raise IntegrationError(step, t1, "inverted", str(exc), cells=exc.cells) from exc
            finally:
                tally.model_seconds[plan.body_index] += time.perf_counter() - clock
        if self._fluid is not None:
            clock = time.perf_counter()
            try:
                self._fluid.advance(self._J1, dt, step, t1)
            finally:
                tally.model_seconds[plan.fluid_index] += time.perf_counter() - clock
        for adapter in self._extras:
            adapter.commit()

    def _solve_device(self, it: int, r_norm: float, step: int, t1: float):
        """CG on the device for dv (into self._dv); returns (iterations, residual)."""
        opts = self.solver
        # CG returns its first guess untouched for a zero right-hand side: only warm-start
        # otherwise (as ImplicitEuler).
        if it == 1 and r_norm > 0 and self._warm_valid:
            self._dv.copy_to_device(self._warm_d)
        else:
            self._k.fill_zero[self._rows, self._k.THREADS](self._dv)
            if r_norm == 0.0:
                return 0, 0.0
        iterations, converged, reason, residual = self._cg.solve(
            self._A, self._b, self._dv, r_norm, tol=opts.cg_tol, max_iterations=opts.max_iterations
        )
        if not converged:
            raise IntegrationError(
                step,
                t1,
                f"cg_{reason}",
                f"CG stopped on {reason.replace('_', ' ')} after {iterations} iterations "
                f"(relative residual {residual:.3g}, tolerance {opts.cg_tol:g}, "
                f"{opts.preconditioner} preconditioner)",
            )
        return iterations, residual

    def _reactions(self, a: float, b: float, dt: float) -> np.ndarray:
        """(3n,) reactions on the host: computed on the device at the constrained dofs only,
        which alone cross (8 bytes each).
        """
        out = np.zeros(3 * self.mesh.n_nodes)
        count = len(self._dofs_host)
        if count:
            k = self._k
            k.reaction[blocks_for(count), k.THREADS](
                self._dofs, self._A.indptr, self._A.indices, self._mass, self._K_tot, a, b,
                self._dv, self._rhs, dt, self._reaction,
            )  # fmt: skip
            out[self._dofs_host] = self._reaction.copy_to_host()[:count]
        return out

    def _commit(self, dt: float, step: int, t1: float, tally: StepTally) -> None:
        """X1 = x0 + dt v, its checks (finite, inverted cells, volume change), then the state."""
        k, T = self._k, self._k.THREADS
        k.clear[1, 1](self._sums)
        k.new_positions[self._reduce_grid, T](self._x_d, self._vref, dt, self._x1, self._sums)
        if self._scalars(1)[0]:
            raise IntegrationError(
                step, t1, "non_finite", "the new positions or velocities are not finite"
            )
        c = 0.0 if self.max_volume_change is None else self.max_volume_change
        k.clear[1, 1](self._sums)
        k.jacobians[self._cell_grid, T](
            self._cells, self._six_volume, self._x1, self._J_d, c, self._J1, self._sums
        )
        inverted, jumps = (int(s) for s in self._scalars())
        if (inverted and not self.allow_inverted) or jumps:  # the host's checks name the cells
            self.check_jacobians(self._J, self._J1.copy_to_host(), step, t1)
        self._accept_models(dt, step, t1, tally)
        self._x_d, self._x1 = self._x1, self._x_d
        self._v_d, self._vref = self._vref, self._v_d
        self._J_d, self._J1 = self._J1, self._J_d
        self.t = t1
        tally.substeps += 1
        tally.inverted = inverted
