"""A SOFA force field on one mesh, called from Python like the project's own fields.

``SofaField(points, cells, material, "mjed")`` gives ``force_and_stiffness(x)`` in this
project's conventions (f = -dPi/dx (n, 3), K = d2Pi/dx2 CSR, dof 3 node + component), each call
one run of the engine program on a case folder it writes itself. The time of a run is mostly
SOFA starting and building its scene, so SOFA's own calls are timed inside the program:
``self_timed(x, calls)`` returns the median seconds of ``addForce`` as an explicit solver calls
it, of ``addForce`` plus ``addKToMatrix`` as an implicit solver with an assembled matrix calls
them, and of one ``addDForce`` (what a CG iteration calls), measured by
``std::chrono::steady_clock`` around the C++ calls, one thread.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.adapters.sofa.mapping import FORCEFIELDS, sofa_material_of
from conformance.adapters.sofa.program import find_program, how_to_build

__all__ = ["SofaField", "SofaUnavailable", "write_case_folder"]


class SofaUnavailable(RuntimeError):
    """The engine program is not built (the message says how to build it)."""


def write_case_folder(folder: Path, points: np.ndarray, cells: np.ndarray, x: np.ndarray) -> None:
    """The three arrays and the ``case.txt`` lines the engine program reads (conventions: raw
    little-endian, row-major; the material goes on the program's command line).
    """
    n, m = len(points), len(cells)
    folder.mkdir(parents=True, exist_ok=True)
    np.ascontiguousarray(points, dtype="<f8").tofile(folder / "points.f64")
    np.ascontiguousarray(x, dtype="<f8").tofile(folder / "positions.f64")
    np.ascontiguousarray(cells, dtype="<i8").tofile(folder / "cells.i64")
    (folder / "case.txt").write_text(
        f"format_version 1\ncase sofa-field\nn_nodes {n}\nn_cells {m}\n"
        f"array points points.f64 <f8 {n} 3\narray cells cells.i64 <i8 {m} 4\n"
        f"array positions positions.f64 <f8 {n} 3\n"
    )


class SofaField:
    """One of SOFA's hyperelastic force fields (``forcefield``: a key of ``FORCEFIELDS``) with
    ``material`` (an mjed material) on the mesh ``points`` (n, 3), ``cells`` (m, 4).

    Raises:
        SofaUnavailable: the engine program is not built.
        conformance.adapters.sofa.NotExpressible: SOFA has no such law (the reason is given).
    """

    def __init__(self, points: np.ndarray, cells: np.ndarray, material: Any, forcefield: str):
        program = find_program()
        if program is None:
            raise SofaUnavailable(how_to_build())
        self.program, self.forcefield = program, forcefield
        self.points = np.asarray(points, dtype=float)
        self.cells = np.asarray(cells, dtype=np.int64)
        self.sofa = sofa_material_of(material, forcefield)
        self.label = f"SOFA {FORCEFIELDS[forcefield]}"

    def _run(self, x: np.ndarray, *extra: str) -> Tuple[Path, tempfile.TemporaryDirectory]:
        work = tempfile.TemporaryDirectory(prefix="mjed-sofa-")
        case, out = Path(work.name) / "input", Path(work.name) / "output"
        write_case_folder(case, self.points, self.cells, x)
        out.mkdir()
        command = [
            str(self.program),
            "--forcefield",
            self.forcefield,
            "--material",
            self.sofa.name,
            "--parameters",
            self.sofa.parameter_set(),
            *extra,
            str(case),
            str(out),
        ]
        done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0:
            work.cleanup()
            raise RuntimeError(f"{self.label}: the engine program failed: {done.stderr.strip()}")
        return out, work

    def force_and_stiffness(self, x: np.ndarray) -> Tuple[np.ndarray, sp.csr_matrix]:
        out, work = self._run(x)
        with work:
            n = 3 * len(self.points)
            f = np.fromfile(out / "force.f64", dtype="<f8").reshape(-1, 3)
            rows = np.fromfile(out / "stiffness_rows.i64", dtype="<i8")
            cols = np.fromfile(out / "stiffness_cols.i64", dtype="<i8")
            vals = np.fromfile(out / "stiffness_values.f64", dtype="<f8")
            K = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()  # duplicates summed
            return f, K

    def self_timed(self, x: np.ndarray, calls: int) -> Dict[str, float]:
        """Median seconds per call over ``calls`` repetitions inside SOFA's process:
        ``force`` (explicit addForce), ``force+stiffness`` (implicit addForce then
        addKToMatrix) and
        ``dforce`` (one addDForce).
        """
        with tempfile.TemporaryDirectory(prefix="mjed-sofa-time-") as tmp:
            timing = Path(tmp) / "timing.json"
            out, work = self._run(x, "--time", str(int(calls)), "--timing-json", str(timing))
            with work:
                t = json.loads(timing.read_text())
        return {
            "force": t["add_force_s"],
            "force+stiffness": t["implicit_add_force_and_k_to_matrix_s"],
            "dforce": t["add_dforce_s"],
        }


def available() -> Optional[str]:
    """None when the engine program is built, else how to build it."""
    return None if find_program() is not None else how_to_build()
