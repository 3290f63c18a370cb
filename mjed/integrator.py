"""Implicit (backward) Euler time integration with Jacobi-preconditioned conjugate gradients.

The scheme is SOFA's EulerImplicitSolver. With M the mass, D = r_M M + r_K K the Rayleigh
damping, f the internal forces (f = -dW/dx, summed over the force models), K = -df/dx their
stiffness and f_ext the external forces (gravity, optional loads), backward Euler is

    M (v1 - v0) = dt (f(x1) + f_ext - D v1),    x1 = x0 + dt v1.

Linearising f(x1) ~ f(x0) - K (x1 - x0) around the start of the step gives one linear solve
for the velocity increment dv = v1 - v0:

    A dv = dt (f(x0) + f_ext - D v0 - dt K v0),    A = M + dt D + dt^2 K
                                                     = (1 + dt r_M) M + (dt^2 + dt r_K) K.

That is the default (``newton_iterations=1``, SOFA's one linearised solve per step). With
``newton_iterations > 1`` the same system is re-linearised at the new positions
x = x0 + dt v until the residual

    r(v) = dt (f(x0 + dt v) + f_ext - D v) - M (v - v0)

falls below ``newton_tol`` times the first right-hand side; the first Newton iterate is exactly
the SOFA step. Both are written as one update: at a linearisation point x_e = x0 + u_e with
reference velocity v_ref, A dv = dt (f_e + f_ext - D v_ref - K (dt v_ref - u_e)) - M (v_ref - v0).

Linear solver: one frozen :class:`mjed.solvers.LinearSolverOptions` (``solver=``) holds every
setting. CG to the relative residual ``cg_tol``, preconditioned by

- ``"jacobi"`` (the default): 1 / diag(A);
- ``"block-jacobi"``: the inverse of A's 3x3 node blocks;
- ``"factorized"``: a sparse factorisation of A taken at some step and kept as the
  preconditioner of the following steps (A changes slowly from step to step), renewed at the
  next step once a solve needs more than ``refactor_iterations`` CG iterations, and at once
  (the solve repeated) if CG fails with a stale factor. Each factorisation certifies that the
  A it factors is positive definite (see :class:`mjed.solvers.SPDFactor`); between them CG's
  own curvature check p^T A p > 0 applies as with Jacobi. The tolerance, the convergence test
  and the errors are the CG's, whatever the preconditioner. ``factor_precision="single"``
  factorises in single precision (about half the time; CG itself stays in double precision);
  a single-precision factorisation that meets a non-positive pivot is redone in double
  precision before the step is refused.

``solver="direct"`` factorises A at every step instead (no CG: a comparison point;
``cg_iterations`` is then 0 and ``cg_residual`` the residual of the direct solve, which must
not exceed ``cg_tol``: reason "direct_residual" otherwise). The
factorisations of both options raise ``IntegrationError(reason="not_positive_definite")`` on a
non-positive pivot.

Steps that fail are retried in substeps. When a step fails (an inverted cell, CG stopping on
negative curvature or its iteration cap, a non-positive-definite factorisation, non-finite
forces, Newton not converging), it is taken again as two steps of dt/2, each of which may split
again, down to dt / 2^``max_halvings`` (default 3: at most 8 substeps in any part of the step).
Nothing of a failed attempt is kept: models are told to accept only a substep that succeeded,
and if the step still fails the positions, velocities, time and every model's history (through
its ``save_history()`` / ``restore_history(saved)`` hooks, e.g. the viscous history or the
fluid pressure) go back to the start of the step before the IntegrationError is raised, naming
the step, the reason and the substeps tried. A model with ``accept_step`` but without these
hooks cannot be rolled back, so its steps are not retried. ``max_halvings=0`` turns retries off.
Each :class:`StepReport` gives ``substeps`` (1 for a step taken whole) and ``retries`` (the
reasons that made it split).

A step can also be required to stay close to its starting point: with ``max_volume_change=c``
a step that changes the volume of some cell by more than a factor c fails (reason
"volume_jump") and is retried in substeps like the others. One linearised step (SOFA's) from a
state far from equilibrium can overshoot into a badly distorted state that no later step
recovers from (an organ hung from a few nodes, at 0.3 s); limiting the change per step is the
usual safeguard, and every step it splits is reported.

Inverted cells. By default a step whose new positions give J <= 0 in some cell is refused (and
retried). ``allow_inverted=True`` accepts such positions, as the paper's section 2.3 allows when
the strain energy stays finite at J <= 0 (see :mod:`mjed.inversion` for which materials
qualify; the force fields must then be built with ``allow_inverted=True`` too): each
StepReport counts the cells inverted at the end of the step (``inverted_cells``); nothing is
hidden.

Where the time goes: each StepReport has ``times`` (:class:`StepTimes`): the seconds spent in
each force model (its force and stiffness, and its ``accept_step``), building the system (the
right-hand side and the free block of A), the linear solve (factorisations included) and the
rest of the step.

Constraints are applied by projection: fixed nodes keep v = 0, prescribed nodes get the
velocity that brings them to their prescribed positions at the end of the step, and their dofs
are removed from the CG system. ``density=0`` drops inertia altogether (quasi-static stepping,
A = dt^2 K); the constraints must then hold the body.

Force models are any objects with ``force_and_stiffness(x) -> (f (n, 3), K CSR (3n, 3n))``
and, optionally, ``prepare_step(dt)`` (called once before the solves of each step) and
``accept_step(x, dt)`` (called once the step is accepted, with the new positions: viscous
history, pore pressure...). ``HyperelasticForceField`` and ``ViscoHyperelasticForceField``
both qualify.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, List, Optional, Protocol, Sequence, Tuple, Union, runtime_checkable

import numpy as np
import scipy.sparse as sp

from mjed.errors import IntegrationError, InvertedElementError
from mjed.linear_system import FreeBlock, sum_same_pattern
from mjed.mass import MASS_KINDS, mass_matrix
from mjed.mesh import TetMesh
from mjed.solvers import (
    FACTOR_PRECISIONS,
    LINEAR_SOLVERS,
    PRECONDITIONERS,
    CGResult,
    LinearSolverOptions,
    NotPositiveDefiniteError,
    SPDFactor,
    block_jacobi_preconditioner,
    conjugate_gradient,
)

__all__ = [
    "ForceModel",
    "Prescribed",
    "StepReport",
    "StepTimes",
    "StepTally",
    "IntegratorState",
    "ImplicitEuler",
    "LinearSolverOptions",
    "LINEAR_SOLVERS",
    "PRECONDITIONERS",
    "FACTOR_PRECISIONS",
    "RETRIED_REASONS",
]

#: Newton stops with "newton_diverged" when the residual grows beyond this factor of the first.
_DIVERGENCE_FACTOR = 1e8

#: IntegrationError reasons that a smaller step may cure, so the step is retried in substeps.
#: (A non-finite external load or prescribed displacement is the user's input: never retried.)
RETRIED_REASONS = frozenset(
    {
        "inverted",
        "cg_negative_curvature",
        "cg_max_iterations",
        "cg_non_finite",
        "cg_preconditioner_indefinite",
        "not_positive_definite",
        "direct_residual",
        "non_finite",
        "newton_diverged",
        "newton_max_iterations",
        "volume_jump",
    }
)


@runtime_checkable
class ForceModel(Protocol):
    """What ImplicitEuler needs from a force model (prepare_step/accept_step are optional)."""

    def force_and_stiffness(self, x: np.ndarray) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Forces (n, 3) and stiffness CSR (3n, 3n) at positions x (n, 3)."""


@dataclass(frozen=True)
class Prescribed:
    """Prescribed displacements of some nodes: x[nodes] = X[nodes] + displacement(t).

    nodes: (k,) node indices; displacement: callable t -> (k, 3) displacement from the rest
    positions at time t.
    """

    nodes: np.ndarray
    displacement: Callable[[float], np.ndarray]

    def __post_init__(self):
        nodes = np.unique(np.asarray(self.nodes, dtype=np.int64).ravel())
        if nodes.size == 0:
            raise ValueError("Prescribed.nodes is empty")
        if not callable(self.displacement):
            raise ValueError(
                f"Prescribed.displacement must be callable t -> (k, 3), got {self.displacement!r}"
            )
        object.__setattr__(self, "nodes", nodes)


@dataclass(frozen=True)
class StepTimes:
    """Wall-clock seconds of one step by phase (summed over its substeps and failed attempts).

    models: per force model, in the order given to the integrator: its force_and_stiffness
    calls and its accept_step. system: the right-hand side and the free block of A.
    solve: the linear solves, factorisations included. total: the whole step.
    """

    models: Tuple[float, ...]
    system: float
    solve: float
    total: float

    @property
    def rest(self) -> float:
        """What no phase above accounts for: constraints, gravity, checks, bookkeeping."""
        return max(0.0, self.total - sum(self.models) - self.system - self.solve)


@dataclass(frozen=True)
class StepReport:
    """What one accepted step did.

    step: its number (1 for the first); time: t at its end; newton_iterations: linear solves
    done; cg_iterations: CG iterations summed over them; cg_residual: the last CG relative
    residual; newton_residual: ||r|| / ||r_0|| at the end (None with one linearised solve);
    reaction: (n, 3) forces the constraints exert on the constrained nodes (zero elsewhere),
    from the balance of the last linear system; factorizations: sparse factorisations done in
    the step (the "factorized" preconditioner or the direct solver; 0 with Jacobi);
    substeps: the substeps that made up the step (1: taken whole); retries: the reason of each
    failed attempt that made it split, in order; inverted_cells: cells with J <= 0 at the end
    of the step (always 0 unless allow_inverted); times: where the step's time went.
    """

    step: int
    time: float
    newton_iterations: int
    cg_iterations: int
    cg_residual: float
    newton_residual: Optional[float]
    reaction: np.ndarray
    factorizations: int = 0
    substeps: int = 1
    retries: Tuple[str, ...] = ()
    inverted_cells: int = 0
    times: Optional[StepTimes] = None


@dataclass(frozen=True)
class IntegratorState:
    """A copy of the integrator's state: positions x (n, 3), velocities v (n, 3), time t, steps."""

    x: np.ndarray
    v: np.ndarray
    t: float
    steps: int


@dataclass
class StepTally:
    """What the substeps of one step add up to (mutable, one per step; what a step's _single
    fills in).
    """

    n_models: int
    substeps: int = 0
    solves: int = 0
    cg: int = 0
    factorizations: int = 0
    residual: float = 0.0
    newton_residual: Optional[float] = None
    reaction: Optional[np.ndarray] = None
    retries: List[str] = field(default_factory=list)
    inverted: int = 0
    model_seconds: Optional[np.ndarray] = None
    system_seconds: float = 0.0
    solve_seconds: float = 0.0

    def __post_init__(self):
        self.model_seconds = np.zeros(self.n_models)


class ImplicitEuler:
    """Backward Euler on a tetrahedral mesh; see the module docstring for the equations.

    Args:
        mesh: the rest mesh (for the mass, the rest positions and the inversion check).
        models: one force model or a sequence of them; forces and stiffnesses are summed.
        density: kg/m^3, scalar or per cell (m,); 0 gives quasi-static stepping.
        dt: time step (s), > 0.
        mass: "lumped" (SOFA's default) or "consistent".
        gravity: acceleration (3,) in m/s^2, or None.
        external_force: optional callable t -> (n, 3) extra load at time t.
        fixed_nodes: node indices held at their current positions.
        prescribed: a Prescribed (or a tuple (nodes, displacement)).
        rayleigh_mass, rayleigh_stiffness: r_M (1/s) and r_K (s), >= 0.
        newton_iterations: linear solves per step at most (1: SOFA's linearised step).
        newton_tol: relative residual that ends the Newton iterations (used when > 1).
        solver: a :class:`mjed.solvers.LinearSolverOptions` (default: CG, Jacobi, rtol 1e-8,
            1000 iterations).
        max_halvings: a failed step is retried in halves, down to dt / 2^max_halvings (0: no
            retry); see the module docstring.
        allow_inverted: accept steps that leave cells with J <= 0 (counted in each report)
            instead of refusing them.
        max_volume_change: if given (a factor c > 1), a step that changes the volume of some
            cell by more than c (J1 / J0 outside [1/c, c]) fails with reason "volume_jump" and is
            retried in substeps: one linearised step that far from its starting point is not
            to be trusted (see the module docstring). None (default): no such limit.
        x0, v0, t0: initial state (default: the rest positions, at rest, t = 0).

    Nodes that no cell uses (``mesh.unreferenced_nodes``: a mesh read with its numbering kept)
    carry no mass and no force, so their motion is undefined: they are held where they are,
    like fixed nodes, and listed in ``idle_nodes``.

    Attributes read by a step (set once): ``M`` the mass matrix, ``gravity_force`` (n, 3) M g,
    ``constrained`` (3n,) the mask of the fixed, idle and prescribed dofs, ``prescribed_nodes``.
    """

    def __init__(
        self,
        mesh: TetMesh,
        models: Union[ForceModel, Sequence[ForceModel]],
        density,
        *,
        dt: float,
        mass: str = "lumped",
        gravity: Optional[Sequence[float]] = (0.0, 0.0, -9.81),
        external_force: Optional[Callable[[float], np.ndarray]] = None,
        fixed_nodes=None,
        prescribed: Union[Prescribed, Tuple, None] = None,
        rayleigh_mass: float = 0.0,
        rayleigh_stiffness: float = 0.0,
        newton_iterations: int = 1,
        newton_tol: float = 1e-8,
        solver: LinearSolverOptions = LinearSolverOptions(),
        max_halvings: int = 3,
        allow_inverted: bool = False,
        max_volume_change: Optional[float] = None,
        x0=None,
        v0=None,
        t0: float = 0.0,
    ):
        if not isinstance(mesh, TetMesh):
            raise TypeError(f"mesh must be an mjed.TetMesh, got {type(mesh).__name__}")
        if not isinstance(solver, LinearSolverOptions):
            raise TypeError(
                f"solver must be an mjed.solvers.LinearSolverOptions, got {type(solver).__name__}"
            )
        self.mesh = mesh
        self.models = _as_models(models)
        self.dt = _positive("dt", dt)
        if mass not in MASS_KINDS:
            raise ValueError(f"mass must be one of {MASS_KINDS}, got {mass!r}")
        self.M = mass_matrix(mesh, density, mass)
        self.rayleigh_mass = _non_negative("rayleigh_mass", rayleigh_mass)
        self.rayleigh_stiffness = _non_negative("rayleigh_stiffness", rayleigh_stiffness)
        if int(newton_iterations) != newton_iterations or newton_iterations < 1:
            raise ValueError(
                f"newton_iterations must be an integer >= 1, got {newton_iterations!r}"
            )
        self.newton_iterations = int(newton_iterations)
        self.newton_tol = _positive("newton_tol", newton_tol)
        self.solver = solver
        if (
            isinstance(max_halvings, bool)
            or int(max_halvings) != max_halvings
            or not 0 <= max_halvings <= 20
        ):
            raise ValueError(f"max_halvings must be an integer in [0, 20], got {max_halvings!r}")
        self.max_halvings = int(max_halvings)
        self.allow_inverted = bool(allow_inverted)
        if max_volume_change is not None and not (
            np.isfinite(max_volume_change) and max_volume_change > 1
        ):
            raise ValueError(
                f"max_volume_change must be a factor > 1 or None, got {max_volume_change!r}"
            )
        self.max_volume_change = None if max_volume_change is None else float(max_volume_change)
        self._factor: Optional[SPDFactor] = None  # the kept factorisation ("factorized")
        self.external_force = external_force
        n = mesh.n_nodes

        # Gravity as a body force: M g is exact for P1 with a constant g, lumped or consistent.
        self.gravity_force = np.zeros((n, 3))
        if gravity is not None:
            g = np.asarray(gravity, dtype=np.float64)
            if g.shape != (3,) or not np.isfinite(g).all():
                raise ValueError(f"gravity must be 3 finite numbers or None, got {gravity!r}")
            self.gravity_force = (self.M @ np.tile(g, n)).reshape(n, 3)

        self.fixed_nodes = _node_set("fixed_nodes", fixed_nodes, n)
        self.idle_nodes = np.asarray(mesh.unreferenced_nodes, dtype=np.int64)
        if isinstance(prescribed, tuple):
            prescribed = Prescribed(*prescribed)
        if prescribed is not None and not isinstance(prescribed, Prescribed):
            raise ValueError(
                "prescribed must be a Prescribed or (nodes, displacement), got "
                f"{type(prescribed).__name__}"
            )
        self.prescribed = prescribed
        prescribed_nodes = np.empty(0, dtype=np.int64)
        if prescribed is not None:
            prescribed_nodes = _node_set("prescribed.nodes", prescribed.nodes, n)
            both = np.intersect1d(prescribed_nodes, self.fixed_nodes)
            if both.size:
                raise ValueError(f"node(s) {both[:5].tolist()} are both fixed and prescribed")
        self.prescribed_nodes = prescribed_nodes
        constrained = np.zeros((n, 3), dtype=bool)
        constrained[self.fixed_nodes] = True
        constrained[self.idle_nodes] = True
        constrained[prescribed_nodes] = True
        self.constrained = constrained.ravel()  # (3n,)
        self._free = np.flatnonzero(~self.constrained)
        if self._free.size == 0:
            raise ValueError("every node is constrained: nothing to integrate")

        self.x = _initial("x0", mesh.points if x0 is None else x0, n)
        self.v = _initial("v0", np.zeros((n, 3)) if v0 is None else v0, n)
        self.t = float(t0)
        self.steps = 0
        self._J = self._jacobians(self.x)  # (m,) J of the current (accepted) state
        self._warm = None  # last dv on the free dofs: the CG's first guess
        self._system = FreeBlock(self.M, self._free)  # A[free][:, free] without re-slicing K
        # Models whose accepted steps change them; a retry needs to roll each of them back.
        self._stateful = [m for m in self.models if hasattr(m, "accept_step")]
        self._rollback = all(
            callable(getattr(m, "save_history", None))
            and callable(getattr(m, "restore_history", None))
            for m in self._stateful
        )

    # ---------------------------------------------------------------- state
    @property
    def state(self) -> IntegratorState:
        return IntegratorState(self.x.copy(), self.v.copy(), self.t, self.steps)

    def kinetic_energy(self) -> float:
        """1/2 v^T M v."""
        v = self.v.ravel()
        return 0.5 * float(v @ (self.M @ v))

    def max_displacement(self) -> float:
        """The largest nodal displacement |x_a - X_a| from the rest positions."""
        return float(np.linalg.norm(self.x - self.mesh.points, axis=1).max())

    # ---------------------------------------------------------------- stepping
    def run(
        self, n_steps: int, callback: Optional[Callable[["ImplicitEuler", StepReport], None]] = None
    ) -> list:
        """Take n_steps steps; callback(integrator, report) after each. Returns the reports."""
        reports = []
        for _ in range(int(n_steps)):
            report = self.step()
            reports.append(report)
            if callback is not None:
                callback(self, report)
        return reports

    def step(self) -> StepReport:
        """One backward Euler step of size dt, split into substeps if it fails whole.

        On failure raises IntegrationError and keeps the state of the last accepted step.
        """
        clock = time.perf_counter()
        step, t_end = self.steps + 1, self.t + self.dt
        start = self._checkpoint()
        tally = StepTally(len(self.models))
        # the models' histories, saved at the first failure (nothing committed yet)
        saved: list = []
        try:
            self._advance(self.dt, 0, step, tally, saved)
        except IntegrationError as exc:
            self._restore(start)
            for model, history in saved:
                model.restore_history(history)
            if not tally.retries:
                raise
            smallest = self.dt / 2**self.max_halvings
            raise IntegrationError(
                step,
                t_end,
                exc.reason,
                f"{_detail(exc)}; retried in substeps down to dt/{2**self.max_halvings} = "
                f"{smallest:.3g} s ({len(tally.retries)} failed attempt(s): "
                f"{', '.join(sorted(set(tally.retries)))})",
                cells=exc.cells,
            ) from exc
        self.t, self.steps = t_end, step  # the substeps' times add up to t_end up to rounding
        times = StepTimes(
            tuple(float(s) for s in tally.model_seconds),
            tally.system_seconds,
            tally.solve_seconds,
            time.perf_counter() - clock,
        )
        return StepReport(
            step,
            t_end,
            tally.solves,
            tally.cg,
            tally.residual,
            tally.newton_residual,
            tally.reaction.reshape(-1, 3),
            tally.factorizations,
            tally.substeps,
            tuple(tally.retries),
            tally.inverted,
            times,
        )

    def _advance(self, dt: float, depth: int, step: int, tally: StepTally, saved: list) -> None:
        """Take dt from the current state, in halves (recursively) if it fails whole."""
        try:
            self._single(dt, step, tally)
        except IntegrationError as exc:
            retry = exc.reason in RETRIED_REASONS and getattr(exc, "retryable", True)
            if not (retry and self._rollback and depth < self.max_halvings):
                raise
            if not tally.retries and not tally.substeps:  # first failure: nothing committed yet
                saved.extend((m, m.save_history()) for m in self._stateful)
            tally.retries.append(exc.reason)
            self._factor = None  # a factor of the failed matrix is no guide for a smaller step
            for _ in range(2):
                self._advance(0.5 * dt, depth + 1, step, tally, saved)

    def _single(self, dt: float, step: int, tally: StepTally) -> None:
        """One backward Euler step of size dt from the current state; commits it on success."""
        t1 = self.t + dt
        for model in self.models:
            if hasattr(model, "prepare_step"):
                model.prepare_step(dt)
        n3 = 3 * self.mesh.n_nodes
        x0, v0 = self.x.ravel(), self.v.ravel()
        f_ext = self.external_forces(step, t1)

        # Velocity of the constrained dofs over the step: zero for fixed nodes, whatever reaches
        # the prescribed positions at t1 for the others (measured from the actual positions, so
        # that no drift accumulates).
        v_ref = v0.copy()
        v_ref[self.constrained] = 0.0
        if self.prescribed is not None:
            target = self.prescribed_positions(step, t1)
            v_ref.reshape(-1, 3)[self.prescribed_nodes] = (
                target - self.x[self.prescribed_nodes]
            ) / dt
        u_e = np.zeros(n3)  # the first linearisation point is x0

        free = self._free
        a_M, b_K = (
            1.0 + dt * self.rayleigh_mass,
            dt * dt + dt * self.rayleigh_stiffness,
        )  # A = a_M M + b_K K
        cg_total, r0_norm, newton_res, solves, factorizations = 0, 0.0, None, 0, 0
        for it in range(1, self.newton_iterations + 2):
            f, K = self._evaluate(x0 + u_e, step, t1, tally)
            clock = time.perf_counter()
            damp = self.rayleigh_mass * (self.M @ v_ref) + self.rayleigh_stiffness * (K @ v_ref)
            rhs = dt * (f + f_ext - damp - K @ (dt * v_ref - u_e)) - self.M @ (v_ref - v0)
            r_norm = float(np.linalg.norm(rhs[free]))
            tally.system_seconds += time.perf_counter() - clock
            if it == 1:
                r0_norm = r_norm
            else:
                # Here u_e = dt v_ref, so rhs is the nonlinear residual r(v_ref).
                newton_res = self.newton_residual(it, r_norm, r0_norm, step, t1)
                if newton_res <= self.newton_tol:
                    reaction = np.where(self.constrained, -rhs / dt, 0.0)
                    break
            clock = time.perf_counter()
            A_ff = self._system(a_M, K, b_K)
            tally.system_seconds += time.perf_counter() - clock
            # CG returns its first guess untouched for a zero right-hand side: only warm-start
            # otherwise.
            warm = self._warm if (it == 1 and r_norm > 0) else None
            clock = time.perf_counter()
            try:
                res, done = self._solve(A_ff, rhs[free], warm, step, t1)
            finally:
                tally.solve_seconds += time.perf_counter() - clock
            cg_total += res.iterations
            factorizations += done
            solves += 1
            dv = np.zeros(n3)
            dv[free] = res.x
            # Reaction: what the constraints must add for the constrained rows to balance too.
            reaction = np.where(
                self.constrained, (a_M * (self.M @ dv) + b_K * (K @ dv) - rhs) / dt, 0.0
            )
            v_ref = v_ref + dv
            u_e = dt * v_ref
            if it == 1:
                self._warm = res.x.copy()
            if self.newton_iterations == 1:
                break  # SOFA's step: one linearised solve, no residual check

        x1 = x0 + dt * v_ref
        if not (np.isfinite(x1).all() and np.isfinite(v_ref).all()):
            raise IntegrationError(
                step, t1, "non_finite", "the new positions or velocities are not finite"
            )
        x1 = x1.reshape(-1, 3)
        J1 = self._jacobians(x1)
        inverted = self.check_jacobians(self._J, J1, step, t1)
        for k, model in enumerate(self.models):
            if hasattr(model, "accept_step"):
                clock = time.perf_counter()
                model.accept_step(x1, dt)
                tally.model_seconds[k] += time.perf_counter() - clock
        self.x, self.v, self.t, self._J = x1, v_ref.reshape(-1, 3), t1, J1
        tally.substeps += 1
        tally.solves += solves
        tally.cg += cg_total
        tally.factorizations += factorizations
        tally.residual = res.residual
        tally.newton_residual = newton_res
        tally.reaction = reaction
        tally.inverted = inverted

    # ---------------------------------------------------------------- a step's pieces
    # (public so that an integrator running the same step elsewhere, mjed.cuda.integrator's on
    # the device, shares them)
    def external_forces(self, step: int, t1: float) -> np.ndarray:
        """(3n,) f_ext at t1: gravity plus the external load (checked finite)."""
        f_ext = self.gravity_force.ravel().copy()
        if self.external_force is not None:
            f_ext += _finite_load(self.external_force(t1), self.mesh.n_nodes, step, t1)
        return f_ext

    def prescribed_positions(self, step: int, t1: float) -> np.ndarray:
        """(k, 3) positions of the prescribed nodes at t1 (checked finite)."""
        k = len(self.prescribed_nodes)
        target = self.mesh.points[self.prescribed_nodes] + np.asarray(
            self.prescribed.displacement(t1), dtype=float
        )
        if target.shape != (k, 3) or not np.isfinite(target).all():
            raise _input_error(
                step,
                t1,
                f"prescribed displacement at t={t1:g} is not a finite ({k}, 3) array",
            )
        return target

    def newton_residual(self, it: int, r_norm: float, r0_norm: float, step: int, t1: float):
        """||r|| / ||r_0|| at Newton iteration it > 1; raises IntegrationError when it has
        diverged, or when it is above newton_tol after the last solve allowed.
        """
        newton_res = r_norm / r0_norm if r0_norm > 0 else 0.0
        if not np.isfinite(r_norm) or newton_res > _DIVERGENCE_FACTOR:
            raise IntegrationError(
                step,
                t1,
                "newton_diverged",
                f"Newton residual grew to {newton_res:.3g} times the first",
            )
        if newton_res > self.newton_tol and it > self.newton_iterations:
            raise IntegrationError(
                step,
                t1,
                "newton_max_iterations",
                f"Newton residual {newton_res:.3g} above newton_tol={self.newton_tol:g} "
                f"after {self.newton_iterations} linear solves",
            )
        return newton_res

    def check_jacobians(self, J0: np.ndarray, J1: np.ndarray, step: int, t1: float) -> int:
        """The checks of the new J1 (J0: at the step's start): inverted cells (refused unless
        allow_inverted) and the volume change; returns the number of inverted cells.
        """
        inverted = self._inverted_cells(J1, step, t1)
        self._check_volume_change(J0, J1, step, t1)
        return inverted

    # ---------------------------------------------------------------- internals
    def _checkpoint(self) -> tuple:
        """What :meth:`step` restores when the step fails: the accepted state (arrays that a
        step replaces and never writes into, so references suffice).
        """
        return self.x, self.v, self.t, self._J

    def _restore(self, saved: tuple) -> None:
        self.x, self.v, self.t, self._J = saved

    def _solve(self, A: sp.csr_matrix, b: np.ndarray, warm, step: int, t1: float):
        """Solve A x = b on the free dofs; returns (CGResult, factorisations done).

        Raises IntegrationError when CG fails (after one retry with a fresh factorisation when
        the kept one was stale) or a factorisation finds A not positive definite.
        """
        opts = self.solver
        if opts.solver == "direct":
            x = self._factorize(A, step, t1)(b)
            nb = float(np.linalg.norm(b))
            residual = float(np.linalg.norm(b - A @ x)) / nb if nb > 0 else 0.0
            if not residual <= opts.cg_tol:  # held to the CG's tolerance (an ill-conditioned A)
                raise IntegrationError(
                    step,
                    t1,
                    "direct_residual",
                    f"the direct solve left a relative residual {residual:.3g} above "
                    f"cg_tol={opts.cg_tol:g}",
                )
            return CGResult(x, 0, True, "direct", residual), 1
        done = 0
        single = opts.factor_precision == "single"
        if opts.solver == "cuda-cg":  # Jacobi CG on the device (validated: jacobi preconditioner)
            from mjed.cuda.solvers import device_conjugate_gradient

            res = device_conjugate_gradient(
                A, b, tol=opts.cg_tol, max_iterations=opts.max_iterations, x0=warm
            )
        else:
            if opts.preconditioner == "jacobi":
                apply = None
            elif opts.preconditioner == "block-jacobi":
                apply = block_jacobi_preconditioner(A)
            else:
                if self._factor is None:
                    self._factor = self._factorize(A, step, t1, single=single)
                    done = 1
                apply = self._factor
            res = conjugate_gradient(
                A,
                b,
                tol=opts.cg_tol,
                max_iterations=opts.max_iterations,
                x0=warm,
                preconditioner=apply,
            )
        if opts.preconditioner == "factorized":
            if not res.converged and done == 0 and res.reason != "negative_curvature":
                # A stale factorisation (an earlier step's A) may simply be too far off now.
                spent = res.iterations
                self._factor = self._factorize(A, step, t1, single=single)
                done += 1
                res = conjugate_gradient(
                    A,
                    b,
                    tol=opts.cg_tol,
                    max_iterations=opts.max_iterations,
                    x0=warm,
                    preconditioner=self._factor,
                )
                res = CGResult(
                    res.x, res.iterations + spent, res.converged, res.reason, res.residual
                )
            if res.iterations > opts.refactor_iterations:
                self._factor = None  # renewed at the next solve
        if not res.converged:
            raise IntegrationError(
                step,
                t1,
                f"cg_{res.reason}",
                f"CG stopped on {res.reason.replace('_', ' ')} after {res.iterations} iterations "
                f"(relative residual {res.residual:.3g}, tolerance {opts.cg_tol:g}, "
                f"{opts.preconditioner} preconditioner)",
            )
        return res, done

    def _factorize(self, A: sp.csr_matrix, step: int, t1: float, single: bool = False) -> SPDFactor:
        if single:
            try:
                return SPDFactor(A, single=True)
            except NotPositiveDefiniteError:
                pass  # maybe single-precision rounding: the double-precision pivots decide
        try:
            return SPDFactor(A)
        except NotPositiveDefiniteError as exc:
            raise IntegrationError(
                step, t1, "not_positive_definite", f"the step matrix A: {exc}"
            ) from None

    def _evaluate(self, x: np.ndarray, step: int, t1: float, tally: StepTally):
        """Summed forces (3n,) and stiffness (3n, 3n) of all models at x (3n,)."""
        xs = x.reshape(-1, 3)
        if not np.isfinite(xs).all():
            raise IntegrationError(
                step, t1, "non_finite", "a Newton iterate has non-finite positions"
            )
        f_total, K_total = None, None
        for k, model in enumerate(self.models):
            clock = time.perf_counter()
            try:
                f, K = model.force_and_stiffness(xs)
            except InvertedElementError as exc:
                raise IntegrationError(step, t1, "inverted", str(exc), cells=exc.cells) from exc
            finally:
                tally.model_seconds[k] += time.perf_counter() - clock
            f_total = f.ravel() if f_total is None else f_total + f.ravel()
            K_total = sp.csr_matrix(K) if K_total is None else sum_same_pattern(K_total, K)
        if not np.isfinite(f_total).all():
            raise IntegrationError(step, t1, "non_finite", "the internal forces are not finite")
        return f_total, K_total

    def _jacobians(self, x: np.ndarray) -> np.ndarray:
        """(m,) J = det F of every cell at positions x (n, 3)."""
        # J = det(current edges) / det(rest edges), the rest determinant being 6 V > 0.
        xc = x[self.mesh.cells]  # (m, 4, 3)
        e = xc[:, 1:] - xc[:, :1]  # (m, 3, 3) edges from node 0
        return np.einsum("mi,mi->m", e[:, 0], np.cross(e[:, 1], e[:, 2])) / (
            6.0 * self.mesh.volumes
        )

    def _inverted_cells(self, J: np.ndarray, step: int, t1: float) -> int:
        """Cells with J <= 0: refused (IntegrationError) unless allow_inverted; returns their
        count.
        """
        bad = np.flatnonzero(~(J > 0))
        if bad.size and not self.allow_inverted:
            shown = ", ".join(f"cell {c} (J={J[c]:.3g})" for c in bad[:5])
            raise IntegrationError(
                step,
                t1,
                "inverted",
                f"{bad.size} cell(s) inverted at the new positions: {shown}",
                cells=bad,
            )
        return int(bad.size)

    def _check_volume_change(self, J0: np.ndarray, J1: np.ndarray, step: int, t1: float) -> None:
        """A step changing some cell's volume (J0 at its start, J1 at its end) by more than
        max_volume_change fails ("volume_jump").
        """
        c = self.max_volume_change
        if c is None:
            return
        both = (J0 > 0) & (J1 > 0)  # inverted cells are counted (or refused) elsewhere
        ratio = np.ones_like(J1)
        ratio[both] = J1[both] / J0[both]
        bad = np.flatnonzero((ratio > c) | (ratio < 1.0 / c))
        if bad.size:
            worst = bad[np.argmax(np.abs(np.log(ratio[bad])))]
            raise IntegrationError(
                step,
                t1,
                "volume_jump",
                f"{bad.size} cell(s) changed volume by more than a factor {c:g} in one step (cell "
                f"{worst}: J {J0[worst]:.3g} -> {J1[worst]:.3g})",
                cells=bad,
            )


def _detail(exc: IntegrationError) -> str:
    """The failure itself, without the "time step ... failed:" frame and the closing clause."""
    text = str(exc)
    head, _, rest = text.partition(" failed: ")
    return rest.rsplit("; the integrator kept", 1)[0] if rest else text


def _input_error(step: int, t1: float, detail: str) -> IntegrationError:
    """A failure caused by the user's input (loads, prescribed motion): no smaller step cures it."""
    exc = IntegrationError(step, t1, "non_finite", detail)
    exc.retryable = False
    return exc


def _as_models(models) -> tuple:
    if hasattr(models, "force_and_stiffness"):
        models = (models,)
    models = tuple(models)
    if not models:
        raise ValueError("models is empty: give at least one force model")
    for m in models:
        if not callable(getattr(m, "force_and_stiffness", None)):
            raise TypeError(f"force model {type(m).__name__} has no force_and_stiffness(x) method")
    return models


def _positive(name: str, value) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return value


def _non_negative(name: str, value) -> float:
    value = float(value)
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return value


def _node_set(name: str, nodes, n: int) -> np.ndarray:
    if nodes is None:
        return np.empty(0, dtype=np.int64)
    arr = np.asarray(nodes)
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name} must be integer node indices, got dtype {arr.dtype}")
    arr = np.unique(arr.astype(np.int64).ravel())
    if arr.size and (arr[0] < 0 or arr[-1] >= n):
        bad = arr[(arr < 0) | (arr >= n)]
        raise ValueError(f"{name} has indices out of range [0, {n}): {bad[:5].tolist()}")
    return arr


def _initial(name: str, value, n: int) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n, 3):
        raise ValueError(f"{name} must have shape ({n}, 3), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} has non-finite entries")
    return arr


def _finite_load(load, n: int, step: int, t1: float) -> np.ndarray:
    load = np.asarray(load, dtype=np.float64)
    if load.shape != (n, 3) or not np.isfinite(load).all():
        raise _input_error(step, t1, f"external_force(t={t1:g}) is not a finite ({n}, 3) array")
    return load.ravel()
