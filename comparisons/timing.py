"""The timing study (paper, Fig. 2): force and stiffness assembly, MJED against the others.

Three methods assemble the same quantities for the same material and state:

- ``mjed``: ``HyperelasticForceField.force_and_stiffness`` (nodal forces and the assembled
  SciPy CSR stiffness), the public path;
- ``classical``: ``ClassicalGalerkin`` (S and the 6x6 elasticity tensor, K_e = geometric +
  B^T C B), same geometry and same CSR assembly as MJED;
- ``dolfinx``: compiled UFL forms, residual vector and PETSc Jacobian (quadrature degree 1;
  form compilation excluded), see :mod:`reference_fem.dolfinx_assembly`.

Protocol: for each material every method is built and called once (pattern, index maps,
JIT: excluded); then, ``repeats`` times, each of force+stiffness, force and stiffness is
timed for every method as the mean over ``iterations`` calls (the paper's protocol), the
methods back to back in an order rotated each repeat, so that machine drift hits them all
alike. Ratios classical/mjed and dolfinx/mjed are formed within each repeat, then
summarised by median, min and max. Garbage collection is off while a batch is timed.

Peak memory: each method runs in a fresh subprocess; the resident-set high-water mark
(Linux VmHWM, reset through /proc/self/clear_refs) is read after constructing the method and
one force+stiffness call, minus the resident set before construction. It is the whole extra
memory the method needs for one assembly (its persistent data: patterns, index maps,
compiled forms, PETSc matrix; plus the working arrays of the call), including PETSc's and
the C libraries' allocations that tracemalloc cannot see.
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

__all__ = [
    "METHODS",
    "WHATS",
    "run_timing",
    "run_scaling",
    "format_markdown",
    "format_scaling_markdown",
    "measure_memory",
]

METHODS = ("mjed", "classical", "dolfinx")
WHATS = ("force+stiffness", "force", "stiffness")

#: Targets of issue 4, checked on force+stiffness.
STVK_TARGET = 5.0  # the paper's St Venant-Kirchhoff speed-up over the standard FEM
FLATNESS_TARGET = 2.0  # max/min MJED time per cell from 1e4 to 1e6 cells
FLATNESS_RANGE = (1e4, 1.5e6)

#: Default scaling sizes (target cell counts of the structured cube; 6 n^3 cells).
SCALING_SIZES = (1_000, 10_000, 30_000, 100_000, 300_000, 1_000_000)
QUICK_SCALING_SIZES = (1_000, 6_000)


# ------------------------------------------------------------------------- the methods
def build_method(method: str, points: np.ndarray, cells: np.ndarray, material) -> Dict[str, Callable]:
    """{what: f(x)} for one method, fully set up (compiled, patterns and maps built)."""
    if method == "mjed":
        import mjed

        field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material)
        return {"force+stiffness": field.force_and_stiffness, "force": field.force, "stiffness": field.stiffness}
    if method == "classical":
        import mjed
        from reference_fem.classical import ClassicalGalerkin

        cg = ClassicalGalerkin(mjed.TetMesh(points, cells), None, material)
        return {"force+stiffness": cg.force_and_stiffness, "force": cg.force, "stiffness": cg.stiffness}
    if method == "dolfinx":
        from reference_fem.dolfinx_assembly import DolfinxAssembly

        dx = DolfinxAssembly(points, cells, material)
        return {"force+stiffness": dx.force_and_stiffness, "force": dx.force, "stiffness": dx.stiffness}
    raise ValueError(f"unknown method {method!r}; known: {', '.join(METHODS)}")


def timing_state(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The deformed positions every method is timed at: the equivalence study's seeded
    smooth random field with a rotation (J > 0.2 everywhere), so no branch is trivial."""
    from comparisons.states import smooth_random

    return smooth_random(points, cells)


def _time_batch(fn: Callable, x: np.ndarray, iterations: int) -> float:
    """Mean seconds per call over ``iterations`` calls, garbage collection off."""
    gc.collect()
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        t0 = time.perf_counter()
        for _ in range(iterations):
            fn(x)
        return (time.perf_counter() - t0) / iterations
    finally:
        if was_enabled:
            gc.enable()


def _summary(values: Sequence[float]) -> Dict[str, float]:
    v = np.asarray(values, dtype=float)
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max())}


# ------------------------------------------------------------------------- memory
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
    and one force+stiffness call, then (optionally) timed calls."""
    from comparisons.cases import default_material

    points, cells = _load_mesh(spec["mesh"])
    material = default_material(spec["material"])
    x = timing_state(points, cells)
    gc.collect()
    with open("/proc/self/clear_refs", "w") as fh:  # reset VmHWM to the current RSS
        fh.write("5")
    before = _status_kib()["VmRSS"]
    t0 = time.perf_counter()
    fns = build_method(spec["method"], points, cells, material)
    setup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    fns["force+stiffness"](x)
    first_s = time.perf_counter() - t0
    after = _status_kib()
    times = [_time_batch(fns["force+stiffness"], x, spec.get("iterations", 1)) for _ in range(spec.get("repeats", 0))]
    return {
        "peak_bytes": 1024 * (after["VmHWM"] - before),
        "resident_after_bytes": 1024 * (after["VmRSS"] - before),
        "setup_s": setup_s,
        "first_call_s": first_s,
        "times_s": times,
        "n_cells": int(len(cells)),
        "n_nodes": int(len(points)),
    }


def measure_memory(method: str, material: str, mesh: Any, *, repeats: int = 0, iterations: int = 1,
                   timeout: float = 1800.0) -> Dict[str, Any]:
    """Run :func:`_memory_worker` in a subprocess; returns its dict, or {'error': ...}.

    mesh: a catalog name or path, or {'structured': n_cells}.
    """
    if not os.path.exists("/proc/self/clear_refs"):
        return {"error": "peak memory needs Linux /proc (VmHWM); not measured"}
    spec = {"method": method, "material": material, "mesh": mesh, "repeats": repeats, "iterations": iterations}
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


def _load_mesh(mesh: Any) -> Tuple[np.ndarray, np.ndarray]:
    if isinstance(mesh, dict):
        from meshes.structured import cube_with_cells

        return cube_with_cells(int(mesh["structured"]))
    import meshes

    points, cells, _ = meshes.resolve(mesh)
    return points, cells


# ------------------------------------------------------------------------- the study
def run_timing(
    materials: "str | Iterable[str]" = "all",
    mesh: str = "cube-paper",
    *,
    iterations: int = 100,
    repeats: int = 3,
    methods: Sequence[str] = METHODS,
    out_dir: Optional[str] = "reports/timing",
    json_path: Optional[str] = None,
    memory: bool = True,
    quick: bool = False,
    progress: Optional[Callable[[str], None]] = None,
) -> Dict[str, Any]:
    """Time force+stiffness, force and stiffness for materials x methods.

    Args:
        materials: 'all', a name, a comma-separated list or an iterable of names.
        mesh: a catalog name or a mesh file.
        iterations: calls averaged per measurement (the paper: 100).
        repeats: interleaved repeats per measurement (>= 1); ratios are formed per repeat.
        methods: a subset of METHODS; ratios need 'mjed'.
        out_dir: where the Markdown table and the Fig. 2 chart go (None: not written).
        json_path: also write the result there.
        memory: measure peak memory in subprocesses.
        quick: a complete but small run (cube-small unless another mesh is given,
            3 iterations, 2 repeats).

    Returns:
        {"mesh", "results", "ratios", "memory", "targets", "settings", "provenance",
        "figures", "tables"}, JSON-serialisable.
    """
    from comparisons.cases import DEFAULT_MATERIALS, parse_materials
    from comparisons.provenance import provenance

    if quick:
        if mesh == "cube-paper":
            mesh = "cube-small"
        iterations, repeats = min(iterations, 3), min(repeats, 2)
    if iterations < 1 or repeats < 1:
        raise ValueError(f"iterations and repeats must be >= 1, got {iterations} and {repeats}")
    methods = _check_methods(methods)
    mats = parse_materials(materials)
    names = [next(k for k, v in DEFAULT_MATERIALS.items() if v is m) for m in mats]
    say = progress or (lambda msg: None)
    points, cells = _load_mesh(mesh)
    x = timing_state(points, cells)

    samples: Dict[Tuple[str, str, str], List[float]] = {}
    setup: Dict[Tuple[str, str], float] = {}
    for name, material in zip(names, mats):
        fns = {}
        for method in methods:
            t0 = time.perf_counter()
            fns[method] = build_method(method, points, cells, material)
            for what in WHATS:  # warm-up: lazy patterns, index maps, JIT, caches
                fns[method][what](x)
            setup[(name, method)] = time.perf_counter() - t0
        for r in range(repeats):
            order = list(methods[r % len(methods):]) + list(methods[: r % len(methods)])
            for what in WHATS:
                for method in order:
                    samples.setdefault((name, method, what), []).append(_time_batch(fns[method][what], x, iterations))
            say(f"{name}: repeat {r + 1}/{repeats}: " + ", ".join(
                f"{m} {samples[(name, m, 'force+stiffness')][-1] * 1e3:.1f} ms" for m in methods))
        del fns
        gc.collect()

    results = []
    for (name, method, what), v in samples.items():
        s = _summary(v)
        results.append({"material": name, "method": method, "what": what, "median_s": s["median"],
                        "min_s": s["min"], "max_s": s["max"], "repeats": len(v)})
    ratios = []
    if "mjed" in methods:
        for other in (m for m in methods if m != "mjed"):
            for name in names:
                for what in WHATS:
                    per = [o / j for o, j in zip(samples[(name, other, what)], samples[(name, "mjed", what)])]
                    s = _summary(per)
                    ratios.append({"material": name, "what": what, "ratio": f"{other}/mjed", "median": s["median"],
                                   "min": s["min"], "max": s["max"], "per_repeat": per})

    mem = []
    if memory:
        # A fresh process per measurement costs about a second; a quick run measures one material.
        for name in names[:1] if quick else names:
            for method in methods:
                say(f"{name}: peak memory of {method} (subprocess)")
                rec = measure_memory(method, name, mesh)
                mem.append({"material": name, "method": method, **{k: rec.get(k) for k in
                            ("peak_bytes", "resident_after_bytes", "error") if k in rec}})

    result = {
        "mesh": {"name": str(mesh), "n_cells": int(len(cells)), "n_nodes": int(len(points))},
        "results": results,
        "ratios": ratios,
        "memory": mem,
        "memory_note": ("peak_bytes: resident-set high-water mark (VmHWM) of a fresh process after building the "
                        "method and one force+stiffness call, minus its resident set before building; includes "
                        "persistent data (patterns, index maps, compiled forms, PETSc matrix) and the call's "
                        "working arrays"),
        "setup_s": [{"material": n, "method": m, "seconds": s} for (n, m), s in setup.items()],
        "targets": _targets(ratios, mesh),
        "settings": {"iterations": iterations, "repeats": repeats, "methods": list(methods), "quick": quick,
                     "state": "smooth_random (seed 0)", "timer": "time.perf_counter, mean over iterations, gc off"},
        "provenance": provenance(with_dolfinx="dolfinx" in methods),
        "figures": [],
        "tables": [],
    }
    return _write_outputs(result, out_dir, json_path, "timing", format_markdown, "plot_fig2")


def _check_methods(methods: "str | Sequence[str]") -> Tuple[str, ...]:
    if isinstance(methods, str):
        methods = [m.strip() for m in methods.split(",") if m.strip()]
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise ValueError(f"unknown method(s) {unknown}; known: {', '.join(METHODS)}")
    return tuple(dict.fromkeys(methods))


def _targets(ratios: List[dict], mesh: str) -> List[dict]:
    """Issue 4's speed targets on force+stiffness, each met or missed with its margin."""
    out = []
    for r in ratios:
        if r["what"] != "force+stiffness":
            continue
        if r["ratio"] == "classical/mjed":
            out.append({"target": "mjed faster than classical", "material": r["material"], "measured": r["median"],
                        "required": 1.0, "met": r["median"] > 1.0})
            if r["material"] == "StVenantKirchhoff":
                out.append({"target": f"StVK speed-up over classical >= {STVK_TARGET:g}x (paper)",
                            "material": r["material"], "measured": r["median"], "required": STVK_TARGET,
                            "met": r["median"] >= STVK_TARGET})
        elif r["ratio"] == "dolfinx/mjed":
            out.append({"target": f"mjed no slower than dolfinx ({mesh})", "material": r["material"],
                        "measured": r["median"], "required": 1.0, "met": r["median"] >= 1.0})
    return out


# ------------------------------------------------------------------------- scaling
def run_scaling(
    sizes: Optional[Sequence[int]] = None,
    *,
    material: str = "NeoHookean",
    methods: Sequence[str] = METHODS,
    repeats: int = 3,
    max_cells: Optional[int] = None,
    time_budget_s: float = 60.0,
    out_dir: Optional[str] = "reports/timing",
    json_path: Optional[str] = None,
    quick: bool = False,
    progress: Optional[Callable[[str], None]] = None,
) -> Dict[str, Any]:
    """Force+stiffness time and peak memory per cell on structured cubes of growing size.

    Each (size, method) runs in a fresh subprocess (build, one call for the peak memory,
    then ``repeats`` timed calls; the minimum is reported). A method stops growing when a
    size fails (memory) or when its previous size took longer than ``time_budget_s`` for
    its build and calls (time); the reason is recorded.
    """
    from comparisons.cases import default_material
    from comparisons.provenance import provenance

    default_material(material)  # raises on an unknown name
    methods = _check_methods(methods)
    if sizes is None:
        sizes = QUICK_SCALING_SIZES if quick else SCALING_SIZES
    if quick:
        repeats = min(repeats, 2)
    if max_cells is not None:
        sizes = [s for s in sizes if s <= max_cells]
    say = progress or (lambda msg: None)
    rows: List[dict] = []
    stopped: Dict[str, str] = {}
    for size in sizes:
        for method in methods:
            if method in stopped:
                continue
            say(f"scaling: {method} on ~{size:,} cells")
            t0 = time.perf_counter()
            rec = measure_memory(method, material, {"structured": int(size)}, repeats=repeats, iterations=1,
                                 timeout=max(600.0, 20 * time_budget_s))
            wall = time.perf_counter() - t0
            if "error" in rec:
                stopped[method] = f"stopped at ~{size:,} cells: {rec['error']}"
                continue
            best = min(rec["times_s"]) if rec["times_s"] else rec["first_call_s"]
            rows.append({"method": method, "target_cells": int(size), "n_cells": rec["n_cells"],
                         "n_nodes": rec["n_nodes"], "seconds": best, "seconds_per_cell": best / rec["n_cells"],
                         "peak_bytes": rec["peak_bytes"], "peak_bytes_per_cell": rec["peak_bytes"] / rec["n_cells"],
                         "setup_s": rec["setup_s"], "wall_s": wall})
            if wall > time_budget_s and size != sizes[-1]:
                stopped[method] = (f"stopped after ~{size:,} cells: that size took {wall:.0f} s "
                                   f"(budget {time_budget_s:.0f} s per size)")
    for method in methods:
        stopped.setdefault(method, f"completed all sizes up to ~{max(sizes):,} cells")
    result = {
        "material": material,
        "rows": rows,
        "stopped": stopped,
        "targets": _flatness(rows),
        "settings": {"sizes": [int(s) for s in sizes], "repeats": repeats, "time_budget_s": time_budget_s,
                     "mesh": "structured unit cube, 6 tetrahedra per hexahedron (meshes.structured)", "quick": quick},
        "provenance": provenance(with_dolfinx="dolfinx" in methods),
        "figures": [],
        "tables": [],
    }
    return _write_outputs(result, out_dir, json_path, "scaling", format_scaling_markdown, "plot_scaling")


def _write_outputs(result: dict, out_dir: Optional[str], json_path: Optional[str], stem: str,
                   table: Callable[[dict], str], plot: str) -> dict:
    """Write <out_dir>/<stem>.md and the figure (listed in the result), then the JSON."""
    if out_dir:
        from comparisons import figures_timing

        os.makedirs(out_dir, exist_ok=True)
        md = os.path.join(out_dir, f"{stem}.md")
        with open(md, "w") as fh:
            fh.write(table(result) + "\n")
        result["tables"].append(md)
        png = "timing_fig2.png" if stem == "timing" else "timing_scaling.png"
        result["figures"].append(getattr(figures_timing, plot)(result, os.path.join(out_dir, png)))
    if json_path:
        from comparisons.options import write_json

        write_json(json_path, result)
    return result


def _flatness(rows: List[dict]) -> List[dict]:
    lo, hi = FLATNESS_RANGE
    per = [r["seconds_per_cell"] for r in rows if r["method"] == "mjed" and lo <= r["n_cells"] <= hi]
    if len(per) < 2:
        return [{"target": f"mjed time per cell flat within {FLATNESS_TARGET:g}x from 1e4 to 1e6 cells",
                 "measured": None, "required": FLATNESS_TARGET, "met": None,
                 "note": "fewer than two sizes in that range were measured"}]
    spread = max(per) / min(per)
    return [{"target": f"mjed time per cell flat within {FLATNESS_TARGET:g}x from 1e4 to 1e6 cells",
             "measured": spread, "required": FLATNESS_TARGET, "met": spread <= FLATNESS_TARGET}]


# ------------------------------------------------------------------------- tables
def _fmt_ms(s: Optional[float]) -> str:
    return "-" if s is None else f"{s * 1e3:.1f}"


def format_markdown(result: Dict[str, Any]) -> str:
    """The per-material table (medians in ms, ratios, targets) and the provenance line."""
    res = {(r["material"], r["method"], r["what"]): r for r in result["results"]}
    rat = {(r["material"], r["what"], r["ratio"]): r for r in result["ratios"]}
    methods = result["settings"]["methods"]
    mats = list(dict.fromkeys(r["material"] for r in result["results"]))
    mesh = result["mesh"]
    lines = [f"Force+stiffness assembly on {mesh['name']} ({mesh['n_cells']:,} cells, {mesh['n_nodes']:,} nodes): "
             f"median of {result['settings']['repeats']} repeats, each the mean of "
             f"{result['settings']['iterations']} calls (ms); ratios per repeat, median [min, max].", ""]
    head = "| material | " + " | ".join(f"{m} f+K" for m in methods)
    others = [m for m in methods if m != "mjed"] if "mjed" in methods else []
    head += "".join(f" | {o}/mjed" for o in others) + " | " + " | ".join(f"{m} f / K" for m in methods) + " |"
    lines += [head, "|" + "---|" * (1 + 2 * len(methods) + len(others))]
    for name in mats:
        row = [name] + [_fmt_ms(res.get((name, m, "force+stiffness"), {}).get("median_s")) for m in methods]
        for o in others:
            r = rat.get((name, "force+stiffness", f"{o}/mjed"))
            row.append("-" if r is None else f"{r['median']:.2f} [{r['min']:.2f}, {r['max']:.2f}]")
        for m in methods:
            f = res.get((name, m, "force"), {}).get("median_s")
            k = res.get((name, m, "stiffness"), {}).get("median_s")
            row.append(f"{_fmt_ms(f)} / {_fmt_ms(k)}")
        lines.append("| " + " | ".join(row) + " |")
    if result.get("memory"):
        lines += ["", "Peak memory (MiB; " + result.get("memory_note", "") + "):", "",
                  "| material | " + " | ".join(methods) + " |", "|" + "---|" * (1 + len(methods))]
        mem = {(r["material"], r["method"]): r for r in result["memory"]}
        for name in mats:
            cells = []
            for m in methods:
                r = mem.get((name, m), {})
                cells.append(f"{r['peak_bytes'] / 2**20:.0f}" if r.get("peak_bytes") is not None else r.get("error", "-"))
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    if result.get("targets"):
        lines += ["", "Targets (force+stiffness, median ratio):", ""]
        for t in result["targets"]:
            verdict = "met" if t["met"] else f"MISSED by {t['required'] / t['measured']:.2f}x"
            lines.append(f"- {t['target']}, {t['material']}: {t['measured']:.2f}x (required {t['required']:g}x): {verdict}")
    lines += ["", provenance_line(result["provenance"])]
    return "\n".join(lines)


def provenance_line(p: Dict[str, Any]) -> str:
    commit = (p.get("git_commit") or "unknown")[:10] + ("+dirty" if p.get("git_dirty") else "")
    return (f"Machine: {p.get('cpu')}, {p.get('usable_cores')} usable core(s); Python {p.get('python')}, "
            f"NumPy {p.get('numpy')}, SciPy {p.get('scipy')}, dolfinx {p.get('dolfinx')}, PETSc {p.get('petsc')}; "
            f"commit {commit}; {p.get('date_utc')}.")


def format_scaling_markdown(result: Dict[str, Any]) -> str:
    lines = [f"Force+stiffness scaling ({result['material']}, {result['settings']['mesh']}): best of "
             f"{result['settings']['repeats']} calls.", "",
             "| method | cells | nodes | time (s) | us per cell | peak MiB | bytes per cell |", "|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['method']} | {r['n_cells']:,} | {r['n_nodes']:,} | {r['seconds']:.4f} | "
                     f"{r['seconds_per_cell'] * 1e6:.2f} | {r['peak_bytes'] / 2**20:.0f} | {r['peak_bytes_per_cell']:.0f} |")
    lines += ["", "Where each method stopped:", ""]
    lines += [f"- {m}: {why}" for m, why in result["stopped"].items()]
    for t in result["targets"]:
        if t["met"] is None:
            lines.append(f"- {t['target']}: not evaluated ({t['note']})")
        else:
            lines.append(f"- {t['target']}: max/min = {t['measured']:.2f} ({'met' if t['met'] else 'MISSED'})")
    lines += ["", provenance_line(result["provenance"])]
    return "\n".join(lines)


if __name__ == "__main__":  # the subprocess worker of measure_memory
    print(json.dumps(_memory_worker(json.loads(sys.argv[1]))))
