"""The liver study's set-up: its models, parameters, constants and force-field backends.

See comparisons.liver.study for the study and the reasons behind each figure.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, is_dataclass
from typing import Any, Callable, List, Optional, Sequence

import numpy as np

from common.options import InputError
from comparisons.liver.regions import relative_box
from mjed.backends import BACKENDS as MJED_BACKENDS
from mjed.materials import ArrudaBoyce
from mjed.materials.base import Material
from mjed.solvers import LinearSolverOptions

__all__ = [
    "LiverParameters",
    "LiverStudyOptions",
    "MODELS",
    "PAPER_FPS",
    "TARGET_FPS",
    "COMPILED_TARGET_FPS",
    "PAPER_HYPERELASTIC_SHARE",
    "BACKEND_AGREEMENT_TOL",
    "TERZAGHI_TOL",
    "LIVER_SOLVER",
    "BACKENDS",
    "KNOWN_BACKENDS",
    "GPU_BACKENDS",
    "backend_force_field",
    "run_solver",
    "device_synchronizer",
    "run_integrator",
    "numpy_force_field",
    "default_fixed_specs",
]

MODELS = ("hyperelastic", "visco-hyperelastic", "visco-poro-hyperelastic")
#: The paper's frame rates (2010 laptop, Core Duo 2.8 GHz), and the real-time target.
PAPER_FPS = {"hyperelastic": 7.5, "visco-hyperelastic": 7.0, "visco-poro-hyperelastic": 6.0}
TARGET_FPS = 25.0
#: The frame rate asked of the compiled backend on this study's 2-core machine (issue 15).
COMPILED_TARGET_FPS = 60.0
#: Two backends give the same trajectory up to this relative difference of the maximum
#: displacement curve: their forces differ by round-off, and each linearised step is solved
#: only to a relative CG residual of 1e-5 (LIVER_SOLVER), which bounds how far they may drift.
BACKEND_AGREEMENT_TOL = 1e-4
#: The paper's share of one step spent in the hyperelastic force and stiffness ("around 60 %").
PAPER_HYPERELASTIC_SHARE = 0.60
#: Relative L2 pressure error allowed in the Terzaghi check (the same 1 % as tests/test_darcy.py).
TERZAGHI_TOL = 1e-2
#: The liver's linear solver (see the module docstring).
LIVER_SOLVER = LinearSolverOptions(
    cg_tol=1e-5, preconditioner="factorized", refactor_iterations=20, factor_precision="single"
)


_BACKEND_LABELS = {
    "numpy": "NumPy MJED (mjed.HyperelasticForceField)",
    "numba": "compiled MJED (mjed.compiled.CompiledForceField, Numba)",
    "cuda": "MJED on the GPU (mjed.cuda.CudaForceField, FP64; implicit Euler's CG on the device)",
    "cuda-fp32": "MJED on the GPU in single precision (mjed.cuda.CudaForceField, FP32; implicit "
    "Euler's CG on the device in FP64)",
}
#: mjed.make_force_field's backend and options of each backend name of the study.
_BACKEND_FIELDS = {
    "numpy": ("numpy", {}),
    "numba": ("numba", {}),
    "cuda": ("cuda", {"dtype": np.float64}),
    "cuda-fp32": ("cuda", {"dtype": np.float32}),
}
#: The backends on the GPU: their runs solve each step by the device CG (``solver="cuda-cg"``).
GPU_BACKENDS = ("cuda", "cuda-fp32")


def backend_force_field(backend: str) -> Callable:
    """The factory ``(mesh, material, *, regularize, allow_inverted)`` -> force field of
    ``mjed.make_force_field(..., backend=...)``, with ``backend`` and ``label`` attributes, and
    ``linear_solver`` (the run's LinearSolverOptions from the study's, see :func:`run_solver`)
    ``synchronize`` (waits for the device; :func:`simulate` calls it before stopping a
    step's clock) and ``integrator`` (:func:`run_integrator`: for the GPU, the step on the
    device where the model allows).

    The compiled and the GPU fields are evaluated once at rest when built, so their kernels
    are compiled (or loaded from Numba's cache) before any step is timed; for the GPU also the
    device CG's kernels. Raises ValueError for an unknown backend; building a "numba" field
    without Numba, or a "cuda" one without a CUDA device, raises
    mjed.compiled.BackendUnavailable.
    """
    if backend not in _BACKEND_LABELS:
        raise ValueError(f"unknown backend {backend!r}; choose from {', '.join(_BACKEND_LABELS)}")
    kind, options = _BACKEND_FIELDS[backend]
    gpu = backend in GPU_BACKENDS

    def factory(mesh, material: Material, *, regularize: bool, allow_inverted: bool):
        import mjed

        field = mjed.make_force_field(
            mesh,
            material,
            backend=kind,
            regularize=regularize,
            allow_inverted=allow_inverted,
            **options,
        )
        if backend != "numpy":
            field.force_and_stiffness(
                mesh.points
            )  # compile / load the kernel now, not in the first step
        if gpu:
            _warm_device_solver()
        return field

    factory.backend = backend
    factory.label = _BACKEND_LABELS[backend] + (_simulated_note() if gpu else "")
    factory.linear_solver = _device_solver if gpu else (lambda options: options)
    factory.synchronize = _synchronize_device if gpu else (lambda: None)
    factory.integrator = _device_integrator if gpu else _host_integrator
    factory.__qualname__ = f"backend_force_field({backend!r})"
    return factory


def run_solver(force_field, params: LiverParameters) -> LinearSolverOptions:
    """The linear solver of a run with this force field: ``params.solver``, or for a GPU
    backend the device CG (Jacobi, the only preconditioner it runs) to the same relative
    residual and iteration cap, so that the system never waits on a host factorisation.
    A factory without ``linear_solver`` (given from Python) runs ``params.solver``.
    """
    choose = getattr(force_field, "linear_solver", None)
    return params.solver if choose is None else choose(params.solver)


def run_integrator(force_field, mesh, models, density, **options):
    """The implicit Euler integrator of a run: for a GPU backend the step on the device
    (mjed.cuda.integrator.implicit_euler: all three models, the viscous history and the fluid
    pressure kept on the device by mjed.cuda.device_models; models it refuses get the
    host-built step with the device CG, saying why), else mjed.integrator.ImplicitEuler.
    Returns (integrator, where: one line saying where the step is built, or "" off the GPU).
    """
    make = getattr(force_field, "integrator", None) or _host_integrator
    return make(mesh, models, density, **options)


def _host_integrator(mesh, models, density, **options):
    from mjed.integrator import ImplicitEuler

    return ImplicitEuler(mesh, models, density, **options), ""


def _device_integrator(mesh, models, density, **options):
    from mjed.cuda.integrator import device_refusal, implicit_euler

    integ = implicit_euler(mesh, models, density, **options)
    why = device_refusal(models, options["solver"])
    return integ, "step on the device" if why is None else f"step built on the host: {why}"


def device_synchronizer(force_field) -> Callable[[], None]:
    """What waits for the force field's device to finish (a no-op off the GPU)."""
    return getattr(force_field, "synchronize", None) or (lambda: None)


def _device_solver(options: LinearSolverOptions) -> LinearSolverOptions:
    return LinearSolverOptions(
        solver="cuda-cg", cg_tol=options.cg_tol, max_iterations=options.max_iterations
    )


def _synchronize_device() -> None:
    """Wait for every kernel and copy on the device: a step's clock stops after its work."""
    from numba import cuda

    cuda.synchronize()


def _simulated_note() -> str:
    from mjed.cuda import simulated

    return " on Numba's CUDA simulator (not a GPU: its FPS mean nothing)" if simulated() else ""


def _warm_device_solver() -> None:
    """Compile the device CG's kernels (a 2 x 2 system taking two iterations) before any step
    is timed: Numba compiles a kernel at its first launch.
    """
    import scipy.sparse as sp

    from mjed.cuda.solvers import device_conjugate_gradient

    A = sp.csr_matrix(np.array([[4.0, 1.0], [1.0, 3.0]]))
    device_conjugate_gradient(A, np.array([1.0, 2.0]), tol=1e-14, max_iterations=4)


#: The default force field: NumPy MJED (mjed.HyperelasticForceField).
numpy_force_field = backend_force_field("numpy")
#: The backends the study runs by default (every CPU backend of mjed.make_force_field), the
#: reference (first) one first.
BACKENDS = MJED_BACKENDS
#: Every backend the study can run (``--backends``): the defaults and the GPU ones.
KNOWN_BACKENDS = tuple(_BACKEND_LABELS)


def _unavailable(backend: str) -> Optional[str]:
    """Why ``backend`` cannot run here, or None."""
    from mjed.compiled import numba_available

    if backend == "numba" and not numba_available():
        return "the compiled (numba) backend: Numba is not installed (Debian: python3-numba)"
    if backend in GPU_BACKENDS:
        from mjed.cuda import BackendUnavailable, require_cuda

        try:
            require_cuda()
        except BackendUnavailable as exc:
            return f"the {backend} backend: not run: no GPU ({exc})"
    return None


def _backend_factories(backends: Sequence[str]):
    """The factories of ``backends`` that can be built here, and what was left out (and why):
    a backend that cannot run is named, never replaced by another.
    """
    if not backends:
        raise InputError(f"give at least one backend ({', '.join(_BACKEND_LABELS)})")
    unknown = [b for b in backends if b not in _BACKEND_LABELS]
    if unknown:
        raise InputError(f"unknown backend(s) {unknown}; known: {', '.join(_BACKEND_LABELS)}")
    factories, missing = [], []
    for b in dict.fromkeys(backends):
        why = _unavailable(b)
        if why is not None:
            missing.append(why)
            continue
        factories.append(backend_force_field(b))
    if not factories:
        raise InputError(
            f"none of the backends {list(backends)} can run here: {'; '.join(missing)}"
        )
    return factories, missing


def _positive(name: str, v, *, zero: bool = False) -> None:
    ok = (
        isinstance(v, (int, float))
        and not isinstance(v, bool)
        and np.isfinite(v)
        and (v >= 0 if zero else v > 0)
    )
    if not ok:
        raise ValueError(
            f"LiverParameters: parameter {name} must be finite and {'>= 0' if zero else '> 0'}, "
            f"got {v!r}"
        )


@dataclass(frozen=True)
class LiverParameters:
    """The liver model and the scenario (see the module docstring for the sources).

    material: the hyperelastic law (default Arruda-Boyce mu 2 kPa, k0 20 kPa, N 8).
    dt_porous: the porous run's step; None for dt / 2 (the paper's 0.15 s beside 0.3 s).
    solver: the integrator's LinearSolverOptions. max_halvings: a failed step is retried in
    halves down to dt / 2^max_halvings. allow_inverted: accept inverted cells (counted), only
    for a material whose energy is finite at J <= 0, with the regularisation on.
    max_volume_change: a step changing a cell's volume by more than this factor is retried in
    substeps (None: no limit); see mjed.integrator.
    """

    material: Material = ArrudaBoyce(mu=2000.0, k0=20000.0, N=8.0)
    density: float = 1000.0
    prony_alphas: tuple = (0.235, 0.333)
    prony_taus: tuple = (0.27, 0.03)
    f_w: float = 0.5
    K0: float = 400.0
    K_lim: float = 2200.0
    kappa: float = 5e-6
    dt: float = 0.3
    dt_porous: Optional[float] = None
    rayleigh_mass: float = 0.1
    rayleigh_stiffness: float = 0.1
    gravity: tuple = (0.0, 0.0, -9.81)
    regularize: bool = True
    solver: LinearSolverOptions = LIVER_SOLVER
    max_halvings: int = 4
    allow_inverted: bool = False
    max_volume_change: Optional[float] = 1.5

    def __post_init__(self):
        if not isinstance(self.material, Material):
            raise ValueError(
                "LiverParameters: material must be one of mjed.materials, got "
                f"{type(self.material).__name__}"
            )
        for name in ("density", "K0", "K_lim", "dt"):
            _positive(name, getattr(self, name))
        if self.dt_porous is not None:
            _positive("dt_porous", self.dt_porous)
        for name in ("kappa", "rayleigh_mass", "rayleigh_stiffness"):
            _positive(name, getattr(self, name), zero=True)
        g = tuple(self.gravity)
        if len(g) != 3 or not all(isinstance(c, (int, float)) and math.isfinite(c) for c in g):
            raise ValueError(
                "LiverParameters: parameter gravity must be 3 finite numbers (m/s^2), got "
                f"{self.gravity!r}"
            )
        object.__setattr__(self, "gravity", tuple(float(c) for c in g))
        if not isinstance(self.solver, LinearSolverOptions):
            raise ValueError(
                "LiverParameters: parameter solver must be a LinearSolverOptions, got "
                f"{self.solver!r}"
            )
        if self.max_volume_change is not None and not (
            isinstance(self.max_volume_change, (int, float))
            and math.isfinite(self.max_volume_change)
            and self.max_volume_change > 1
        ):
            raise ValueError(
                "LiverParameters: parameter max_volume_change must be a factor > 1 or None, got "
                f"{self.max_volume_change!r}"
            )
        m = self.max_halvings
        if isinstance(m, bool) or not isinstance(m, int) or not 0 <= m <= 10:
            raise ValueError(
                f"LiverParameters: parameter max_halvings must be an integer in [0, 10], got {m!r}"
            )
        if self.allow_inverted:
            from mjed.inversion import inversion_blockers

            blockers = inversion_blockers(self.material)
            if blockers or not self.regularize:
                why = (
                    f"its energy term {blockers[0][0]} is not finite at {blockers[0][1]}"
                    if blockers
                    else "the regularisation is off"
                )
                raise ValueError(
                    "LiverParameters: allow_inverted needs the regularisation and an energy "
                    f"finite at J <= 0 (paper, section 2.3); {type(self.material).__name__} does "
                    f"not qualify: {why}"
                )

    @property
    def porous_dt(self) -> float:
        return self.dt / 2 if self.dt_porous is None else self.dt_porous

    def to_dict(self) -> dict:
        out = {}
        for k in self.__dataclass_fields__:
            v = getattr(self, k)
            if isinstance(v, Material):
                out[k] = {"name": type(v).__name__, **_jsonable(asdict(v))}
            elif is_dataclass(v):
                out[k] = asdict(v)
            else:
                out[k] = _jsonable(v)
        return out


def _jsonable(v):
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (tuple, list)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


def default_fixed_specs(points: np.ndarray) -> List[str]:
    """Vena cava and suspensory ligament, as fractions of the mesh's bounding box.

    Vena cava (with the bare area around it, where the liver lies against the diaphragm): a
    block on the posterior-superior side between the lobes (x in 25-75 %, y in the back 40 %,
    z above 35 %). Suspensory ligament: a strip on top between the lobes (x in 30-55 %, z in
    the top 20 %). Axes as in meshes/liver.py (x left to right, y anterior to posterior, z up):
    for a mesh with other axes, give --fixed.
    """
    return [
        relative_box(points, (0.25, 0.60, 0.35), (0.75, 1.0, 1.0)),
        relative_box(points, (0.30, 0.0, 0.80), (0.55, 1.0, 1.0)),
    ]


def _models(kind: str, mesh, params: LiverParameters, fixed: np.ndarray, force_field):
    """Force models, the time step and the fluid model (or None) of one run."""
    from mjed.darcy import DarcyParameters, FluidPressureForce
    from mjed.porous import PorousVolume
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    solid = force_field(
        mesh, params.material, regularize=params.regularize, allow_inverted=params.allow_inverted
    )
    if kind == "hyperelastic":
        return [solid], params.dt, None
    visco = ViscoHyperelasticForceField(solid, prony=Prony(params.prony_alphas, params.prony_taus))
    if kind == "visco-hyperelastic":
        return [visco], params.dt, None
    # The porous solid U(J) and the fluid pressure are one volumetric model (sigma_p = sigma - P),
    # in parallel with the visco-hyperelastic network, so the Prony series does not relax them.
    law = PorousVolume(params.f_w, params.K0, params.K_lim)
    fluid = FluidPressureForce(
        mesh, DarcyParameters(params.K_lim, params.kappa), solid=law, drained_nodes=fixed
    )
    return [visco, fluid], params.porous_dt, fluid


#: The phases of a step, in the order of the split figure.


@dataclass(frozen=True)
class LiverStudyOptions:
    """What a liver study runs: the organ, its supports, the models, backends and outputs.

    mesh: a catalog name, a mesh file or (points, cells); fixed: region specs (default: vena
    cava and ligament); steps: time steps of each run (default 30, quick 6); units or scale:
    the mesh's length unit; models: which of MODELS; backends: the MJED backends, or
    force_fields: factories replacing them (Python only); oscillation / full_oscillation: the
    Fig. 4 study and its long version; json_path: also write the data there; relative_to:
    figure paths in the blocks are made relative to this directory (a report's run directory);
    allow_disconnected: accept a mesh in several parts, each with a fixed node (warned).
    """

    quick: bool = False
    out_dir: str = os.path.join("reports", "liver")
    series: bool = True
    mesh: Any = "liver"
    fixed: Optional[Sequence[str]] = None
    steps: Optional[int] = None
    units: Optional[str] = None
    scale: Optional[float] = None
    fix_orientation: bool = False
    params: LiverParameters = LiverParameters()
    models: Sequence[str] = MODELS
    oscillation: bool = True
    full_oscillation: bool = False
    backends: Sequence[str] = BACKENDS
    force_fields: Optional[Sequence[Callable]] = None
    json_path: Optional[str] = None
    relative_to: Optional[str] = None
    allow_disconnected: bool = False

    @property
    def full(self) -> bool:
        """The long oscillation study (never with --quick)."""
        return self.full_oscillation and not self.quick
