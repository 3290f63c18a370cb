"""The timing study (paper, Fig. 2) and the scaling study, each returning a StudyResult.

``timing_study`` times force+stiffness, force and stiffness on one mesh and one state for
each material and each method of :mod:`comparisons.timing_methods`: MJED and the classical
Galerkin, each in NumPy and compiled (Numba), dolfinx's compiled assembly, and the peer
libraries (FElupe, SfePy) where their energy matches. Before a method is timed its result is
compared with NumPy MJED's (proven equal to the UFL oracle); a method that does not match is
not timed. The like-for-like answer to Fig. 2 is the compiled pair: compiled classical over
compiled MJED, set beside the operation-count model of :mod:`comparisons.opcount`. Each
force+stiffness time is also set against the floor implied by the bytes the result must move
at this machine's copy bandwidth (:mod:`comparisons.bandwidth`).

How measurements are repeated is the protocol (:mod:`comparisons.timing_protocol`): the
default ``budget`` protocol stops repeating once the spread is small; ``paper`` is the paper's
100 calls x 3 repeats. Ratios are formed within each round, then summarised (median, range).

Peak memory: each method runs in a fresh subprocess; the resident-set high-water mark
(Linux VmHWM, reset through /proc/self/clear_refs) is read after constructing the method and
one force+stiffness call, minus the resident set before construction (persistent data and the
working arrays of one call, including what C libraries allocate).

``scaling_study`` times force+stiffness on structured cubes of growing size, each (method,
size) in a fresh subprocess, with the time and memory per cell.
"""

from __future__ import annotations

import gc
import json
import os
import shlex
import subprocess
import sys
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from common.result import Check, StudyResult
from comparisons.timing_protocol import calls_for, relative_spread, summary, time_batch
from comparisons.timing_protocol import protocol as get_protocol

KEY = "timing"
TITLE = "Timing: MJED and the classical FEM, NumPy and compiled, dolfinx and peers (paper Fig. 2)"
SCALING_KEY = "scaling"
SCALING_TITLE = "Scaling with mesh size"

__all__ = [
    "KEY", "TITLE", "SCALING_KEY", "SCALING_TITLE", "WHATS", "DEFAULT_METHODS", "timing_study", "scaling_study", "timing_command", "scaling_command",
    "measure_memory", "timing_state", "check_methods",
]

WHATS = ("force+stiffness", "force", "stiffness")
DEFAULT_METHODS = ("mjed", "mjed-numba", "classical", "classical-numba", "dolfinx", "felupe", "sfepy")
REFERENCE = "mjed"  # NumPy MJED: every result is compared with it, every ratio is against an MJED

#: Targets (issues 4 and 15), on force+stiffness unless said.
PAPER_SPEEDUP = 5.0  # the paper: MJED up to 5x faster than the standard FEM (St Venant-Kirchhoff)
FLOOR_FACTOR = 2.0  # compiled MJED within 2x of the bandwidth floor (NeoHookean)
COMPILED_SPEEDUP = 3.0  # compiled MJED at least 3x faster than the NumPy engine (NeoHookean)
PEER_SPEEDUP = 3.0  # NumPy MJED at least 3x faster than FElupe
TARGET_MATERIAL = "NeoHookean"
VERIFY_TOL = 1e-10  # the equivalence study's force and stiffness tolerances

#: Ratio pairs (numerator / denominator) formed per round; the first method must be timed too.
PAIRS = (("classical", "mjed"), ("classical-numba", "mjed-numba"), ("mjed", "mjed-numba"), ("dolfinx", "mjed"),
         ("felupe", "mjed"), ("sfepy", "mjed"))

#: Scaling: target cell counts of the structured cube (6 n^3 cells).
SCALING_SIZES = (1_000, 10_000, 100_000, 1_000_000)
QUICK_SCALING_SIZES = (1_000, 6_000)
SCALING_METHODS = ("mjed", "mjed-numba", "classical-numba", "dolfinx")
FLATNESS_TARGET = 2.0  # max/min time per cell of MJED from 1e4 to 1e6 cells
FLATNESS_RANGE = (1e4, 1.5e6)


# ------------------------------------------------------------------ shared helpers
def timing_state(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The deformed positions every method is timed at: the equivalence study's seeded
    smooth random field with a rotation (J > 0.2 everywhere), so no branch is trivial."""
    from common.states import smooth_random

    return smooth_random(points, cells)


def _load_mesh(mesh: Any) -> Tuple[np.ndarray, np.ndarray]:
    if isinstance(mesh, dict):
        from meshes.structured import cube_with_cells

        return cube_with_cells(int(mesh["structured"]))
    import meshes

    points, cells, _ = meshes.resolve(mesh)
    return points, cells


def _names(materials: "str | Iterable[str]") -> List[str]:
    from common.cases import DEFAULT_MATERIALS, parse_materials

    mats = parse_materials(materials)
    return [next(k for k, v in DEFAULT_MATERIALS.items() if v is m) for m in mats]


def check_methods(methods: "str | Sequence[str]") -> Tuple[str, ...]:
    from comparisons.timing_methods import get

    if isinstance(methods, str):
        methods = [m.strip() for m in methods.split(",") if m.strip()]
    if not methods:
        raise ValueError("no method given")
    for m in methods:
        get(m)  # raises naming the known methods
    methods = tuple(dict.fromkeys(methods))
    if REFERENCE not in methods:
        raise ValueError(f"the methods must include {REFERENCE!r} (NumPy MJED: the reference every result is "
                         "checked against)")
    return methods


def timing_command(materials: Sequence[str], mesh: str, *, quick: bool, protocol: str, methods: Sequence[str],
                   memory: bool, out_dir: Optional[str], json_path: Optional[str] = None) -> str:
    """The mjed-verify command line that runs exactly this timing study."""
    parts = ["mjed-verify", "timing", "--material", ",".join(materials), "--mesh", str(mesh), "--methods",
             ",".join(methods), "--protocol", protocol]
    parts += ["--quick"] if quick else []
    parts += [] if memory else ["--no-memory"]
    parts += ["--out", out_dir] if out_dir else []
    parts += ["--json", json_path] if json_path else []
    return shlex.join(parts)


def scaling_command(*, quick: bool, material: str, methods: Sequence[str], max_cells: Optional[int],
                    out_dir: Optional[str], json_path: Optional[str] = None) -> str:
    parts = ["mjed-verify", "timing", "--scaling", "--scaling-material", material, "--methods", ",".join(methods)]
    parts += ["--quick"] if quick else []
    parts += ["--max-cells", str(max_cells)] if max_cells else []
    parts += ["--out", out_dir] if out_dir else []
    parts += ["--json", json_path] if json_path else []
    return shlex.join(parts)


def _load() -> Optional[List[float]]:
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


# ------------------------------------------------------------------ memory (subprocess)
def _status_kib() -> Dict[str, int]:
    out = {}
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(("VmHWM", "VmRSS")):
                key, value = line.split(":")
                out[key] = int(value.split()[0])
    return out


def _memory_worker(spec: Dict[str, Any]) -> Dict[str, Any]:
    """Runs in a fresh process: peak resident-set growth of building ``spec['method']``
    and one force+stiffness call, then ``repeats`` timed calls."""
    from common.cases import default_material
    from comparisons.timing_methods import get

    method = get(spec["method"])
    points, cells = _load_mesh(spec["mesh"])
    material = default_material(spec["material"])
    x = timing_state(points, cells)
    gc.collect()
    with open("/proc/self/clear_refs", "w") as fh:  # reset VmHWM to the current RSS
        fh.write("5")
    before = _status_kib()["VmRSS"]
    t0 = time.perf_counter()
    obj = method.build(points, cells, material)
    setup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    obj.force_and_stiffness(x)
    first_s = time.perf_counter() - t0
    after = _status_kib()
    times = [time_batch(obj.force_and_stiffness, x, 1) for _ in range(spec.get("repeats", 0))]
    return {"peak_bytes": 1024 * (after["VmHWM"] - before), "resident_after_bytes": 1024 * (after["VmRSS"] - before),
            "setup_s": setup_s, "first_call_s": first_s, "times_s": times, "n_cells": int(len(cells)),
            "n_nodes": int(len(points))}


def measure_memory(method: str, material: str, mesh: Any, *, repeats: int = 0, timeout: float = 1800.0) -> Dict[str, Any]:
    """Run the memory worker in a subprocess; its dict, or {'error': ...}.
    mesh: a catalog name or path, or {'structured': n_cells}."""
    if not os.path.exists("/proc/self/clear_refs"):
        return {"error": "peak memory needs Linux /proc (VmHWM); not measured"}
    spec = {"method": method, "material": material, "mesh": mesh, "repeats": repeats}
    env = dict(os.environ)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    try:
        proc = subprocess.run([sys.executable, "-m", "comparisons.timing", json.dumps(spec)], capture_output=True,
                              text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return {"error": f"did not finish within {timeout:.0f} s"}
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        if proc.returncode < 0 or "MemoryError" in proc.stderr:
            return {"error": f"out of memory or killed (exit {proc.returncode}): {tail}"}
        return {"error": f"worker failed (exit {proc.returncode}): {tail}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------------ the timing study
def timing_study(
    materials: "str | Iterable[str]" = "all",
    mesh: str = "cube-paper",
    *,
    quick: bool = False,
    out_dir: Optional[str] = "reports/timing",
    progress: Optional[Callable[[str], None]] = None,
    protocol: str = "budget",
    methods: "str | Sequence[str]" = DEFAULT_METHODS,
    memory: bool = True,
    command: Optional[str] = None,
) -> StudyResult:
    """Time force+stiffness, force and stiffness for materials x methods; a StudyResult.

    Args:
        materials: 'all', a name, a comma-separated list or an iterable of names.
        mesh: a catalog name or a mesh file (quick: cube-small unless another is given).
        quick: a complete but small run (cube-small, the quick protocol, memory of one material).
        out_dir: where the figure goes (None: no figure).
        progress: called with one line per material and round.
        protocol: "budget" (default) or "paper" (100 calls x 3 repeats); see timing_protocol.
        methods: names of comparisons.timing_methods; must include "mjed".
        memory: measure peak memory in subprocesses (all materials under "paper", else one).
        command: the command line that ran (default: the equivalent mjed-verify command).
    """
    from common.cases import default_material
    from comparisons import timing_blocks
    from comparisons.bandwidth import floor_bytes, measure_bandwidth
    from comparisons.opcount import model
    from comparisons.provenance import provenance
    from comparisons.timing_methods import get, verify
    from mjed.sparse import CSRPattern

    t_start = time.perf_counter()
    if quick and mesh == "cube-paper":
        mesh = "cube-small"
    proto = get_protocol("quick" if quick and protocol == "budget" else protocol)
    methods = check_methods(methods)
    names = _names(materials)
    cmd = command or timing_command(names, mesh, quick=quick, protocol=protocol, methods=methods, memory=memory,
                                    out_dir=out_dir)
    say = progress or (lambda msg: None)
    load_before = _load()
    points, cells = _load_mesh(mesh)
    x = timing_state(points, cells)
    edge = float(np.mean(np.linalg.norm(points[cells[:, 1]] - points[cells[:, 0]], axis=1)))
    pattern = CSRPattern(cells, len(points))
    say("bandwidth: copy of 64 MiB")
    bw = measure_bandwidth()
    floor_b = floor_bytes(len(points), len(cells), pattern.nnz)
    floor_s = floor_b / bw.bytes_per_s

    not_covered: List[str] = []
    if quick:
        not_covered.append(f"quick run: {mesh} and the quick protocol instead of cube-paper and the budget protocol")
    unavailable = {m: get(m).unavailable() for m in methods}
    for m, why in unavailable.items():
        if why:
            not_covered.append(f"{get(m).label} not timed: {why}")
    active = [m for m in methods if not unavailable[m]]

    samples: Dict[Tuple[str, str, str], List[float]] = {}
    calls: Dict[Tuple[str, str, str], int] = {}
    stopped: Dict[str, Tuple[int, str]] = {}
    verification: Dict[Tuple[str, str], Any] = {}
    skipped: Dict[Tuple[str, str], str] = {}
    setup: Dict[Tuple[str, str], float] = {}
    for name in names:
        material = default_material(name)
        objs: Dict[str, Any] = {}
        reference = None
        for m in active:
            spec = get(m)
            why = spec.unsupported(material)
            if why:
                skipped[(name, m)] = f"energy cannot be matched: {why}"
                continue
            t0 = time.perf_counter()
            try:
                obj = spec.build(points, cells, material)
            except Exception as exc:  # a peer refusing at build time: not timed, said why
                skipped[(name, m)] = f"could not be built: {type(exc).__name__}: {exc}"
                continue
            if m == REFERENCE:
                reference = obj.force_and_stiffness(x)
            objs[m] = obj
            setup[(name, m)] = time.perf_counter() - t0
        for m, obj in objs.items():
            v = verify(get(m), obj, x, reference, edge, VERIFY_TOL) if m != REFERENCE else None
            if v is not None:
                verification[(name, m)] = v
                if not v.passed:
                    skipped[(name, m)] = f"not timed: {v.note}"
        timed = {m: o for m, o in objs.items() if (name, m) not in skipped}
        fns = {(m, w): getattr(o, _ATTR[w]) for m, o in timed.items() for w in WHATS if hasattr(o, _ATTR[w])}
        for (m, w), fn in fns.items():  # warm-up (lazy maps, JIT, caches), then a second call sizes the batches
            fn(x)
            t0 = time.perf_counter()
            fn(x)
            calls[(name, m, w)] = calls_for(proto, time.perf_counter() - t0)
        order = list(timed)
        elapsed = 0.0
        rounds = 0
        while True:
            shift = rounds % max(1, len(order))
            for w in WHATS:
                for m in order[shift:] + order[:shift]:
                    if (m, w) in fns:
                        t = time_batch(fns[(m, w)], x, calls[(name, m, w)])
                        samples.setdefault((name, m, w), []).append(t)
                        elapsed += t * calls[(name, m, w)]
            rounds += 1
            spreads = [relative_spread(samples[(name, m, w)]) for (m, w) in fns]
            say(f"{name}: round {rounds}: " + ", ".join(
                f"{m} {samples[(name, m, 'force+stiffness')][-1] * 1e3:.2f} ms" for m in order
                if (name, m, "force+stiffness") in samples))
            why = proto.should_stop(rounds, spreads, elapsed)
            if why:
                stopped[name] = (rounds, why)
                break
        del objs, timed, fns
        gc.collect()

    results = []
    for (name, m, w), v in samples.items():
        s = summary(v)
        results.append({"material": name, "method": m, "what": w, "median_s": s["median"], "min_s": s["min"],
                        "max_s": s["max"], "repeats": len(v), "calls_per_repeat": calls[(name, m, w)],
                        "spread": relative_spread(v), "stopped_by": stopped[name][1], "protocol": proto.name})
    ratios = []
    for num, den in PAIRS:
        for name in names:
            for w in WHATS:
                a, b = samples.get((name, num, w)), samples.get((name, den, w))
                if not a or not b:
                    continue
                per = [p / q for p, q in zip(a, b)]
                s = summary(per)
                ratios.append({"material": name, "what": w, "ratio": f"{num}/{den}", "median": s["median"],
                               "min": s["min"], "max": s["max"], "per_repeat": per})
    opcount = {name: model(default_material(name)) for name in names}

    mem = []
    if memory:
        mem_names = names if proto.name == "paper" else [TARGET_MATERIAL if TARGET_MATERIAL in names else names[0]]
        for name in mem_names:
            for m in active:
                if (name, m) in skipped:
                    continue
                say(f"{name}: peak memory of {m} (subprocess)")
                rec = measure_memory(m, name, mesh)
                mem.append({"material": name, "method": m, **{k: rec[k] for k in ("peak_bytes", "resident_after_bytes",
                                                                                    "error") if k in rec}})

    data: Dict[str, Any] = {
        "mesh": {"name": str(mesh), "n_cells": int(len(cells)), "n_nodes": int(len(points)), "nnz": int(pattern.nnz)},
        "results": results,
        "ratios": ratios,
        "opcount": opcount,
        "bandwidth": bw.to_dict(),
        "floor": {"bytes": floor_b, "seconds": floor_s,
                  "what": "CSR values and force written once; positions, connectivity (int32) and rest geometry "
                          "(D, V0) read once; at the measured copy bandwidth"},
        "verification": [{"material": n, "method": m, **v.to_dict()} for (n, m), v in verification.items()],
        "skipped": [{"material": n, "method": m, "reason": r} for (n, m), r in skipped.items()],
        "memory": mem,
        "memory_note": ("peak_bytes: resident-set high-water mark (VmHWM) of a fresh process after building the "
                        "method and one force+stiffness call, minus its resident set before building"),
        "setup_s": [{"material": n, "method": m, "seconds": s} for (n, m), s in setup.items()],
        "rounds": {n: {"rounds": r, "stopped_by": why} for n, (r, why) in stopped.items()},
        "settings": {"protocol": proto.name, "protocol_text": proto.describe(), "methods": list(active),
                     "labels": {m: get(m).label for m in methods}, "quick": quick, "iterations": proto.calls or "adaptive",
                     "repeats": max((r for r, _ in stopped.values()), default=0),
                     "state": "smooth_random (seed 0)", "timer": "time.perf_counter, mean per call, gc off"},
        "load_average": {"before": load_before, "after": _load()},
        "provenance": provenance(with_dolfinx="dolfinx" in active),
        "figures": [],
    }
    checks = _timing_checks(data, names, str(mesh))
    data["targets"] = [_target_dict(c) for c in checks if c.kind == "target"]
    if out_dir:
        from comparisons import figures_timing

        os.makedirs(out_dir, exist_ok=True)
        data["figures"].append(figures_timing.plot_fig2(data, os.path.join(out_dir, "timing_fig2.png")))
    blocks = timing_blocks.timing_blocks(data, checks)
    headline = timing_blocks.timing_headline(data)
    return StudyResult.from_checks(KEY, TITLE, checks, headline=headline, command=cmd,
                                   not_covered=tuple(not_covered), protocol=proto.describe(), data=data, blocks=blocks,
                                   seconds=time.perf_counter() - t_start)


_ATTR = {"force+stiffness": "force_and_stiffness", "force": "force", "stiffness": "stiffness"}


def _median(data: dict, material: str, method: str, what: str = "force+stiffness") -> Optional[float]:
    for r in data["results"]:
        if (r["material"], r["method"], r["what"]) == (material, method, what):
            return r["median_s"]
    return None


def _ratio(data: dict, material: str, pair: str, what: str = "force+stiffness") -> Optional[float]:
    for r in data["ratios"]:
        if (r["material"], r["ratio"], r["what"]) == (material, pair, what):
            return r["median"]
    return None


def _timing_checks(data: dict, names: List[str], mesh: str) -> List[Check]:
    """The verification tolerances and the speed targets, each with its figure and a note."""
    checks: List[Check] = []
    for v in data["verification"]:
        if v["force_err"] is None or v["method"] in ("felupe", "sfepy"):
            continue  # by construction; peers that differ are not timed, and said so
        checks.append(Check(f"{v['method']} matches NumPy MJED before timing, {v['material']} (force, stiffness)",
                            max(v["force_err"], v["stiffness_err"]), VERIFY_TOL))
    opc = data["opcount"]
    for name in names:
        for pair, label in (("classical/mjed", "NumPy"), ("classical-numba/mjed-numba", "compiled")):
            r = _ratio(data, name, pair)
            if r is None:
                continue
            note = ""
            if label == "compiled":
                pred = opc[name]["predicted_ratio"]
                note = f"operation-count model predicts {pred:.2f}x; measured/predicted {r / pred:.2f}"
            checks.append(Check(f"MJED faster than the classical FEM ({label} pair), {name} on {mesh}", r, 1.0, ">=",
                                "target", note))
        if name == "StVenantKirchhoff":
            r = _ratio(data, name, "classical-numba/mjed-numba")
            pred = opc[name]["predicted_ratio"]
            checks.append(Check(f"paper's claim: classical/MJED >= {PAPER_SPEEDUP:g}x, compiled pair, {name} on {mesh}",
                                r, PAPER_SPEEDUP, ">=", "target",
                                f"the operation-count model predicts {pred:.2f}x for these two kernels"))
        r = _ratio(data, name, "dolfinx/mjed")
        if r is not None:
            checks.append(Check(f"NumPy MJED no slower than dolfinx (force+stiffness), {name} on {mesh}", r, 1.0, ">=",
                                "target"))
        r = _ratio(data, name, "dolfinx/mjed", "force")
        if r is not None:
            checks.append(Check(f"NumPy MJED force no slower than dolfinx's residual, {name} on {mesh}", r, 1.0, ">=",
                                "target"))
        r = _ratio(data, name, "felupe/mjed")
        if r is not None:
            checks.append(Check(f"NumPy MJED at least {PEER_SPEEDUP:g}x faster than FElupe, {name} on {mesh}", r,
                                PEER_SPEEDUP, ">=", "target"))
    t = TARGET_MATERIAL
    if t in names:
        comp = _median(data, t, "mjed-numba")
        floor = data["floor"]["seconds"]
        flops = opc[t]["mjed_source"]  # counted from the generated kernel's source
        cells = data["mesh"]["n_cells"]
        checks.append(Check(f"compiled MJED within {FLOOR_FACTOR:g}x of the bandwidth floor, {t} on {mesh}",
                            None if comp is None else comp / floor, FLOOR_FACTOR, "<=", "target",
                            "not measured: compiled MJED not timed" if comp is None else
                            f"floor {floor * 1e3:.3f} ms at {data['bandwidth']['GB_per_s']:.1f} GB/s, so {FLOOR_FACTOR:g}x "
                            f"the floor is {FLOOR_FACTOR * floor / cells * 1e9:.0f} ns per cell; the kernel takes "
                            f"{comp / cells * 1e9:.0f} ns per cell for about {flops} flops ({flops * cells / comp / 1e9:.2f} "
                            "Gflop/s measured): a serial kernel at that arithmetic is compute-bound, not memory-bound"))
        r = _ratio(data, t, "mjed/mjed-numba")
        checks.append(Check(f"compiled MJED at least {COMPILED_SPEEDUP:g}x faster than the NumPy engine, {t} on {mesh}",
                            r, COMPILED_SPEEDUP, ">=", "target",
                            "not measured: compiled MJED not timed" if r is None else
                            f"NumPy {_median(data, t, 'mjed') * 1e3:.2f} ms, compiled "
                            f"{_median(data, t, 'mjed-numba') * 1e3:.2f} ms; for the same {flops} flops per cell that "
                            f"is {_gflops(flops, data, t, 'mjed'):.2f} and {_gflops(flops, data, t, 'mjed-numba'):.2f} "
                            "Gflop/s: the NumPy engine already runs each step as a whole-array (SIMD) operation over "
                            "all cells, the compiled kernel is scalar per cell"))
    return checks


def _gflops(flops: int, data: dict, material: str, method: str) -> float:
    """Model flops per second of a method's force+stiffness (the op-count model's MJED count)."""
    return flops * data["mesh"]["n_cells"] / _median(data, material, method) / 1e9


def _target_dict(c: Check) -> dict:
    return {"target": c.name, "measured": c.measured, "required": c.limit, "relation": c.relation,
            "met": c.passed, "note": c.note}


# ------------------------------------------------------------------ the scaling study
def scaling_study(
    *,
    quick: bool,
    out_dir: Optional[str] = "reports/timing",
    progress: Optional[Callable[[str], None]] = None,
    material: str = "NeoHookean",
    methods: "str | Sequence[str]" = SCALING_METHODS,
    sizes: Optional[Sequence[int]] = None,
    max_cells: Optional[int] = None,
    time_budget_s: float = 25.0,
    repeats: int = 3,
    command: Optional[str] = None,
) -> StudyResult:
    """Force+stiffness time and peak memory per cell on structured cubes of growing size.

    Each (size, method) runs in a fresh subprocess (build, one call for the peak memory, then
    ``repeats`` timed calls; the best is reported). A method stops growing when a size fails
    (memory) or took longer than ``time_budget_s`` (build and calls); the reason is recorded.
    """
    from common.cases import default_material
    from comparisons import timing_blocks
    from comparisons.provenance import provenance
    from comparisons.timing_methods import get

    t_start = time.perf_counter()
    default_material(material)  # raises on an unknown name
    methods = check_methods(methods)
    if sizes is None:
        sizes = QUICK_SCALING_SIZES if quick else SCALING_SIZES
    if quick:
        repeats = min(repeats, 2)
    if max_cells is not None:
        sizes = [s for s in sizes if s <= max_cells]
    cmd = command or scaling_command(quick=quick, material=material, methods=methods, max_cells=max_cells,
                                     out_dir=out_dir)
    say = progress or (lambda msg: None)
    rows: List[dict] = []
    stopped: Dict[str, str] = {}
    for m in methods:
        why = get(m).unavailable()
        if why:
            stopped[m] = f"not run: {why}"
    for size in sizes:
        for m in methods:
            if m in stopped:
                continue
            say(f"scaling: {m} on ~{size:,} cells")
            t0 = time.perf_counter()
            rec = measure_memory(m, material, {"structured": int(size)}, repeats=repeats,
                                 timeout=max(600.0, 20 * time_budget_s))
            wall = time.perf_counter() - t0
            if "error" in rec:
                stopped[m] = f"stopped at ~{size:,} cells: {rec['error']}"
                continue
            best = min(rec["times_s"]) if rec["times_s"] else rec["first_call_s"]
            rows.append({"method": m, "target_cells": int(size), "n_cells": rec["n_cells"], "n_nodes": rec["n_nodes"],
                         "seconds": best, "seconds_per_cell": best / rec["n_cells"], "peak_bytes": rec["peak_bytes"],
                         "peak_bytes_per_cell": rec["peak_bytes"] / rec["n_cells"], "setup_s": rec["setup_s"],
                         "wall_s": wall})
            if wall > time_budget_s and size != sizes[-1]:
                stopped[m] = (f"stopped after ~{size:,} cells: that size took {wall:.0f} s "
                              f"(budget {time_budget_s:.0f} s per size)")
    for m in methods:
        stopped.setdefault(m, f"completed all sizes up to ~{max(sizes):,} cells")
    largest = max((r["n_cells"] for r in rows), default=0)
    smallest = min((r["n_cells"] for r in rows), default=0)
    not_covered = []
    if max(sizes) < FLATNESS_RANGE[0] * 100 * 0.9:
        not_covered.append(f"sizes only up to ~{max(sizes):,} cells (the flatness target spans 1e4 to 1e6)")
    for m, why in stopped.items():
        if not why.startswith("completed"):
            not_covered.append(f"{get(m).label}: {why}")
    data = {
        "material": material, "rows": rows, "stopped": stopped,
        "settings": {"sizes": [int(s) for s in sizes], "repeats": repeats, "time_budget_s": time_budget_s,
                     "mesh": "structured unit cube, 6 tetrahedra per hexahedron (meshes.structured)", "quick": quick,
                     "methods": list(methods), "labels": {m: get(m).label for m in methods}},
        "load_average": _load(),
        "provenance": provenance(with_dolfinx="dolfinx" in methods),
        "figures": [],
    }
    checks = _flatness_checks(rows)
    data["targets"] = [_target_dict(c) for c in checks]
    if out_dir and rows:
        from comparisons import figures_timing

        os.makedirs(out_dir, exist_ok=True)
        data["figures"].append(figures_timing.plot_scaling(data, os.path.join(out_dir, "timing_scaling.png")))
    protocol = (f"each (method, size) in a fresh process: build, one call (peak memory), then the best of {repeats} "
                f"timed calls; a method stops growing after a size that took over {time_budget_s:.0f} s")
    return StudyResult.from_checks(
        SCALING_KEY, f"{SCALING_TITLE}: force+stiffness from {smallest:,} to {largest:,} cells", checks,
        headline=timing_blocks.scaling_headline(data), command=cmd, not_covered=tuple(not_covered),
        protocol=protocol, data=data, blocks=timing_blocks.scaling_blocks(data, checks),
        seconds=time.perf_counter() - t_start)


def _flatness_checks(rows: List[dict]) -> List[Check]:
    lo, hi = FLATNESS_RANGE
    out = []
    for m in ("mjed", "mjed-numba"):
        per = [r["seconds_per_cell"] for r in rows if r["method"] == m and lo <= r["n_cells"] <= hi]
        name = f"{m} time per cell flat within {FLATNESS_TARGET:g}x from 1e4 to 1e6 cells"
        if not any(r["method"] == m for r in rows):
            continue
        if len(per) < 2:
            out.append(Check(name, None, FLATNESS_TARGET, "<=", "target", "fewer than two sizes in that range were measured"))
        else:
            out.append(Check(name, max(per) / min(per), FLATNESS_TARGET, "<=", "target"))
    return out


if __name__ == "__main__":  # the subprocess worker of measure_memory
    print(json.dumps(_memory_worker(json.loads(sys.argv[1]))))
