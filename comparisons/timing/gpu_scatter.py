"""Does the stiffness scatter bound the CUDA force + stiffness kernel? The experiment of
docs/studies/timing.md ("the 144 atomic adds per cell into the CSR values remain the first
suspect"), printed as figures on a real GPU:

    python -m comparisons.timing.gpu_scatter --json OUT.json [--sizes 1e5,1e6,1e7]
        [--material NeoHookean] [--dtypes float64,float32] [--budget 70]

For structured cubes (meshes.structured.cube_with_cells, as comparisons.timing.gpu), each
precision, MJED's CUDA field (mjed.cuda.CudaForceField) generated both ways
(:class:`mjed.cuda.codegen.Assembly`) and timed with positions, forces and values on the
device, best of adaptive repeats with the device synchronised after each call
(comparisons.timing.gpu.time_device):

- ``force``: the force kernel alone (the reference: no stiffness code);
- ``atomic f+K``: today's kernel, 144 atomic adds per cell into the CSR values (which the call
  zeroes first);
- ``element kernel``: the cell kernel of the element assembly alone, each cell storing its
  144 entries into a (144, m) array, one row per entry (coalesced stores), no atomics but the
  force's;
- ``gather``: the gather kernel alone, one thread per 3x3 block of the pattern summing its
  cells' entries through the incidence built on the host (mjed.cuda.codegen.element_incidence);
- ``element f+K``: the two in sequence;
- ``edge kernel``: the cell kernel of the edge assembly alone, each cell storing only its six
  edge blocks K_ab (a < b), 54 values, into a (54, m) array (2.7x fewer stores);
- ``edge gather``: its gather kernel alone, one thread per 3x3 block of the pattern summing
  the edge blocks of its cell edges (transposed where the edge runs the other way; minus the
  sum of every edge touching the node for a diagonal block: K_aa = -sum_b K_ab), through the
  incidence mjed.cuda.codegen.edge_incidence (24 contributions per cell, against the
  element gather's 16);
- ``edge f+K``: the two in sequence.

The force is atomic in every assembly (12 adds per cell). Before timing, at each size and
precision, the element and edge paths' CSR values and force are compared with the atomic
path's (largest difference over the largest entry); a path that disagrees beyond
:data:`TOLERANCE` is not timed (the atomic and force figures still are). Ratios are of
figures from the same run. It needs a real device: without one (or under Numba's CUDA
simulator) it says so and exits 2; :func:`measure` runs anywhere numba.cuda does (the tests run
it on the simulator, figures meaningless). Sizes after the first are started only while less
than ``--budget`` seconds have passed (the 1e7 cube: about a minute of host set-up).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Callable, Dict, Optional, Sequence

import numpy as np

from comparisons.timing.gpu import (
    MEMORY_SHARE,
    bench_state,
    cube_counts,
    device_bytes,
    device_name,
    free_memory,
    time_device,
    utc_now,
)

__all__ = ["DEFAULT_SIZES", "TOLERANCE", "VARIANTS", "extra_bytes", "measure", "main"]

DEFAULT_SIZES = (100_000, 1_000_000, 10_000_000)
DTYPES = ("float64", "float32")
#: Element against atomic, largest difference over largest entry (summation orders differ).
TOLERANCE = {"float64": 1e-12, "float32": 1e-5}
VARIANTS = (
    "force",
    "atomic f+K",
    "element kernel",
    "gather",
    "element f+K",
    "edge kernel",
    "edge gather",
    "edge f+K",
)
#: The variants of each gathered path, timed only where the path agrees with the atomic one.
PATHS = {
    "element": ("element kernel", "gather", "element f+K"),
    "edge": ("edge kernel", "edge gather", "edge f+K"),
}


def extra_bytes(cells: int, blocks: int, dtype: str) -> int:
    """Device bytes the element and edge assemblies add to comparisons.timing.gpu.device_bytes:
    the per-cell entries (144 m values) and edge blocks (54 m), a second CSR array (shared by
    the two gathers), the incidences (16 m and 24 m contributions, offsets, block starts and
    row lengths, the edge one's diagonal flags; int32 while they fit, as the launcher's).
    """
    isz = np.dtype(dtype).itemsize
    idx = 4 if 144 * cells < 2**31 else 8
    eidx = 4 if 2 * 54 * cells < 2**31 and 24 * cells < 2**31 else 8
    element = 144 * cells * isz + idx * (16 * cells + 3 * blocks + 1)
    edge = 54 * cells * isz + eidx * (24 * cells + 4 * blocks + 1)
    return element + edge + 9 * blocks * isz


def _calls(fields, launcher, x_d, arrays) -> Dict[str, Callable[[], object]]:
    """The timed calls, by :data:`VARIANTS` name."""
    atomic, element, edge = fields
    f, data_a, data_g, ke, kg = arrays

    def both():
        element.device_element_stiffness(x_d, out=(f, ke))
        launcher.gather(ke, data_g)

    def edge_both():
        edge.device_element_stiffness(x_d, out=(f, kg))
        launcher.gather(kg, data_g, "edge")

    return {
        "force": lambda: atomic.device_force_and_stiffness(x_d, stiffness=False, out=(f, data_a)),
        "atomic f+K": lambda: atomic.device_force_and_stiffness(x_d, out=(f, data_a)),
        "element kernel": lambda: element.device_element_stiffness(x_d, out=(f, ke)),
        "gather": lambda: launcher.gather(ke, data_g),
        "element f+K": both,
        "edge kernel": lambda: edge.device_element_stiffness(x_d, out=(f, kg)),
        "edge gather": lambda: launcher.gather(kg, data_g, "edge"),
        "edge f+K": edge_both,
    }


def _check(calls, arrays, tol: float) -> dict:
    """The element and edge paths against the atomic one at the same positions (run once
    each): the element path's figures at the top level (K, f, agrees), the edge path's under
    "edge".
    """
    f, data_a, data_g = arrays[:3]
    calls["atomic f+K"]()
    f_a, K_a = f.copy_to_host(), data_a.copy_to_host()

    def rel(a, b):
        return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))

    out = {"tol": tol}
    for path in PATHS:
        data_g.copy_to_device(np.full(data_g.shape[0], np.nan, dtype=data_g.dtype))
        calls[PATHS[path][2]]()
        K, force = data_g.copy_to_host(), f.copy_to_host()
        got = {"K": rel(K, K_a), "f": rel(force, f_a)}
        got["agrees"] = all(v <= tol for v in got.values())  # NaN (a value not written): no
        if path == "element":
            out.update(got)
        else:
            out[path] = got
    return out


def _precision(mesh, material, layout, dtype: str, min_time: float) -> dict:
    """Check, then time, the variants in one precision on one mesh."""
    from mjed.cuda import CudaForceField
    from mjed.cuda.codegen import BLOCK_ENTRIES, EDGE_ENTRIES
    from mjed.cuda.launch import CellLauncher

    launcher = CellLauncher(mesh, dtype, layout)
    fields = [
        CudaForceField(mesh, material, dtype=dtype, launcher=launcher, assembly=a)
        for a in ("atomic", "element", "edge")
    ]
    cuda, nnz = launcher.cuda, launcher.pattern.nnz
    x_d = launcher.to_device(bench_state(mesh.points))
    arrays = (
        cuda.device_array((mesh.n_nodes, 3), dtype=dtype),
        cuda.device_array(nnz, dtype=dtype),
        cuda.device_array(nnz, dtype=dtype),
        cuda.device_array((BLOCK_ENTRIES, mesh.n_cells), dtype=dtype),
        cuda.device_array((EDGE_ENTRIES, mesh.n_cells), dtype=dtype),
    )
    calls = _calls(fields, launcher, x_d, arrays)
    check = _check(calls, arrays, TOLERANCE[dtype])
    refused = set()
    if not check["agrees"]:
        refused.update(PATHS["element"])
    if not check["edge"]["agrees"]:
        refused.update(PATHS["edge"])
    out = {"check": check, "timings": {}}
    for name, call in calls.items():
        if name in refused:
            continue  # a variant that disagrees is not timed
        best, median, repeats = time_device(call, min_time)
        out["timings"][name] = {
            "best_s": best,
            "median_s": median,
            "repeats": repeats,
            "tets_per_s": mesh.n_cells / best,
        }
    out["ratios"] = _ratios({k: v["best_s"] for k, v in out["timings"].items()})
    return out


def _ratios(best: Dict[str, float]) -> Dict[str, float]:
    """Time ratios of one run's best times (a / b > 1: b is faster)."""
    pairs = [
        ("atomic f+K", "element f+K"),
        ("atomic f+K", "element kernel"),
        ("atomic f+K", "force"),
        ("element kernel", "force"),
        ("gather", "element f+K"),
        ("atomic f+K", "edge f+K"),
        ("element f+K", "edge f+K"),
        ("element kernel", "edge kernel"),
        ("gather", "edge gather"),
        ("edge kernel", "force"),
    ]
    return {f"{a} / {b}": best[a] / best[b] for a, b in pairs if a in best and b in best}


def measure_size(target: int, material, dtypes, min_time: float, say) -> dict:
    """One cube: its counts, the host set-up, and per precision the check and the timings
    (or why it was skipped: the device memory it needs).
    """
    import mjed
    from meshes.structured import cube_with_cells
    from mjed.cuda.launch import BlockLayout

    _, cells, nodes, nnz = cube_counts(target)
    need = {d: device_bytes(cells, nodes, nnz, d) + extra_bytes(cells, nnz // 9, d) for d in dtypes}
    row = {"target": target, "cells": cells, "nodes": nodes, "nnz": nnz, "needed_bytes": need}
    t0 = time.perf_counter()
    mesh = mjed.TetMesh(*cube_with_cells(target))
    layout = BlockLayout.of(mesh)
    row["layout_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    row["blocks"] = layout.incidence.blocks
    row["incidence_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    layout.edge_incidence
    row["edge_incidence_s"] = time.perf_counter() - t0
    row["precisions"], row["skipped"] = {}, {}
    for dtype in dtypes:
        free = free_memory()
        if need[dtype] > MEMORY_SHARE * free:
            row["skipped"][dtype] = f"needs {need[dtype] / 1e9:.2f} GB, {free / 1e9:.2f} GB free"
            continue
        say(f"{cells:,} tets {dtype}")
        row["precisions"][dtype] = _precision(mesh, material, layout, dtype, min_time)
    return row


def measure(
    material_name: str = "NeoHookean",
    sizes: Sequence[int] = DEFAULT_SIZES,
    *,
    dtypes: Sequence[str] = DTYPES,
    min_time: float = 0.2,
    budget: float = 70.0,
    say: Callable[[str], None] = lambda s: None,
) -> dict:
    """The figures of the experiment (see the module docstring) as a JSON-ready dict."""
    from common.cases import default_material
    from mjed.cuda import simulated

    start = time.perf_counter()
    material = default_material(material_name)
    rows, not_started = [], []
    for k, target in enumerate(sorted(sizes)):
        if k and time.perf_counter() - start > budget:
            not_started.append(target)
            continue
        rows.append(measure_size(target, material, dtypes, min_time, say))
    return {
        "device": device_name(),
        "date": utc_now(),
        "simulated": simulated(),
        "material": material_name,
        "sizes": rows,
        "not_started": not_started,
        "budget_s": budget,
        "seconds": time.perf_counter() - start,
    }


def print_figures(fig: dict, out: Callable[[str], None] = print) -> None:
    """The figures as text: per size and precision the check, each variant's time and rate,
    and the ratios.
    """
    note = " (simulator: figures meaningless)" if fig["simulated"] else ""
    out(f"{fig['device']}{note}, {fig['date']}, {fig['material']}, {fig['seconds']:.0f} s")
    for row in fig["sizes"]:
        counts = f"{row['cells']:,} tets, {row['nnz']:,} CSR values in {row['blocks']:,} blocks"
        host = (
            f"layout {row['layout_s']:.1f} s, incidence {row['incidence_s']:.1f} s, "
            f"edge incidence {row['edge_incidence_s']:.1f} s"
        )
        out(f"  {counts}; host: {host}")
        skipped = "; ".join(f"{d} ({why})" for d, why in row["skipped"].items())
        if skipped:
            out(f"    skipped: {skipped}")
        for dtype, p in row["precisions"].items():
            c = p["check"]
            for path, got in (("element", c), ("edge", c["edge"])):
                verdict = "agrees" if got["agrees"] else f"DISAGREES: {path} variants not timed"
                out(
                    f"    {dtype} {path} vs atomic: K {got['K']:.1e}, f {got['f']:.1e} "
                    f"(tol {c['tol']:.0e}) {verdict}"
                )
            for name, t in p["timings"].items():
                out(
                    f"    {dtype} {name:<15s} {t['best_s'] * 1e3:9.3f} ms  "
                    f"{t['tets_per_s']:.3e} tets/s  (median {t['median_s'] * 1e3:.3f} ms of "
                    f"{t['repeats']})"
                )
            for name, r in p["ratios"].items():
                out(f"    {dtype} time {name:<32s} {r:6.2f}")
    for target in fig["not_started"]:
        out(f"  {target:,} tets not started: past the budget of {fig['budget_s']:.0f} s")


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m comparisons.timing.gpu_scatter", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--json", help="also write the figures here")
    ap.add_argument(
        "--sizes", default=",".join(f"{s:.0e}" for s in DEFAULT_SIZES), help="tets per cube"
    )
    ap.add_argument("--material", default="NeoHookean")
    ap.add_argument("--dtypes", default=",".join(DTYPES), help="of float64, float32")
    ap.add_argument("--min-time", type=float, default=0.2, help="seconds of repeats per figure")
    ap.add_argument("--budget", type=float, default=70.0, help="seconds before the last sizes")
    args = ap.parse_args(argv)
    from common.cases import DEFAULT_MATERIALS

    dtypes = [d for d in args.dtypes.split(",") if d]
    if args.material not in DEFAULT_MATERIALS or not set(dtypes) <= set(DTYPES) or not dtypes:
        ap.error(f"--material of {', '.join(DEFAULT_MATERIALS)}; --dtypes of {', '.join(DTYPES)}")
    from comparisons.timing.hardware import gpu_status

    why = gpu_status()
    if why:
        print(f"gpu_scatter: needs a real NVIDIA GPU: {why}; nothing timed", file=sys.stderr)
        return 2
    sizes = [int(float(s)) for s in args.sizes.split(",") if s]
    fig = measure(
        args.material,
        sizes,
        dtypes=dtypes,
        min_time=args.min_time,
        budget=args.budget,
        say=lambda s: print(f"  {s}", file=sys.stderr, flush=True),
    )
    print_figures(fig)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(fig, fh, indent=1)
    bad = [
        p
        for r in fig["sizes"]
        for p in r["precisions"].values()
        if not (p["check"]["agrees"] and p["check"]["edge"]["agrees"])
    ]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
