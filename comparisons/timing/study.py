"""The timing study (paper, Fig. 2) and the scaling study, each returning a StudyResult.

``timing_study`` times force+stiffness, force and stiffness on one mesh and one state for
each material and each method of :mod:`comparisons.timing.methods`: MJED and the classical
Galerkin, each in NumPy and compiled (Numba), dolfinx's compiled assembly, and the peer
libraries (FElupe, SfePy) where their energy matches. Before a method is timed its result is
compared with NumPy MJED's (proven equal to the UFL oracle); a method that does not match is
not timed. The like-for-like answer to Fig. 2 is the compiled pair: compiled classical over
compiled MJED, set beside the operation-count model of :mod:`comparisons.timing.opcount`. Each
force+stiffness time is also set against the floor implied by the bytes the result must move
at this machine's copy bandwidth (:mod:`comparisons.timing.bandwidth`).

How measurements are repeated is the protocol (:mod:`comparisons.timing.protocol`): the
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
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from common.result import Check, StudyResult
from comparisons.timing.protocol import calls_for, relative_spread, summary, time_batch
from comparisons.timing.protocol import protocol as get_protocol
from comparisons.timing.records import (
    Floor,
    MemoryRecord,
    MeshInfo,
    Ratio,
    Rounds,
    ScalingData,
    ScalingRow,
    ScalingSettings,
    Skipped,
    TimedCall,
    TimingData,
    TimingSettings,
    Verified,
)

KEY = "timing"
TITLE = "Timing: MJED and the classical FEM, NumPy and compiled, dolfinx and peers (paper Fig. 2)"
SCALING_KEY = "scaling"
SCALING_TITLE = "Scaling with mesh size"

__all__ = [
    "KEY",
    "TITLE",
    "SCALING_KEY",
    "SCALING_TITLE",
    "WHATS",
    "DEFAULT_METHODS",
    "timing_study",
    "scaling_study",
    "timing_command",
    "scaling_command",
    "measure_memory",
    "timing_state",
    "check_methods",
    "timing_checks",
]

WHATS = ("force+stiffness", "force", "stiffness")
DEFAULT_METHODS = (
    "mjed",
    "mjed-numba",
    "classical",
    "classical-numba",
    "dolfinx",
    "felupe",
    "sfepy",
    "sofa-mjed",
    "sofa-classical",
)
SELF_TIMED_CALLS = 10  # calls a self-timed method (SOFA) times per round; its median is kept
REFERENCE = "mjed"  # NumPy MJED: every result is compared with it, every ratio is against an MJED

#: Targets (issues 4 and 15), on force+stiffness unless said.
PAPER_SPEEDUP = 5.0  # the paper: MJED up to 5x faster than the standard FEM (St Venant-Kirchhoff)
FLOOR_FACTOR = 2.0  # compiled MJED within 2x of the bandwidth floor (NeoHookean)
COMPILED_SPEEDUP = 3.0  # compiled MJED at least 3x faster than the NumPy engine (NeoHookean)
PEER_SPEEDUP = 3.0  # NumPy MJED at least 3x faster than FElupe
TARGET_MATERIAL = "NeoHookean"
VERIFY_TOL = 1e-10  # the equivalence study's force and stiffness tolerances

#: Ratio pairs (numerator / denominator) formed per round; the first method must be timed too.
PAIRS = (
    ("classical", "mjed"),
    ("classical-numba", "mjed-numba"),
    ("mjed", "mjed-numba"),
    ("dolfinx", "mjed"),
    ("felupe", "mjed"),
    ("sfepy", "mjed"),
)

#: Scaling: target cell counts of the structured cube (6 n^3 cells).
SCALING_SIZES = (1_000, 10_000, 100_000, 1_000_000)
QUICK_SCALING_SIZES = (1_000, 6_000)
SCALING_METHODS = ("mjed", "mjed-numba", "classical-numba", "dolfinx")
FLATNESS_TARGET = 2.0  # max/min time per cell of MJED from 1e4 to 1e6 cells
FLATNESS_RANGE = (1e4, 1.5e6)


# ------------------------------------------------------------------ shared helpers
def timing_state(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The deformed positions every method is timed at: the equivalence study's seeded
    smooth random field with a rotation (J > 0.2 everywhere), so no branch is trivial.
    """
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
    from comparisons.timing.methods import get

    if isinstance(methods, str):
        methods = [m.strip() for m in methods.split(",") if m.strip()]
    if not methods:
        raise ValueError("no method given")
    for m in methods:
        get(m)  # raises naming the known methods
    methods = tuple(dict.fromkeys(methods))
    if REFERENCE not in methods:
        raise ValueError(
            f"the methods must include {REFERENCE!r} (NumPy MJED: the reference every result is "
            "checked against)"
        )
    return methods


def timing_command(
    materials: Sequence[str],
    mesh: str,
    *,
    quick: bool,
    protocol: str,
    methods: Sequence[str],
    memory: bool,
    out_dir: Optional[str],
    json_path: Optional[str] = None,
) -> str:
    """The mjed-verify command line that runs exactly this timing study."""
    parts = [
        "mjed-verify",
        "timing",
        "--material",
        ",".join(materials),
        "--mesh",
        str(mesh),
        "--methods",
        ",".join(methods),
        "--protocol",
        protocol,
    ]
    parts += ["--quick"] if quick else []
    parts += [] if memory else ["--no-memory"]
    parts += ["--out", out_dir] if out_dir else []
    parts += ["--json", json_path] if json_path else []
    return shlex.join(parts)


def scaling_command(
    *,
    quick: bool,
    material: str,
    methods: Sequence[str],
    max_cells: Optional[int],
    out_dir: Optional[str],
    json_path: Optional[str] = None,
) -> str:
    parts = [
        "mjed-verify",
        "timing",
        "--scaling",
        "--scaling-material",
        material,
        "--methods",
        ",".join(methods),
    ]
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
    and one force+stiffness call, then ``repeats`` timed calls.
    """
    from common.cases import default_material
    from comparisons.timing.methods import get

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
    return {
        "peak_bytes": 1024 * (after["VmHWM"] - before),
        "resident_after_bytes": 1024 * (after["VmRSS"] - before),
        "setup_s": setup_s,
        "first_call_s": first_s,
        "times_s": times,
        "n_cells": int(len(cells)),
        "n_nodes": int(len(points)),
    }


def measure_memory(
    method: str, material: str, mesh: Any, *, repeats: int = 0, timeout: float = 1800.0
) -> Dict[str, Any]:
    """Run the memory worker in a subprocess; its dict, or {'error': ...}.
    mesh: a catalog name or path, or {'structured': n_cells}.
    """
    if not os.path.exists("/proc/self/clear_refs"):
        return {"error": "peak memory needs Linux /proc (VmHWM); not measured"}
    spec = {"method": method, "material": material, "mesh": mesh, "repeats": repeats}
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[2])  # the repository (comparisons/timing/study.py)
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "comparisons.timing.study", json.dumps(spec)],
            capture_output=True,
            text=True,
            timeout=timeout,
            env=env,
        )
    except subprocess.TimeoutExpired:
        return {"error": f"did not finish within {timeout:.0f} s"}
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        if proc.returncode < 0 or "MemoryError" in proc.stderr:
            return {"error": f"out of memory or killed (exit {proc.returncode}): {tail}"}
        return {"error": f"worker failed (exit {proc.returncode}): {tail}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------------ the timing study
@dataclass(frozen=True)
class TimingSetup:
    """What every material of one timing run shares: the mesh, state, protocol and methods."""

    mesh: str
    points: np.ndarray
    cells: np.ndarray
    x: np.ndarray
    edge: float
    protocol: Any
    active: List[str]
    not_covered: List[str]


@dataclass
class _Samples:
    """Per-round times of every (material, method, what), with batch sizes and stop reasons."""

    times: Dict[Tuple[str, str, str], List[float]] = field(default_factory=dict)
    calls: Dict[Tuple[str, str, str], int] = field(default_factory=dict)


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
        methods: names of comparisons.timing.methods; must include "mjed".
        memory: measure peak memory in subprocesses (all materials under "paper", else one).
        command: the command line that ran (default: the equivalent mjed-verify command).
    """
    t_start = time.perf_counter()
    if quick and mesh == "cube-paper":
        mesh = "cube-small"
    methods = check_methods(methods)
    names = _names(materials)
    cmd = command or timing_command(
        names, mesh, quick=quick, protocol=protocol, methods=methods, memory=memory, out_dir=out_dir
    )
    say = progress or (lambda msg: None)
    load_before = _load()
    setup = _timing_setup(mesh, quick, protocol, methods)
    data = _timing_data(setup, methods, quick, say)
    samples = _Samples()
    for name in names:
        _time_material(name, setup, data, samples, say)
    _summarise(data, samples, names, setup.protocol.name)
    if memory:
        _measure_memories(data, names, setup, say)
    data.load_average = {"before": load_before, "after": _load()}
    return _timing_result(data, names, setup, out_dir, cmd, time.perf_counter() - t_start)


def _timing_setup(mesh: str, quick: bool, protocol: str, methods: Sequence[str]) -> TimingSetup:
    """Load the mesh once, form the timing state, and sort the methods into runnable or not."""
    from comparisons.timing.methods import get

    proto = get_protocol("quick" if quick and protocol == "budget" else protocol)
    points, cells = _load_mesh(mesh)
    x = timing_state(points, cells)
    edge = float(np.mean(np.linalg.norm(points[cells[:, 1]] - points[cells[:, 0]], axis=1)))
    not_covered: List[str] = []
    if quick:
        not_covered.append(
            f"quick run: {mesh} and the quick protocol instead of cube-paper and the budget "
            "protocol"
        )
    unavailable = {m: get(m).unavailable() for m in methods}
    not_covered += [f"{get(m).label} not timed: {why}" for m, why in unavailable.items() if why]
    active = [m for m in methods if not unavailable[m]]
    return TimingSetup(str(mesh), points, cells, x, edge, proto, active, not_covered)


def _timing_data(setup: TimingSetup, methods: Sequence[str], quick: bool, say) -> TimingData:
    """The record of this run, with the mesh, the bandwidth floor and the settings filled in."""
    from comparisons.provenance import provenance
    from comparisons.timing.bandwidth import floor_bytes, measure_bandwidth
    from comparisons.timing.methods import get
    from mjed.sparse import CSRPattern

    pattern = CSRPattern(setup.cells, len(setup.points))
    say("bandwidth: copy of 64 MiB")
    bw = measure_bandwidth()
    floor_b = floor_bytes(len(setup.points), len(setup.cells), pattern.nnz)
    floor = Floor(
        floor_b,
        floor_b / bw.bytes_per_s,
        "CSR values and force written once; positions, connectivity (int32) and rest geometry (D, "
        "V0) read once; at the measured copy bandwidth",
    )
    proto = setup.protocol
    settings = TimingSettings(
        proto.name,
        proto.describe(),
        list(setup.active),
        {m: get(m).label for m in methods},
        quick,
        proto.calls or "adaptive",
        0,
    )
    return TimingData(
        MeshInfo(setup.mesh, int(len(setup.cells)), int(len(setup.points)), int(pattern.nnz)),
        settings,
        bw,
        floor,
        provenance=provenance(with_dolfinx="dolfinx" in setup.active),
    )


def _build_methods(name: str, setup: TimingSetup, data: TimingData):
    """Build every runnable method for one material, verify it against NumPy MJED, and return
    the ones that may be timed (name -> object); the others are recorded as skipped.
    """
    from common.cases import default_material
    from comparisons.timing.methods import get, verify

    material = default_material(name)
    objs: Dict[str, Any] = {}
    reference = None
    for m in setup.active:
        why = get(m).unsupported(material)
        if why:
            data.skipped.append(Skipped(name, m, f"energy cannot be matched: {why}"))
            continue
        t0 = time.perf_counter()
        try:
            obj = get(m).build(setup.points, setup.cells, material)
        except Exception as exc:  # a peer refusing at build time: not timed, said why
            data.skipped.append(
                Skipped(name, m, f"could not be built: {type(exc).__name__}: {exc}")
            )
            continue
        if m == REFERENCE:
            reference = obj.force_and_stiffness(setup.x)
        objs[m] = obj
        data.setup_s[(name, m)] = time.perf_counter() - t0
    for m, obj in list(objs.items()):
        if m == REFERENCE:
            continue
        v = verify(get(m), obj, setup.x, reference, setup.edge, VERIFY_TOL)
        data.verification.append(Verified(name, m, v))
        if not v.passed:
            data.skipped.append(Skipped(name, m, f"not timed: {v.note}"))
            del objs[m]
    return objs


def _time_material(name: str, setup: TimingSetup, data: TimingData, samples: _Samples, say) -> None:
    """Time every verified method of one material in interleaved rounds until the protocol
    stops them (the order rotates each round, so drift in the machine hits all methods).
    """
    objs = _build_methods(name, setup, data)
    fns = {
        (m, w): getattr(o, _ATTR[w]) for m, o in objs.items() for w in WHATS if hasattr(o, _ATTR[w])
    }
    x, proto = setup.x, setup.protocol
    # SOFA's fields time their own calls inside SOFA's process (one process start per round,
    # not per call): their medians are recorded as each round's figure for their quantities.
    self_timed = {m: o for m, o in objs.items() if hasattr(o, "self_timed")}
    fns = {k: fn for k, fn in fns.items() if k[0] not in self_timed}
    for (m, w), fn in fns.items():  # warm-up (lazy maps, JIT, caches), then a call sizes the batch
        fn(x)
        t0 = time.perf_counter()
        fn(x)
        samples.calls[(name, m, w)] = calls_for(proto, time.perf_counter() - t0)
    order = list(objs)
    elapsed, rounds = 0.0, 0
    while True:
        shift = rounds % max(1, len(order))
        for w in WHATS:
            for m in order[shift:] + order[:shift]:
                if (m, w) in fns:
                    n = samples.calls[(name, m, w)]
                    t = time_batch(fns[(m, w)], x, n)
                    samples.times.setdefault((name, m, w), []).append(t)
                    elapsed += t * n
        for m, o in self_timed.items():
            for w, t in o.self_timed(x, SELF_TIMED_CALLS).items():
                if w in WHATS:
                    samples.times.setdefault((name, m, w), []).append(t)
                    samples.calls[(name, m, w)] = SELF_TIMED_CALLS
                    elapsed += SELF_TIMED_CALLS * t
        rounds += 1
        say(
            f"{name}: round {rounds}: "
            + ", ".join(
                f"{m} {samples.times[(name, m, 'force+stiffness')][-1] * 1e3:.2f} ms"
                for m in order
                if (name, m, "force+stiffness") in samples.times
            )
        )
        spreads = [relative_spread(samples.times[(name, m, w)]) for (m, w) in fns]
        spreads += [
            relative_spread(samples.times[k])
            for k in samples.times
            if k[0] == name and k[1] in self_timed  # this material's rounds only
        ]
        why = proto.should_stop(rounds, spreads, elapsed)
        if why:
            data.rounds[name] = Rounds(rounds, why)
            break
    del objs, fns
    gc.collect()


def _summarise(data: TimingData, samples: _Samples, names: Sequence[str], protocol: str) -> None:
    """Medians and ranges per call, per-round ratios of the PAIRS, and the op-count model."""
    from common.cases import default_material
    from comparisons.timing.opcount import model

    for (name, m, w), v in samples.times.items():
        s = summary(v)
        data.results.append(
            TimedCall(
                name,
                m,
                w,
                s["median"],
                s["min"],
                s["max"],
                len(v),
                samples.calls[(name, m, w)],
                relative_spread(v),
                data.rounds[name].stopped_by,
                protocol,
            )
        )
    for num, den in PAIRS:
        for name in names:
            for w in WHATS:
                a, b = samples.times.get((name, num, w)), samples.times.get((name, den, w))
                if a and b:
                    per = [p / q for p, q in zip(a, b)]
                    s = summary(per)
                    data.ratios.append(
                        Ratio(name, w, f"{num}/{den}", s["median"], s["min"], s["max"], per)
                    )
    data.opcount = {name: model(default_material(name)) for name in names}
    data.settings = replace(
        data.settings, repeats=max((r.rounds for r in data.rounds.values()), default=0)
    )


def _measure_memories(data: TimingData, names: Sequence[str], setup: TimingSetup, say) -> None:
    """Peak memory per method in fresh processes: every material under the paper protocol,
    else only the target material (each measurement rebuilds the method from scratch).
    """
    if setup.protocol.name == "paper":
        mem_names = list(names)
    else:
        mem_names = [TARGET_MATERIAL if TARGET_MATERIAL in names else names[0]]
    skipped = data.skipped_pairs()
    for name in mem_names:
        for m in setup.active:
            if (name, m) in skipped:
                continue
            say(f"{name}: peak memory of {m} (subprocess)")
            rec = measure_memory(m, name, setup.mesh)
            data.memory.append(
                MemoryRecord(
                    name,
                    m,
                    rec.get("peak_bytes"),
                    rec.get("resident_after_bytes"),
                    rec.get("error"),
                )
            )


def _timing_result(
    data: TimingData,
    names: Sequence[str],
    setup: TimingSetup,
    out_dir: Optional[str],
    cmd: str,
    seconds: float,
) -> StudyResult:
    """Checks, figure and report blocks of a measured run."""
    from comparisons.timing import blocks

    checks = timing_checks(data, names, setup.mesh)
    data.targets = [_target_dict(c) for c in checks if c.kind == "target"]
    if out_dir:
        from comparisons.timing import figures

        os.makedirs(out_dir, exist_ok=True)
        path = os.path.join(out_dir, "timing_fig2.png")
        data.figures.append(figures.plot_fig2(data, path))
    return StudyResult.from_checks(
        KEY,
        TITLE,
        checks,
        headline=blocks.timing_headline(data),
        command=cmd,
        not_covered=tuple(setup.not_covered),
        protocol=setup.protocol.describe(),
        data=data.to_dict(),
        blocks=blocks.timing_blocks(data, checks),
        seconds=seconds,
    )


_ATTR = {"force+stiffness": "force_and_stiffness", "force": "force", "stiffness": "stiffness"}


def timing_checks(data: TimingData, names: Sequence[str], mesh: str) -> List[Check]:
    """The verification tolerances and the speed targets, each with its figure and a note."""
    checks = _verification_checks(data)
    for name in names:
        checks += _ratio_targets(data, name, mesh)
    if TARGET_MATERIAL in names:
        checks += _compiled_targets(data, TARGET_MATERIAL, mesh)
    return checks


def _verification_checks(data: TimingData) -> List[Check]:
    # Methods verified by construction, and peers (which are simply not timed when they
    # differ, and said so), have no tolerance check of their own.
    return [
        Check(
            f"{v.method} matches NumPy MJED before timing, {v.material} (force, stiffness)",
            max(v.check.force_err, v.check.stiffness_err),
            VERIFY_TOL,
        )
        for v in data.verification
        if v.check.force_err is not None and v.method not in ("felupe", "sfepy")
    ]


def _median_ratio(data: TimingData, name: str, pair: str, what: str = "force+stiffness"):
    r = data.ratio(name, pair, what)
    return None if r is None else r.median


def _ratio_targets(data: TimingData, name: str, mesh: str) -> List[Check]:
    """The ratio targets of one material: MJED against the classical element and the peers."""
    checks: List[Check] = []
    pred = data.opcount[name]["predicted_ratio"]
    for pair, label in (("classical/mjed", "NumPy"), ("classical-numba/mjed-numba", "compiled")):
        r = _median_ratio(data, name, pair)
        if r is not None:
            note = (
                f"operation-count model predicts {pred:.2f}x; measured/predicted {r / pred:.2f}"
                if label == "compiled"
                else ""
            )
            checks.append(
                Check(
                    f"MJED faster than the classical FEM ({label} pair), {name} on {mesh}",
                    r,
                    1.0,
                    ">=",
                    "target",
                    note,
                )
            )
    if name == "StVenantKirchhoff":
        checks.append(
            Check(
                f"paper's claim: classical/MJED >= {PAPER_SPEEDUP:g}x, compiled pair, {name} on "
                f"{mesh}",
                _median_ratio(data, name, "classical-numba/mjed-numba"),
                PAPER_SPEEDUP,
                ">=",
                "target",
                f"the operation-count model predicts {pred:.2f}x for these two kernels",
            )
        )
    for pair, what, text, limit in (
        (
            "dolfinx/mjed",
            "force+stiffness",
            "NumPy MJED no slower than dolfinx (force+stiffness)",
            1.0,
        ),
        ("dolfinx/mjed", "force", "NumPy MJED force no slower than dolfinx's residual", 1.0),
        (
            "felupe/mjed",
            "force+stiffness",
            f"NumPy MJED at least {PEER_SPEEDUP:g}x faster than FElupe",
            PEER_SPEEDUP,
        ),
    ):
        r = _median_ratio(data, name, pair, what)
        if r is not None:
            checks.append(Check(f"{text}, {name} on {mesh}", r, limit, ">=", "target"))
    return checks


def _compiled_targets(data: TimingData, t: str, mesh: str) -> List[Check]:
    """The compiled kernel against the bandwidth floor and against the NumPy engine."""
    comp = data.median(t, "mjed-numba")
    floor = data.floor.seconds
    flops = data.opcount[t]["mjed_source"]  # counted from the generated kernel's source
    cells = data.mesh.n_cells
    floor_note = (
        "not measured: compiled MJED not timed"
        if comp is None
        else f"floor {floor * 1e3:.3f} ms at {data.bandwidth.bytes_per_s / 1e9:.1f} GB/s, so "
        f"{FLOOR_FACTOR:g}x the floor is {FLOOR_FACTOR * floor / cells * 1e9:.0f} ns per cell; the "
        f"kernel takes {comp / cells * 1e9:.0f} ns per cell for about {flops} flops "
        f"({flops * cells / comp / 1e9:.2f} Gflop/s measured): a serial kernel at that arithmetic "
        "is compute-bound, not memory-bound"
    )
    r = _median_ratio(data, t, "mjed/mjed-numba")
    speed_note = (
        "not measured: compiled MJED not timed"
        if r is None
        else f"NumPy {data.median(t, 'mjed') * 1e3:.2f} ms, compiled {comp * 1e3:.2f} ms; for the "
        f"same {flops} flops per cell that is {_gflops(flops, data, t, 'mjed'):.2f} and "
        f"{_gflops(flops, data, t, 'mjed-numba'):.2f} Gflop/s: the NumPy engine already runs each "
        "step as a whole-array (SIMD) operation over all cells, the compiled kernel is scalar per "
        "cell"
    )
    return [
        Check(
            f"compiled MJED within {FLOOR_FACTOR:g}x of the bandwidth floor, {t} on {mesh}",
            None if comp is None else comp / floor,
            FLOOR_FACTOR,
            "<=",
            "target",
            floor_note,
        ),
        Check(
            f"compiled MJED at least {COMPILED_SPEEDUP:g}x faster than the NumPy engine, {t} on "
            f"{mesh}",
            r,
            COMPILED_SPEEDUP,
            ">=",
            "target",
            speed_note,
        ),
    ]


def _gflops(flops: int, data: TimingData, material: str, method: str) -> float:
    """Model flops per second of a method's force+stiffness (the op-count model's MJED count)."""
    return flops * data.mesh.n_cells / data.median(material, method) / 1e9


def _target_dict(c: Check) -> dict:
    return {
        "target": c.name,
        "measured": c.measured,
        "required": c.limit,
        "relation": c.relation,
        "met": c.passed,
        "note": c.note,
    }


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
    from comparisons.provenance import provenance
    from comparisons.timing.methods import get

    t_start = time.perf_counter()
    default_material(material)  # raises on an unknown name
    methods = check_methods(methods)
    if sizes is None:
        sizes = QUICK_SCALING_SIZES if quick else SCALING_SIZES
    if quick:
        repeats = min(repeats, 2)
    if max_cells is not None:
        sizes = [s for s in sizes if s <= max_cells]
    cmd = command or scaling_command(
        quick=quick, material=material, methods=methods, max_cells=max_cells, out_dir=out_dir
    )
    settings = ScalingSettings(
        [int(s) for s in sizes],
        repeats,
        time_budget_s,
        quick,
        list(methods),
        {m: get(m).label for m in methods},
    )
    data = ScalingData(
        material,
        settings,
        load_average=_load(),
        provenance=provenance(with_dolfinx="dolfinx" in methods),
    )
    _measure_sizes(data, progress or (lambda msg: None))
    return _scaling_result(data, out_dir, cmd, time.perf_counter() - t_start)


def _measure_sizes(data: ScalingData, say) -> None:
    """Every (size, method) in a fresh process, smallest first; a method stops growing after a
    failure or a size over the time budget, and ``data.stopped`` says why.
    """
    from comparisons.timing.methods import get

    s = data.settings
    for m in s.methods:
        why = get(m).unavailable()
        if why:
            data.stopped[m] = f"not run: {why}"
    for size in s.sizes:
        for m in s.methods:
            if m in data.stopped:
                continue
            say(f"scaling: {m} on ~{size:,} cells")
            t0 = time.perf_counter()
            rec = measure_memory(
                m,
                data.material,
                {"structured": int(size)},
                repeats=s.repeats,
                timeout=max(600.0, 20 * s.time_budget_s),
            )
            wall = time.perf_counter() - t0
            if "error" in rec:
                data.stopped[m] = f"stopped at ~{size:,} cells: {rec['error']}"
                continue
            best = min(rec["times_s"]) if rec["times_s"] else rec["first_call_s"]
            n = rec["n_cells"]
            data.rows.append(
                ScalingRow(
                    m,
                    int(size),
                    n,
                    rec["n_nodes"],
                    best,
                    best / n,
                    rec["peak_bytes"],
                    rec["peak_bytes"] / n,
                    rec["setup_s"],
                    wall,
                )
            )
            if wall > s.time_budget_s and size != s.sizes[-1]:
                data.stopped[m] = (
                    f"stopped after ~{size:,} cells: that size took {wall:.0f} s (budget "
                    f"{s.time_budget_s:.0f} s per size)"
                )
    for m in s.methods:
        data.stopped.setdefault(m, f"completed all sizes up to ~{max(s.sizes):,} cells")


def _scaling_result(
    data: ScalingData, out_dir: Optional[str], cmd: str, seconds: float
) -> StudyResult:
    """Checks, figure and report blocks of a measured scaling run."""
    from comparisons.timing import blocks
    from comparisons.timing.methods import get

    s = data.settings
    largest = max((r.n_cells for r in data.rows), default=0)
    smallest = min((r.n_cells for r in data.rows), default=0)
    not_covered = []
    if max(s.sizes) < FLATNESS_RANGE[0] * 100 * 0.9:
        not_covered.append(
            f"sizes only up to ~{max(s.sizes):,} cells (the flatness target spans 1e4 to 1e6)"
        )
    not_covered += [
        f"{get(m).label}: {why}"
        for m, why in data.stopped.items()
        if not why.startswith("completed")
    ]
    checks = _flatness_checks(data.rows)
    data.targets = [_target_dict(c) for c in checks]
    if out_dir and data.rows:
        from comparisons.timing import figures

        os.makedirs(out_dir, exist_ok=True)
        path = os.path.join(out_dir, "timing_scaling.png")
        data.figures.append(figures.plot_scaling(data, path))
    protocol = (
        "each (method, size) in a fresh process: build, one call (peak memory), then the best of "
        f"{s.repeats} timed calls; a method stops growing after a size that took over "
        f"{s.time_budget_s:.0f} s"
    )
    return StudyResult.from_checks(
        SCALING_KEY,
        f"{SCALING_TITLE}: force+stiffness from {smallest:,} to {largest:,} cells",
        checks,
        headline=blocks.scaling_headline(data),
        command=cmd,
        not_covered=tuple(not_covered),
        protocol=protocol,
        data=data.to_dict(),
        blocks=blocks.scaling_blocks(data, checks),
        seconds=seconds,
    )


def _flatness_checks(rows: Sequence[ScalingRow]) -> List[Check]:
    lo, hi = FLATNESS_RANGE
    out = []
    for m in ("mjed", "mjed-numba"):
        if not any(r.method == m for r in rows):
            continue
        per = [r.seconds_per_cell for r in rows if r.method == m and lo <= r.n_cells <= hi]
        name = f"{m} time per cell flat within {FLATNESS_TARGET:g}x from 1e4 to 1e6 cells"
        if len(per) < 2:
            out.append(
                Check(
                    name,
                    None,
                    FLATNESS_TARGET,
                    "<=",
                    "target",
                    "fewer than two sizes in that range were measured",
                )
            )
        else:
            out.append(Check(name, max(per) / min(per), FLATNESS_TARGET, "<=", "target"))
    return out


if __name__ == "__main__":  # the subprocess worker of measure_memory
    print(json.dumps(_memory_worker(json.loads(sys.argv[1]))))
