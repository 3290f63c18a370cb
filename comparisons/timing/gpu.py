"""The GPU section of the hardware benchmark (comparisons.timing.hardware): MJED and the
classical element on the device, the GPU figures of docs/studies/timing.md as typed records.

For each size (structured cubes, meshes.structured.cube_with_cells, 1e4 to 1e7 tets by
default), each precision (FP64, FP32), each method (MJED: mjed.cuda.CudaForceField; the
classical element generated and compiled the same way: reference_fem.classical_cuda) and
each quantity (force alone, force + stiffness), the time of one call with positions, forces
and CSR values kept on the device (``device_force_and_stiffness``: the zeroing, the cell
kernel and the reduction of J and the energy, with its 16-byte copy back), best of adaptive
repeats, as tets per second and as GB/s of the bytes the call must move at least (positions
read and forces written, rest geometry and connectivity read, J and the energy written; with
the stiffness, the CSR values written once and the block map read), against the device's
copy bandwidth measured in the same run. Before a size is built, the device memory it needs
is computed and compared with the memory free; a size that does not fit is skipped with the
figures. Before anything is timed, each method and precision is checked against the NumPy
element on the smallest size (a method that differs is not timed). The compiled CPU backend
(mjed.compiled, all of Numba's threads) is timed on the same machine at the largest size up
to 1e6 tets, for the GPU/CPU ratio; and the targets are judged (:data:`TARGETS`) only on a
real device, never on Numba's CUDA simulator.
"""

from __future__ import annotations

import datetime as _dt
import time
from dataclasses import asdict, dataclass
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

__all__ = [
    "GpuTiming",
    "GpuSize",
    "Verification",
    "CpuReference",
    "TargetOutcome",
    "GpuFigures",
    "TARGETS",
    "DEFAULT_SIZES",
    "cube_counts",
    "device_bytes",
    "moved_bytes",
    "timed_repeats",
    "time_device",
    "bench_state",
    "free_memory",
    "device_name",
    "utc_now",
    "copy_bandwidth",
    "measure",
    "not_run",
    "print_figures",
]

DEFAULT_SIZES = (10_000, 100_000, 1_000_000, 10_000_000)
METHODS = ("mjed", "classical")
DTYPES = ("float64", "float32")
QUANTITIES = ("f", "f+K")
#: Relative tolerances of the check before timing (largest difference over largest entry).
VERIFY_TOL = {"float64": 1e-10, "float32": 1e-4}
#: Largest size at which the CPU backend is timed for the ratio.
CPU_MAX_CELLS = 1_500_000
#: Share of the free device memory a size may plan to use.
MEMORY_SHARE = 0.9


@dataclass(frozen=True)
class Target:
    """A target of the GPU benchmark: tets/s of ``method`` ``quantity`` in ``dtype`` at the size
    closest to ``cells`` (within a factor 1.5), for ``material``.
    """

    name: str
    material: str
    method: str
    dtype: str
    quantity: str
    cells: int
    tets_per_s: float


TARGETS = (
    Target(
        "NeoHookean force+stiffness FP64 at 1M tets",
        "NeoHookean",
        "mjed",
        "float64",
        "f+K",
        1_000_000,
        1e9,
    ),
    Target(
        "NeoHookean force only FP64 at 1M tets",
        "NeoHookean",
        "mjed",
        "float64",
        "f",
        1_000_000,
        3e9,
    ),
)


@dataclass(frozen=True)
class GpuTiming:
    """One method, precision and quantity at one size."""

    method: str
    dtype: str
    quantity: str
    best_s: float
    median_s: float
    repeats: int
    tets_per_s: float
    moved_bytes: int
    GBs: float
    copy_fraction: float  # GBs over the device's copy bandwidth


@dataclass(frozen=True)
class GpuSize:
    """One cube: its counts, the device memory it needs per precision, what was timed and
    what was skipped (with why).
    """

    target: int
    cells: int
    nodes: int
    nnz: int
    needed_bytes: dict  # dtype -> device bytes of the mesh arrays, block map and outputs
    csr_bytes: dict  # dtype -> bytes of the CSR values alone
    setup_s: float = 0.0  # host: mesh, CSR pattern and block map
    timings: Tuple[GpuTiming, ...] = ()
    skipped: Tuple[str, ...] = ()

    def timing(self, method: str, dtype: str, quantity: str) -> Optional[GpuTiming]:
        for t in self.timings:
            if (t.method, t.dtype, t.quantity) == (method, dtype, quantity):
                return t
        return None


@dataclass(frozen=True)
class Verification:
    """A method and precision against the NumPy element before timing."""

    method: str
    dtype: str
    cells: int
    force_err: float
    stiffness_err: float
    tol: float

    @property
    def passed(self) -> bool:
        return bool(self.force_err <= self.tol and self.stiffness_err <= self.tol)


@dataclass(frozen=True)
class CpuReference:
    """The compiled MJED CPU backend, all threads, FP64, at one size of the GPU list."""

    cells: int
    threads: int
    f_s: float
    fK_s: float
    force_vs_gpu: float  # its force against the GPU FP64 MJED force, relative


@dataclass(frozen=True)
class TargetOutcome:
    """A target with its figure; met is None when not judged (``note`` says why)."""

    name: str
    required: float
    measured: Optional[float]
    met: Optional[bool]
    note: str = ""

    def line(self) -> str:
        head = f"target {self.name} >= {self.required:.0e} tets/s:"
        if self.met is None:
            return f"{head} {self.note}"
        return f"{head} {'met' if self.met else 'missed'} ({self.measured:.3e} tets/s{self.note})"


@dataclass(frozen=True)
class GpuFigures:
    """The GPU section of one run (``status`` "measured", or why it was not run)."""

    status: str
    material: str = "NeoHookean"
    device: str = ""
    date: str = ""
    simulated: bool = False
    copy_GBs: float = 0.0
    memory_free_bytes: float = 0.0
    verification: Tuple[Verification, ...] = ()
    sizes: Tuple[GpuSize, ...] = ()
    cpu: Optional[CpuReference] = None
    targets: Tuple[TargetOutcome, ...] = ()
    seconds: float = 0.0

    @property
    def measured(self) -> bool:
        return self.status == "measured"

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "GpuFigures":
        """The record of :meth:`to_dict` (as read back from JSON)."""
        sizes = tuple(
            GpuSize(
                **{
                    **s,
                    "timings": tuple(GpuTiming(**t) for t in s["timings"]),
                    "skipped": tuple(s["skipped"]),
                }
            )
            for s in d.get("sizes", ())
        )
        cpu = d.get("cpu")
        return cls(
            **{
                **d,
                "verification": tuple(Verification(**v) for v in d.get("verification", ())),
                "sizes": sizes,
                "cpu": None if cpu is None else CpuReference(**cpu),
                "targets": tuple(TargetOutcome(**t) for t in d.get("targets", ())),
            }
        )


# ------------------------------------------------------------------ sizes and bytes
def cube_counts(target: int) -> Tuple[int, int, int, int]:
    """(divisions, cells, nodes, nnz) of cube_with_cells(target) without building it: n^3
    hexahedra of six tetrahedra, (n + 1)^3 nodes, and edges 3 n (n + 1)^2 along the axes,
    3 n^2 (n + 1) face diagonals, n^3 body diagonals; nnz = 9 (nodes + 2 edges).
    """
    n = max(1, int(round((target / 6.0) ** (1.0 / 3.0))))
    nodes = (n + 1) ** 3
    edges = 3 * n * (n + 1) ** 2 + 3 * n * n * (n + 1) + n**3
    return n, 6 * n**3, nodes, 9 * (nodes + 2 * edges)


def _index_bytes(nodes: int, nnz: int) -> int:
    return 4 if max(nnz, 3 * nodes) < 2**31 else 8  # mjed.cuda.launch.CellLauncher.index


def device_bytes(cells: int, nodes: int, nnz: int, dtype: str) -> int:
    """Device bytes of one precision: the launcher's arrays (connectivity, D, V0, block map,
    row lengths, J, E), positions, forces and CSR values (shared by both methods).
    """
    isz, idx = np.dtype(dtype).itemsize, _index_bytes(nodes, nnz)
    return idx * (20 * cells + nodes) + isz * (15 * cells + 6 * nodes + nnz)


def moved_bytes(cells: int, nodes: int, nnz: int, dtype: str, stiffness: bool) -> int:
    """Bytes a call must move at least: positions read, forces written (3 n values each),
    D and V0 read (13 per cell), J and E written (2 per cell), the connectivity read; with
    the stiffness the CSR values written once and the block map (16 per cell) and row
    lengths read (comparisons.timing.bandwidth.floor_bytes counts the same, without J, E and
    the map).
    """
    isz, idx = np.dtype(dtype).itemsize, _index_bytes(nodes, nnz)
    out = isz * (6 * nodes + 15 * cells) + idx * 4 * cells
    if stiffness:
        out += isz * nnz + idx * (16 * cells + nodes)
    return int(out)


# ------------------------------------------------------------------ timing
def timed_repeats(call: Callable[[], object], min_time: float) -> Tuple[float, float, int]:
    """(best, median, repeats) of ``call`` in seconds, for a ``call`` that waits for its own
    device work: it runs once before (compiling and loading), then as many times as fit in
    ``min_time`` (3 to 200).
    """
    call()
    t0 = time.perf_counter()
    call()
    first = max(time.perf_counter() - t0, 1e-7)
    repeats = int(min(200, max(3, min_time / first)))
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        call()
        samples.append(time.perf_counter() - t0)
    return min(samples), float(np.median(samples)), repeats


def time_device(call: Callable[[], object], min_time: float) -> Tuple[float, float, int]:
    """:func:`timed_repeats` of ``call`` with the device synchronised after each call."""
    from numba import cuda

    def waited():
        call()
        cuda.synchronize()

    return timed_repeats(waited, min_time)


def copy_bandwidth(copy_bytes: int) -> float:
    """GB/s (read + write) of a device-to-device copy of ``copy_bytes``, best of five."""
    from numba import cuda

    n_copy = max(1, copy_bytes // 8)
    a = cuda.to_device(np.ones(n_copy))
    b = cuda.device_array(n_copy)
    best = time_device(lambda: b.copy_to_device(a), 0.0)[0]
    return 2 * 8 * n_copy / best / 1e9


def bench_state(points: np.ndarray) -> np.ndarray:
    """The deformed positions every figure is taken at (a stretch; J stays near 1)."""
    return points * [1.05, 0.98, 0.99]


def _fields(mesh, material, dtype: str, layout):
    """The MJED and classical GPU fields of one precision, sharing one launcher."""
    from mjed.cuda import CudaForceField
    from mjed.cuda.launch import CellLauncher
    from reference_fem.classical_cuda import CudaClassicalGalerkin

    launcher = CellLauncher(mesh, dtype, layout)
    return launcher, {
        "mjed": CudaForceField(mesh, material, dtype=dtype, launcher=launcher),
        "classical": CudaClassicalGalerkin(mesh, None, material, dtype=dtype, launcher=launcher),
    }


def verify(mesh, material, layout) -> List[Verification]:
    """Each method and precision against the NumPy element (MJED: mjed's engine; classical:
    reference_fem.classical), force and stiffness, relative to their largest entries.
    """
    import mjed
    from reference_fem.classical import ClassicalGalerkin

    x = bench_state(mesh.points)
    refs = {
        "mjed": mjed.make_force_field(mesh, material).force_and_stiffness(x),
        "classical": ClassicalGalerkin(mesh, None, material).force_and_stiffness(x),
    }
    out = []
    for dtype in DTYPES:
        _, fields = _fields(mesh, material, dtype, layout)
        for method, fld in fields.items():
            f, K = fld.force_and_stiffness(x)
            f_r, K_r = refs[method]
            out.append(
                Verification(
                    method,
                    dtype,
                    mesh.n_cells,
                    float(np.abs(f - f_r).max() / np.abs(f_r).max()),
                    float(abs(K - K_r).max() / abs(K_r).max()),
                    VERIFY_TOL[dtype],
                )
            )
    return out


def _time_dtype(mesh, material, dtype, layout, allowed, copy_GBs, min_time) -> List[GpuTiming]:
    """Both methods and quantities of one precision on one mesh (positions, forces and CSR
    values on the device; one force and one CSR array shared by the methods).
    """
    from numba import cuda

    launcher, fields = _fields(mesh, material, dtype, layout)
    x_d = launcher.to_device(bench_state(mesh.points))
    out = (
        cuda.device_array((mesh.n_nodes, 3), dtype=dtype),
        cuda.device_array(launcher.pattern.nnz, dtype=dtype),
    )
    timings = []
    for method in (m for m in METHODS if (m, dtype) in allowed):
        for quantity in QUANTITIES:
            stiff = quantity == "f+K"

            def call(fld=fields[method], stiff=stiff):
                fld.device_force_and_stiffness(x_d, force=True, stiffness=stiff, out=out)

            best, median, repeats = time_device(call, min_time)
            moved = moved_bytes(mesh.n_cells, mesh.n_nodes, launcher.pattern.nnz, dtype, stiff)
            GBs = moved / best / 1e9
            timings.append(
                GpuTiming(
                    method,
                    dtype,
                    quantity,
                    best,
                    median,
                    repeats,
                    mesh.n_cells / best,
                    moved,
                    GBs,
                    GBs / copy_GBs,
                )
            )
    return timings


def free_memory() -> float:
    from numba import cuda

    return float(cuda.current_context().get_memory_info()[0])


def measure_size(target, material, allowed, copy_GBs, min_time, verifications=None):
    """One cube: memory check per precision, then the timings that fit. With
    ``verifications`` (a list), the methods are first checked here and the list filled.
    Returns (GpuSize, mesh, layout); mesh and layout are None when nothing fit.
    """
    import mjed
    from meshes.structured import cube_with_cells
    from mjed.cuda.launch import BlockLayout

    _, cells, nodes, nnz = cube_counts(target)
    need = {d: device_bytes(cells, nodes, nnz, d) for d in DTYPES}
    csr = {d: np.dtype(d).itemsize * nnz for d in DTYPES}
    free = free_memory()
    skipped = [
        f"{d}: needs {need[d] / 1e9:.2f} GB of device memory (CSR values {csr[d] / 1e9:.2f} GB, "
        f"{nnz:,} entries), {free / 1e9:.2f} GB free"
        for d in DTYPES
        if need[d] > MEMORY_SHARE * free
    ]
    size = GpuSize(target, cells, nodes, nnz, need, csr, skipped=tuple(skipped))
    if len(skipped) == len(DTYPES):
        return size, None, None
    t0 = time.perf_counter()
    mesh = mjed.TetMesh(*cube_with_cells(target))
    layout = BlockLayout.of(mesh)
    setup_s = time.perf_counter() - t0
    if verifications is not None:
        verifications.extend(verify(mesh, material, layout))
        allowed = {(v.method, v.dtype) for v in verifications if v.passed}
    timings = []
    for dtype in DTYPES:
        if need[dtype] <= MEMORY_SHARE * free_memory():
            timings += _time_dtype(mesh, material, dtype, layout, allowed, copy_GBs, min_time)
    size = GpuSize(target, cells, nodes, nnz, need, csr, setup_s, tuple(timings), size.skipped)
    return size, mesh, layout


def cpu_reference(mesh, material, min_time: float) -> CpuReference:
    """The compiled MJED CPU backend on all of Numba's threads, FP64, force alone and force +
    stiffness, best of adaptive repeats; its force against the GPU FP64 MJED force.
    """
    import numba

    import mjed

    x = bench_state(mesh.points)
    cpu = mjed.make_force_field(mesh, material, backend="numba", parallel=True)
    gpu_force = mjed.make_force_field(mesh, material, backend="cuda").force(x)
    f = cpu.force(x)
    times = {}
    for name, call in (("f", lambda: cpu.force(x)), ("fK", lambda: cpu.force_and_stiffness(x))):
        call()
        t0 = time.perf_counter()
        call()
        repeats = int(min(100, max(3, min_time / max(time.perf_counter() - t0, 1e-7))))
        samples = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            call()
            samples.append(time.perf_counter() - t0)
        times[name] = min(samples)
    err = float(np.abs(gpu_force - f).max() / np.abs(f).max())
    return CpuReference(mesh.n_cells, numba.get_num_threads(), times["f"], times["fK"], err)


def judge(fig_sizes, material: str, simulated: bool) -> Tuple[TargetOutcome, ...]:
    """The targets with their figures; never judged on the simulator."""
    out = []
    for t in TARGETS:
        if simulated:
            out.append(TargetOutcome(t.name, t.tets_per_s, None, None, "not judged: simulator"))
            continue
        near = [s for s in fig_sizes if t.cells / 1.5 <= s.cells <= 1.5 * t.cells]
        timing = near[0].timing(t.method, t.dtype, t.quantity) if near else None
        if material != t.material or timing is None:
            why = "material" if material != t.material else "size or method"
            out.append(TargetOutcome(t.name, t.tets_per_s, None, None, f"not measured ({why})"))
            continue
        v = timing.tets_per_s
        note = f" at {near[0].cells:,} tets"
        out.append(TargetOutcome(t.name, t.tets_per_s, v, v >= t.tets_per_s, note))
    return tuple(out)


def measure(
    material_name: str = "NeoHookean",
    sizes: Sequence[int] = DEFAULT_SIZES,
    *,
    min_time: float = 0.25,
    copy_bytes: int = 2**30,
    cpu: bool = True,
    say: Callable[[str], None] = lambda s: None,
) -> GpuFigures:
    """The GPU figures (see the module docstring). ``say`` reports progress."""
    from common.cases import default_material
    from mjed.cuda import simulated

    t_start = time.perf_counter()
    material = default_material(material_name)
    copy_GBs = copy_bandwidth(copy_bytes)
    say(f"device copy bandwidth {copy_GBs:.0f} GB/s")
    checks: List[Verification] = []
    allowed = {(m, d) for m in METHODS for d in DTYPES}
    done, cpu_mesh = [], None
    for target in sorted(sizes):
        say(f"size {target:,}")
        size, mesh, _ = measure_size(
            target, material, allowed, copy_GBs, min_time, None if checks else checks
        )
        if checks:  # checked on the first size that was built
            allowed = {(v.method, v.dtype) for v in checks if v.passed}
        done.append(size)
        if mesh is not None and mesh.n_cells <= CPU_MAX_CELLS:
            cpu_mesh = mesh
    say("CPU reference")
    ref = cpu_reference(cpu_mesh, material, min_time) if cpu and cpu_mesh is not None else None
    return GpuFigures(
        "measured",
        material_name,
        device_name(),
        utc_now(),
        simulated(),
        copy_GBs,
        free_memory(),
        tuple(checks),
        tuple(done),
        ref,
        judge(done, material_name, simulated()),
        time.perf_counter() - t_start,
    )


def not_run(reason: str, material_name: str = "NeoHookean") -> GpuFigures:
    """The section of a run without a device: the reason, every target unjudged."""
    targets = tuple(TargetOutcome(t.name, t.tets_per_s, None, None, reason) for t in TARGETS)
    return GpuFigures(reason, material_name, date=utc_now(), targets=targets)


def device_name() -> str:
    from numba import cuda

    try:
        name = cuda.get_current_device().name
    except AttributeError:  # Numba's CUDA simulator
        return "Numba CUDA simulator"
    return name.decode() if isinstance(name, bytes) else str(name)


def utc_now() -> str:
    return f"{_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC"


# ------------------------------------------------------------------ printing
def print_figures(fig: GpuFigures, out: Callable[[str], None] = print) -> None:
    """The section as text: one line per size, precision, method and quantity, the CPU
    ratio and one line per target.
    """
    if not fig.measured:
        out(f"GPU: {fig.status}")
    else:
        out(
            f"GPU: {fig.device}{' (figures meaningless: simulator)' if fig.simulated else ''}, "
            f"{fig.date}, {fig.material}, device copy bandwidth {fig.copy_GBs:.0f} GB/s, "
            f"{fig.seconds:.0f} s"
        )
        for v in fig.verification:
            out(
                f"  check {v.method:<9s} {v.dtype} on {v.cells:,} tets against NumPy: force "
                f"{v.force_err:.1e}, stiffness {v.stiffness_err:.1e} (tol {v.tol:.0e}) "
                f"{'ok' if v.passed else 'DIFFERS: not timed'}"
            )
        for size in fig.sizes:
            _print_size(size, out)
        _print_cpu(fig, out)
    for t in fig.targets:
        out(f"  {t.line()}")


def _print_size(size: GpuSize, out) -> None:
    out(
        f"  {size.cells:,} tets, {size.nodes:,} nodes, CSR {size.nnz:,} values: FP64 "
        f"{size.csr_bytes['float64'] / 1e9:.2f} GB, FP32 {size.csr_bytes['float32'] / 1e9:.2f} "
        f"GB; device memory FP64 {size.needed_bytes['float64'] / 1e9:.2f} GB, FP32 "
        f"{size.needed_bytes['float32'] / 1e9:.2f} GB; host set-up {size.setup_s:.1f} s"
    )
    for reason in size.skipped:
        out(f"    skipped {reason}")
    for t in size.timings:
        out(
            f"    {t.method:<9s} {t.dtype} {t.quantity:<3s} {t.best_s * 1e3:9.3f} ms  "
            f"{t.tets_per_s:.3e} tets/s  {t.GBs:7.1f} GB/s ({100 * t.copy_fraction:4.1f} % of "
            f"copy)  median {t.median_s * 1e3:.3f} ms of {t.repeats}"
        )
    for dtype in DTYPES:
        for q in QUANTITIES:
            m, c = size.timing("mjed", dtype, q), size.timing("classical", dtype, q)
            if m and c:
                out(f"    classical / MJED, {dtype} {q}: {c.best_s / m.best_s:.2f}x")


def _print_cpu(fig: GpuFigures, out) -> None:
    ref = fig.cpu
    if ref is None:
        out("  CPU reference: not run")
        return
    out(
        f"  CPU compiled MJED, {ref.threads} threads, {ref.cells:,} tets: force "
        f"{ref.f_s * 1e3:.2f} ms ({ref.cells / ref.f_s:.3e} tets/s), force + stiffness "
        f"{ref.fK_s * 1e3:.2f} ms ({ref.cells / ref.fK_s:.3e} tets/s); its force against the "
        f"GPU's {ref.force_vs_gpu:.1e}"
    )
    size = next((s for s in fig.sizes if s.cells == ref.cells), None)
    for q, cpu_s in (("f", ref.f_s), ("f+K", ref.fK_s)):
        t = size.timing("mjed", "float64", q) if size else None
        if t is not None:
            out(f"  GPU / CPU, MJED FP64 {q} at {ref.cells:,} tets: {cpu_s / t.best_s:.1f}x")
