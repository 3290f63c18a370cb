"""Running the SOFA study: each verdict is one ``mjed-verify check --command`` run on SOFA's
engine program (a subprocess, so that every verdict is exactly what a user's command line
gives), and each timing row SOFA's calls timed inside its process beside the project's
compiled kernels timed in this one.
"""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, List, Sequence

import numpy as np

from comparisons.sofa.records import SofaTiming, SofaVerdict
from comparisons.sofa.setup import costa_energy_options, environment_with_program, states_for

__all__ = ["check_one", "time_material"]


def _engine_command(forcefield: str, material: str, program: Path) -> str:
    """The engine program itself, with the material mapped once here: the same arguments the
    Python adapter (``python -m conformance.adapters.sofa case``) would pass for every case of
    this material, without a Python start per case.
    """
    from common.cases import default_material
    from conformance.adapters.sofa.mapping import sofa_material_of

    # Costa is checked as its global-axes energy, with Costa's parameters: the same ParameterSet
    sofa = sofa_material_of(default_material(material), forcefield)
    return (
        shlex.join(
            [
                str(program),
                "--forcefield",
                forcefield,
                "--material",
                sofa.name,
                "--parameters",
                sofa.parameter_set(),
            ]
        )
        + " {input} {output}"
    )


def check_one(
    forcefield: str, material: str, label: str, mesh: str, program: Path, timeout_s: float = 600.0
) -> SofaVerdict:
    """``mjed-verify check`` of one force field, material and mesh; the verdict it gave."""
    states = states_for(label)
    model = costa_energy_options() if material == "Costa" else ["--material", material]
    with tempfile.TemporaryDirectory(prefix="mjed-sofa-check-") as tmp:
        out = Path(tmp) / "results.json"
        argv = [
            "check",
            "--command",
            _engine_command(forcefield, material, program),
            *model,
            "--mesh",
            mesh,
            "--states",
            states,
            "--out",
            str(Path(tmp) / "r"),
            "--json",
            str(out),
            "--quiet",
            "--timeout",
            "120",
        ]
        subprocess.run(
            [sys.executable, "-m", "comparisons.cli", *argv],
            env=environment_with_program(program),
            capture_output=True,
            text=True,
            timeout=timeout_s,
        )
        if not out.is_file():
            raise RuntimeError(f"check of SOFA {forcefield} {material} on {label} wrote no results")
        results = json.loads(out.read_text())
    return _verdict(
        forcefield,
        material,
        label,
        states,
        results,
        "mjed-verify " + shlex.join(a for a in argv if a not in ("--quiet",)),
    )


def _verdict(forcefield, material, label, states, results, command) -> SofaVerdict:
    cases = results["cases"]
    compared = [c for c in cases if "errors" in c]
    failed = [c for c in cases if c["status"] == "failed"]
    bad = [c for c in cases if c["status"] == "bad input"]
    diagnosis = ""
    if failed and failed[0].get("findings"):
        f = failed[0]["findings"][0]
        diagnosis = f"{f['title']} [{f['strength']}]: {f['evidence']}"
    worst = lambda key: max((c["errors"][key] for c in compared), default=None)  # noqa: E731
    return SofaVerdict(
        forcefield,
        material,
        label,
        states,
        passed=sum(c["status"] == "passed" for c in cases),
        cases=len(cases),
        force_error=worst("force"),
        stiffness_error=worst("stiffness"),
        diagnosis=diagnosis,
        bad_input=(bad[0]["message"][:300] if bad else ""),
        command=command,
    )


def _median_time(fn: Callable, x: np.ndarray, calls: int) -> float:
    fn(x)  # warm-up: JIT, lazily built maps
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        fn(x)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def time_material(
    material_name: str,
    label: str,
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    forcefields: Sequence[str],
    calls: int,
    say: Callable[[str], None] = lambda s: None,
) -> List[SofaTiming]:
    """SOFA's force fields and the project's compiled MJED and classical kernels on one mesh
    and state, one thread: a row per method (median of ``calls`` calls each).
    """
    from common.cases import default_material
    from conformance.adapters.sofa import NotExpressible
    from conformance.adapters.sofa.field import SofaField

    material = default_material(material_name)
    rows: List[SofaTiming] = []
    for ff in forcefields:
        try:
            field = SofaField(points, cells, material, ff)
        except NotExpressible as why:
            say(f"{material_name}: SOFA {ff} not timed: {why}")
            continue
        try:
            t = field.self_timed(x, calls)
        except RuntimeError as why:  # SOFA crashed or refused: said, not timed
            say(f"{material_name}: SOFA {ff} not timed: {why}")
            continue
        rows.append(
            SofaTiming(
                f"sofa-{ff}",
                material_name,
                label,
                len(cells),
                t["force"],
                t["force+stiffness"],
                t["dforce"],
            )
        )
        say(
            f"{material_name} on {label}: sofa-{ff} f {t['force'] * 1e3:.2f} ms, "
            f"f+K {t['force+stiffness'] * 1e3:.2f} ms"
        )
    for method, obj in _own_kernels(points, cells, material, say):
        f_s = _median_time(obj.force, x, calls)
        fk_s = _median_time(obj.force_and_stiffness, x, calls)
        rows.append(SofaTiming(method, material_name, label, len(cells), f_s, fk_s))
        say(f"{material_name} on {label}: {method} f {f_s * 1e3:.2f} ms, f+K {fk_s * 1e3:.2f} ms")
    return rows


def _own_kernels(points, cells, material, say):
    """The project's compiled kernels, single-threaded, where Numba is installed."""
    import mjed
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    mesh = mjed.TetMesh(points, cells)
    try:  # parallel is off by default: one thread, as SOFA's force fields run
        yield "mjed-numba", mjed.make_force_field(mesh, material, backend="numba")
    except Exception as exc:  # no Numba here, or the kernel refuses this material: said why
        say(f"mjed-numba not timed: {type(exc).__name__}: {exc}")
    try:
        yield "classical-numba", CompiledClassicalGalerkin(mesh, None, material)
    except Exception as exc:
        say(f"classical-numba not timed: {type(exc).__name__}: {exc}")
