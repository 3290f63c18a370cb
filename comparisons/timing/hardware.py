"""MJED at the hardware's limit: the figures of one run, printed (docs/studies/timing.md).

    python -m comparisons.timing.hardware                       # cube-paper, NeoHookean
    python -m comparisons.timing.hardware --materials NeoHookean,Ogden --mesh cube-medium
    python -m comparisons.timing.hardware --json figures.json

CPU: force + stiffness and force alone on one mesh by the NumPy engine, the compiled kernel
on one thread and the compiled kernel on all of Numba's threads (CompiledForceField with
parallel=True; its force + stiffness also on one thread, which measures its cell order
without the threads), and both again cell-batched (``batch=B``, mjed.compiled.batched: the
cell body over B cells at once, one per SIMD lane; B is mjed.compiled.batched.DEFAULT_BATCH,
cpu_figures(batch=...) for another), in nanoseconds per cell, against two floors measured in
the same run:

- the bandwidth floor (comparisons.timing.bandwidth): the bytes force + stiffness must move at
  least, over the copy bandwidth of this machine (one thread, and all threads);
- the compute floor: the kernel's flops per cell, counted from its generated source
  (comparisons.timing.opcount.mjed_source_flops), over this machine's measured peak: the flop rate
  of a vectorised polynomial kernel (Horner, 64 flops per element on an array in L1 cache,
  every lane and FMA unit busy), on one thread and on all.

Every figure is the best of interleaved rounds (each round times every method once, in a
rotated order), so drift and other work on the machine hit them alike; the spread over the
rounds is printed with it.

GPU (comparisons.timing.gpu): MJED (mjed.cuda) and the classical element generated and
compiled the same way (reference_fem.classical_cuda) timed on the device, positions, forces
and CSR values left there, FP64 and FP32, force only and force + stiffness, in tets per
second on structured cubes of 1e4 to 1e7 tets (a size that does not fit the device memory is
skipped with the bytes it needs), with the GB/s each achieves against the device's copy
bandwidth measured in the same run; the compiled CPU backend on all cores of the same
machine at up to 1e6 tets for the GPU/CPU ratio; one line per target (met or missed, with
the figure). Without a CUDA device the section prints "not run: no GPU" and no target is
judged (and it never times the simulator).

    python -m comparisons.timing.hardware --json gpu.json         # on the GPU machine
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from comparisons.timing.gpu import DEFAULT_SIZES as DEFAULT_GPU_SIZES

__all__ = ["measure_peak_flops", "cpu_figures", "gpu_figures", "main"]

#: Horner steps of the peak kernel (2 flops each).
_HORNER = 32


def _peak_kernels():
    """The Horner kernel, serial and over threads. 32 multiply-adds per element written out,
    the coefficients scalar arguments of a separate function whose only loop runs over the
    elements: that loop is what the compiler turns into SIMD (measured: with the coefficients
    read from an array inside the same function, or the multiply-adds in a loop, Numba 0.56
    emits scalar FMAs, 3 to 4 Gflop/s here instead of 20 to 30).
    """
    from numba import njit, prange

    coefs = ", ".join(f"c{k}" for k in range(_HORNER + 1))
    steps = "\n".join(f"        acc = acc * v + c{k}" for k in range(1, _HORNER + 1))
    args = ", ".join(f"c[{k}]" for k in range(_HORNER + 1))
    source = f"""
def horner(x, y, {coefs}):
    for i in range(x.shape[0]):
        v = x[i]
        acc = c0
{steps}
        y[i] = acc


def run(x, y, c, reps, threads):
    block = x.shape[0] // threads
    for t in prange(threads):
        for _ in range(reps):
            lo, hi = t * block, (t + 1) * block
            horner(x[lo:hi], y[lo:hi], {args})
"""
    namespace = {"prange": prange}
    exec(compile(source, "<peak kernel>", "exec"), namespace)
    namespace["horner"] = njit(fastmath=True, inline="never", cache=False)(namespace["horner"])
    run = namespace["run"]
    return njit(cache=False)(run), njit(cache=False, parallel=True)(run)


def measure_peak_flops(threads: int, seconds: float = 0.2) -> float:
    """Flops per second of a vectorised Horner kernel on ``threads`` threads (1: serial),
    4 KiB of data per thread (in L1 cache).
    """
    import numba

    serial, parallel = _peak_kernels()
    kernel = serial if threads == 1 else parallel
    threads = max(1, threads)
    old = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        n = 512 * threads
        x = np.linspace(0.5, 0.9, n)
        y = np.empty(n)
        c = np.linspace(0.1, 0.2, _HORNER + 1) / _HORNER
        kernel(x, y, c, 1, threads)
        reps = 100
        while True:
            t0 = time.perf_counter()
            kernel(x, y, c, reps, threads)
            dt = time.perf_counter() - t0
            if dt > seconds / 5:
                break
            reps *= 4
        best = dt
        for _ in range(4):
            t0 = time.perf_counter()
            kernel(x, y, c, reps, threads)
            best = min(best, time.perf_counter() - t0)
    finally:
        numba.set_num_threads(old)
    return 2.0 * _HORNER * n * reps / best


def _rounds(
    calls: Dict[str, Callable[[], object]], rounds: int, min_batch_s: float
) -> Dict[str, dict]:
    """Best and spread of seconds per call of each callable, interleaved rounds."""
    batch = {}
    for name, fn in calls.items():  # warm up, then choose a batch lasting min_batch_s
        fn()
        t0 = time.perf_counter()
        fn()
        dt = max(time.perf_counter() - t0, 1e-7)
        batch[name] = max(1, int(min_batch_s / dt))
    samples: Dict[str, List[float]] = {name: [] for name in calls}
    names = list(calls)
    for r in range(rounds):
        for name in names[r % len(names) :] + names[: r % len(names)]:
            fn, k = calls[name], batch[name]
            t0 = time.perf_counter()
            for _ in range(k):
                fn()
            samples[name].append((time.perf_counter() - t0) / k)
    return {
        name: {"best_s": min(v), "median_s": float(np.median(v)), "spread": max(v) / min(v) - 1.0}
        for name, v in samples.items()
    }


def cpu_figures(
    mesh_name: str,
    material_name: str,
    rounds: int = 7,
    min_batch_s: float = 0.05,
    batch: Optional[int] = None,
) -> dict:
    """The CPU figures of one material on one mesh (see the module docstring)."""
    import numba

    import mjed
    from meshes import catalog

    points, cells = catalog.resolve(mesh_name)[:2]
    mesh = mjed.TetMesh(points, cells)
    material = _material(material_name)
    rng = np.random.default_rng(0)
    h = (mesh.volumes.mean() * 6) ** (1 / 3)
    x = points * [1.08, 0.97, 0.98] + 0.02 * h * rng.standard_normal(points.shape)
    threads = numba.get_num_threads()
    fields = _checked_fields(mesh, material, x, batch)
    calls = {}
    for name, field in fields.items():
        calls[f"{name} f+K"] = (lambda fl: lambda: fl.force_and_stiffness(x))(field)
        calls[f"{name} f"] = (lambda fl: lambda: fl.force(x))(field)

    def one_thread():  # the parallel schedule run by one thread: its cell order, no threads
        numba.set_num_threads(1)
        try:
            fields["numba-parallel"].force_and_stiffness(x)
        finally:
            numba.set_num_threads(threads)

    calls["numba-parallel-1thread f+K"] = one_thread
    timed = _rounds(calls, rounds, min_batch_s)
    m, n, nnz = mesh.n_cells, mesh.n_nodes, fields["numba-serial"].pattern.nnz
    out = {"mesh": mesh_name, "material": material_name, "cells": m, "nodes": n, "nnz": nnz}
    out.update(_cpu_floors(material, threads, n, m, nnz))
    flops = out["flops_per_cell"]
    out["timings"] = {}
    for name, t in timed.items():
        out["timings"][name] = dict(t, ns_per_cell=t["best_s"] / m * 1e9, ms=t["best_s"] * 1e3)
        if name.endswith("f+K") and not name.startswith("numpy"):
            out["timings"][name]["Gflops"] = flops * m / t["best_s"] / 1e9
    out["ratios"] = _cpu_ratios({k: v["best_s"] for k, v in timed.items()})
    out["colours"] = fields["numba-parallel"].schedule.n_colours
    out["batch"] = fields["numba-batched"].batch
    return out


def _cpu_ratios(tf: Dict[str, float]) -> Dict[str, float]:
    """Speed-ups from one run's best times (a / b: how many times faster b is than a)."""
    pairs = [
        ("numpy", "numba-serial", "f+K"),
        ("numpy", "numba-parallel", "f+K"),
        ("numba-serial", "numba-parallel", "f+K"),
        ("numba-serial", "numba-parallel", "f"),
        ("numpy", "numba-batched", "f+K"),
        ("numpy", "numba-batched-parallel", "f+K"),
        ("numba-serial", "numba-batched", "f+K"),
        ("numba-serial", "numba-batched", "f"),
        ("numba-parallel", "numba-batched-parallel", "f+K"),
        ("numba-parallel", "numba-batched-parallel", "f"),
    ]
    return {f"{a} / {b}, {q}": tf[f"{a} {q}"] / tf[f"{b} {q}"] for a, b, q in pairs}


def _checked_fields(mesh, material, x: np.ndarray, batch: Optional[int] = None) -> dict:
    """The NumPy, serial and parallel fields, and the serial and parallel cell-batched ones
    (``batch`` cells per batch, default mjed.compiled.batched.DEFAULT_BATCH), the compiled
    ones checked against NumPy's force and stiffness at x before anything is timed.
    """
    import mjed
    from mjed.compiled.batched import DEFAULT_BATCH

    b = DEFAULT_BATCH if batch is None else batch
    numba = dict(backend="numba")
    fields = {
        "numpy": mjed.make_force_field(mesh, material),
        "numba-serial": mjed.make_force_field(mesh, material, **numba),
        "numba-parallel": mjed.make_force_field(mesh, material, **numba, parallel=True),
        "numba-batched": mjed.make_force_field(mesh, material, **numba, batch=b),
        "numba-batched-parallel": mjed.make_force_field(
            mesh, material, **numba, batch=b, parallel=True
        ),
    }
    f_ref, K_ref = fields["numpy"].force_and_stiffness(x)
    for name in list(fields)[1:]:
        f, K = fields[name].force_and_stiffness(x)
        if not (
            np.abs(f - f_ref).max() <= 1e-12 * np.abs(f_ref).max()
            and abs(K - K_ref).max() <= 1e-12 * abs(K_ref).max()
        ):
            raise RuntimeError(f"{name} differs from the NumPy engine: not timed")
    return fields


def _cpu_floors(material, threads: int, n: int, m: int, nnz: int) -> dict:
    """Bandwidth and compute floors per cell, on one thread and on all of them."""
    from comparisons.timing.bandwidth import floor_bytes, measure_bandwidth
    from comparisons.timing.opcount import mjed_source_flops

    bw1 = measure_bandwidth().bytes_per_s
    bw_all = _parallel_bandwidth(threads)
    flops = mjed_source_flops(material)
    peak1, peak_all = measure_peak_flops(1), measure_peak_flops(threads)
    floor_b = floor_bytes(n, m, nnz)
    return {
        "threads": threads,
        "flops_per_cell": flops,
        "floor_bytes": floor_b,
        "bandwidth_GBs": {"1 thread": bw1 / 1e9, f"{threads} threads": bw_all / 1e9},
        "peak_Gflops": {"1 thread": peak1 / 1e9, f"{threads} threads": peak_all / 1e9},
        "floors_ns_per_cell": {
            "bandwidth, 1 thread": floor_b / bw1 / m * 1e9,
            f"bandwidth, {threads} threads": floor_b / bw_all / m * 1e9,
            "compute, 1 thread": flops / peak1 * 1e9,
            f"compute, {threads} threads": flops / peak_all * 1e9,
        },
    }


def _parallel_bandwidth(threads: int) -> float:
    """Copy bandwidth (read + write bytes/s) of a 64 MiB array on ``threads`` threads."""
    from numba import njit, prange

    @njit(parallel=True, cache=False)
    def copy(src, dst):
        for i in prange(src.shape[0]):
            dst[i] = src[i]

    n = 8 * 2**20
    src, dst = np.ones(n), np.zeros(n)
    copy(src, dst)
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        copy(src, dst)
        best = min(best, time.perf_counter() - t0)
    return 16.0 * n / best


def _material(name: str):
    """A material by name, with the parameters every study uses (common.cases)."""
    from common.cases import default_material

    return default_material(name)


def _material_names() -> list:
    from common.cases import DEFAULT_MATERIALS

    return list(DEFAULT_MATERIALS)


# ------------------------------------------------------------------ GPU
def gpu_status() -> Optional[str]:
    """None when a real CUDA device can be timed, else why not ("no GPU", "simulator", ...)."""
    from mjed.cuda import cuda_available, simulated

    if simulated():
        return "not run: NUMBA_ENABLE_CUDASIM is set (Numba's CUDA simulator is not a GPU)"
    if not cuda_available():
        return "not run: no GPU (numba.cuda found no CUDA device)"
    return None


def gpu_figures(
    material_name: str = "NeoHookean",
    sizes: Sequence[int] = DEFAULT_GPU_SIZES,
    *,
    min_time: float = 0.25,
    copy_bytes: int = 2**30,
    cpu: bool = True,
    say=lambda s: None,
):
    """The GPU figures (comparisons.timing.gpu.GpuFigures): MJED and the classical element on
    the device per size, precision and quantity, the copy bandwidth, the compiled CPU backend
    for the ratio and the targets (see comparisons.timing.gpu).
    """
    from comparisons.timing.gpu import measure

    return measure(material_name, sizes, min_time=min_time, copy_bytes=copy_bytes, cpu=cpu, say=say)


# ------------------------------------------------------------------ printing
def _print_cpu(fig: dict) -> None:
    print(
        f"CPU: {fig['material']} on {fig['mesh']} ({fig['cells']} cells, {fig['nodes']} nodes, nnz "
        f"{fig['nnz']}), "
        f"{fig['threads']} threads, {fig['colours']} colours in the parallel schedule"
    )
    print(
        "  measured: copy bandwidth "
        + ", ".join(f"{k} {v:.1f} GB/s" for k, v in fig["bandwidth_GBs"].items())
        + "; peak "
        + ", ".join(f"{k} {v:.1f} Gflop/s" for k, v in fig["peak_Gflops"].items())
    )
    print(
        f"  kernel: {fig['flops_per_cell']} flops per cell (generated source); floor bytes "
        f"{fig['floor_bytes'] / fig['cells']:.0f} per cell"
    )
    for k, v in fig["floors_ns_per_cell"].items():
        print(f"  floor {k:<28s} {v:8.1f} ns/cell")
    for k, v in fig["timings"].items():
        extra = f"  {v['Gflops']:.1f} Gflop/s" if "Gflops" in v else ""
        print(
            f"  {k:<24s} {v['ms']:8.3f} ms  {v['ns_per_cell']:8.1f} ns/cell  (spread "
            f"{100 * v['spread']:.0f} %)"
            f"{extra}"
        )
    for k, v in fig["ratios"].items():
        print(f"  {k:<40s} {v:6.2f}x")


def _print_gpu(fig) -> None:
    from comparisons.timing.gpu import print_figures

    print_figures(fig)


def _add_gpu_options(ap: argparse.ArgumentParser) -> None:
    ap.add_argument(
        "--gpu-sizes",
        default=",".join(str(s) for s in DEFAULT_GPU_SIZES),
        help="tets of the GPU cubes (default 1e4 to 1e7; a size that does not fit the device "
        "memory is skipped, saying why)",
    )
    ap.add_argument(
        "--gpu-min-time",
        type=float,
        default=0.25,
        help="seconds of repeated calls per GPU figure (default 0.25; at least 3 calls)",
    )
    ap.add_argument("--no-gpu", action="store_true", help="skip the GPU section")
    ap.add_argument(
        "--no-cpu",
        action="store_true",
        help="skip the CPU section (the GPU section still times the compiled CPU backend on all "
        "cores of this machine for its GPU/CPU ratio)",
    )


def _gpu_section(args, material_name: str) -> dict:
    """Run (or say why not) and print the GPU section; its record as a dict for --json."""
    from comparisons.timing.gpu import not_run

    status = "not run: --no-gpu" if args.no_gpu else gpu_status()
    sizes = [int(float(s)) for s in args.gpu_sizes.split(",") if s]
    if status is None:
        fig = gpu_figures(
            material_name,
            sizes,
            min_time=args.gpu_min_time,
            say=lambda s: print(f"  GPU: {s}", file=sys.stderr, flush=True),
        )
    else:
        fig = not_run(status, material_name)
    _print_gpu(fig)
    return fig.to_dict()


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m comparisons.timing.hardware",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument(
        "--mesh", default="cube-paper", help="catalog name or mesh file (default cube-paper)"
    )
    ap.add_argument(
        "--materials",
        default="NeoHookean",
        help=f"comma-separated, of {', '.join(_material_names())}",
    )
    ap.add_argument("--rounds", type=int, default=7, help="interleaved timing rounds (default 7)")
    _add_gpu_options(ap)
    ap.add_argument("--json", help="also write the figures to this file")
    args = ap.parse_args(argv)
    names = [s for s in args.materials.split(",") if s]
    unknown = [s for s in names if s not in _material_names()]
    if unknown or args.rounds < 1:
        ap.error(f"unknown material(s) {unknown}" if unknown else "--rounds must be >= 1")
    from mjed.compiled.kernels import prefer_passive_wait

    prefer_passive_wait()  # as a parallel field does, before anything starts Numba's threads
    import numba

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"MJED hardware figures, {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs, "
        f"Numba {numba.__version__}, OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY')}, "
        f"load average {load:.2f} before"
    )
    figures = {"cpu": [], "load_before": load}
    for name in [] if args.no_cpu else names:
        fig = cpu_figures(args.mesh, name, rounds=args.rounds)
        figures["cpu"].append(fig)
        _print_cpu(fig)
    figures["gpu"] = _gpu_section(args, names[0])
    figures["load_after"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"load average {figures['load_after']:.2f} after (a load above the core count means other "
        "work "
        f"shared the cores: the parallel figures are then pessimistic)"
    )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(figures, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
