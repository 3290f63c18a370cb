"""What the liver study records, as typed records.

``comparisons.liver.simulation.simulate`` returns one :class:`LiverRun` per run and
``comparisons.liver.study.run_liver`` a :class:`LiverData` holding them (with the oscillation
study's ``comparisons.liver.oscillation_records.OscillationData`` once ``liver_study`` adds
it). The checks,
tables, figures and the command line read them by attribute; ``to_dict()`` gives the JSON form
written to ``results.json`` and ``--json`` (the keys are the field names, plus the derived values
listed in each record), and ``from_dict()`` reads it back (``common.json_fields``), refusing a
missing, unexpected or bad key by name and place. Each record checks its fields on construction
(``common.record_fields``). Times are in seconds, lengths in metres, pressures in pascals, frame
rates in steps per second.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np

from common.json_fields import JSONFields, JSONRecord
from common.record_fields import RecordFields
from comparisons.liver.oscillation_records import OscillationData
from comparisons.liver.setup import MODELS, PAPER_FPS, TARGET_FPS, TERZAGHI_TOL
from comparisons.liver.terzaghi_records import TerzaghiResult

__all__ = [
    "PHASES",
    "PressureSnapshot",
    "LiverRun",
    "StepSplit",
    "BackendAgreement",
    "LiverData",
]

#: The phases of a step, in the order of the split figure and of ``phase_seconds``.
PHASES = (
    "hyperelastic force + stiffness",
    "other forces",
    "building the system",
    "linear solve",
    "rest",
)


# ----------------------------------------------------------------------------- one run
@dataclass(frozen=True)
class PressureSnapshot:
    """The fluid pressure at the step of its largest magnitude (Fig. 1 right; not in JSON).

    max_abs_pressure: max |P| then (Pa); pressure: (n,) nodal P (Pa); positions: (n, 3) the
    nodes then (m).
    """

    max_abs_pressure: float
    pressure: np.ndarray
    positions: np.ndarray


@dataclass(frozen=True)
class LiverRun(JSONRecord):
    """One run of one liver model (``comparisons.liver.simulation.simulate``).

    model: one of MODELS. dt: the time step (s). steps_planned: the steps asked for.
    error: why the integrator stopped the run (a step refused after its substeps), or None.
    time (s) and max_displacement (max nodal |u|, m): one entry per state, the first at t = 0.
    cg_iterations, substeps (1: taken whole), retries (the reasons a step was split) and
    inverted_cells: one entry per step taken. factorizations: preconditioner factorisations
    over the run. solver, force_field, backend: what ran (labels). stepping_seconds: the
    wall-clock seconds of the integrator's steps; cpu_fps: steps per CPU second of this
    process (None when none was measured). phase_seconds: the seconds of the steps by PHASES.
    max_abs_pressure: max nodal |P| (Pa) per state, porous runs only. pressure_snapshot: the
    pressure field for Fig. 1 right (porous runs; not written to JSON).

    Derived (properties, also written to JSON): steps, final_max_displacement,
    peak_max_displacement, cg_iterations_mean, steps_split, substeps_total,
    inverted_cells_max, fps, realtime_factor and paper_fps.
    """

    model: str
    dt: float
    steps_planned: int
    error: Optional[str]
    time: Tuple[float, ...]
    max_displacement: Tuple[float, ...]
    cg_iterations: Tuple[int, ...]
    substeps: Tuple[int, ...]
    retries: Tuple[Tuple[str, ...], ...]
    inverted_cells: Tuple[int, ...]
    factorizations: int
    solver: str
    force_field: str
    backend: str
    stepping_seconds: float
    cpu_fps: Optional[float]
    phase_seconds: Dict[str, float]
    max_abs_pressure: Optional[Tuple[float, ...]] = None
    pressure_snapshot: Optional[PressureSnapshot] = field(
        default=None, compare=False, repr=False, metadata={"json": False}
    )

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.one_of("model", MODELS)
        f.real("dt", positive=True)
        f.text("error", optional=True)
        for key in ("solver", "force_field", "backend"):
            f.text(key)
        for key in ("steps_planned", "factorizations"):
            f.count(key)
        for key in ("time", "max_displacement"):
            f.reals(key)
        f.reals("max_abs_pressure", optional=True)
        for key in ("cg_iterations", "substeps", "inverted_cells"):
            f.counts(key)
        f.items("retries", _is_reasons, "lists of strings", lambda r: tuple(map(str, r)))
        f.real("stepping_seconds")
        f.real("cpu_fps", optional=True)
        f.reals_by_key("phase_seconds", PHASES)
        self._check_lengths(f)

    def _check_lengths(self, f: RecordFields) -> None:
        """One entry per step (cg_iterations, ...) and one more per state (time, ...)."""
        n = len(self.cg_iterations)
        per_state = ["time", "max_displacement"]
        per_state += [] if self.max_abs_pressure is None else ["max_abs_pressure"]
        for key in per_state:
            if len(getattr(self, key)) != n + 1:
                raise f.refusal(
                    key, f"{n + 1} values (the steps taken, plus t = 0)", len(getattr(self, key))
                )
        for key in ("substeps", "retries", "inverted_cells"):
            if len(getattr(self, key)) != n:
                raise f.refusal(key, f"{n} values (one per step taken)", len(getattr(self, key)))
        if n > self.steps_planned:
            raise f.refusal("steps_planned", f">= the {n} steps taken", self.steps_planned)

    # ------------------------------------------------------------------ derived
    @property
    def steps(self) -> int:
        """The steps taken (fewer than steps_planned when the run stopped)."""
        return len(self.cg_iterations)

    @property
    def final_max_displacement(self) -> float:
        """Max nodal |u| at the last state (m)."""
        return self.max_displacement[-1]

    @property
    def peak_max_displacement(self) -> float:
        """Largest max nodal |u| over the run (m)."""
        return max(self.max_displacement)

    @property
    def cg_iterations_mean(self) -> Optional[float]:
        """Mean CG iterations per step (None when no step was taken)."""
        return float(np.mean(self.cg_iterations)) if self.cg_iterations else None

    @property
    def steps_split(self) -> int:
        """Steps taken in substeps."""
        return int(sum(s > 1 for s in self.substeps))

    @property
    def substeps_total(self) -> int:
        return int(sum(self.substeps))

    @property
    def inverted_cells_max(self) -> int:
        return int(max(self.inverted_cells)) if self.inverted_cells else 0

    @property
    def fps(self) -> Optional[float]:
        """Steps per wall-clock second of stepping (None when nothing was timed)."""
        s = self.stepping_seconds
        return self.steps / s if s > 0 else None

    @property
    def realtime_factor(self) -> Optional[float]:
        """Simulated seconds per wall-clock second of stepping."""
        s = self.stepping_seconds
        return self.steps * self.dt / s if s > 0 else None

    @property
    def paper_fps(self) -> float:
        """The paper's frame rate for this model (2010 laptop)."""
        return PAPER_FPS[self.model]

    @property
    def completed(self) -> bool:
        """The integrator took every step (no error)."""
        return self.error is None

    # ------------------------------------------------------------------ JSON
    _DERIVED = (
        "steps",
        "final_max_displacement",
        "peak_max_displacement",
        "cg_iterations_mean",
        "steps_split",
        "substeps_total",
        "inverted_cells_max",
        "fps",
        "realtime_factor",
        "paper_fps",
    )

    def to_dict(self) -> dict:
        """The run's JSON record (keys in the order results.json has always had them)."""
        out = {
            "model": self.model,
            "dt": self.dt,
            "steps": self.steps,
            "steps_planned": self.steps_planned,
            "error": self.error,
            "time": list(self.time),
            "max_displacement": list(self.max_displacement),
            "final_max_displacement": self.final_max_displacement,
            "peak_max_displacement": self.peak_max_displacement,
            "cg_iterations_mean": self.cg_iterations_mean,
            "cg_iterations": list(self.cg_iterations),
            "substeps": list(self.substeps),
            "steps_split": self.steps_split,
            "substeps_total": self.substeps_total,
            "retries": [list(r) for r in self.retries],
            "inverted_cells": list(self.inverted_cells),
            "inverted_cells_max": self.inverted_cells_max,
            "factorizations": self.factorizations,
            "solver": self.solver,
            "force_field": self.force_field,
            "backend": self.backend,
            "stepping_seconds": self.stepping_seconds,
            "fps": self.fps,
            "cpu_fps": self.cpu_fps,
            "realtime_factor": self.realtime_factor,
            "paper_fps": self.paper_fps,
            "phase_seconds": dict(self.phase_seconds),
        }
        if self.max_abs_pressure is not None:
            out["max_abs_pressure"] = list(self.max_abs_pressure)
        return out

    def fps_row(self) -> dict:
        """The run's row of the JSON ``fps_table``."""
        keys = ("model", "backend", "dt", "fps", "cpu_fps", "paper_fps", "solver", "force_field")
        keys += ("cg_iterations_mean", "factorizations", "steps", "steps_split")
        keys += ("substeps_total", "inverted_cells_max")
        row = {k: getattr(self, k) for k in keys}
        row.update(
            target_fps=TARGET_FPS,
            completed=self.completed,
            meets_target=bool(self.fps is not None and self.fps >= TARGET_FPS),
        )
        return row


def _is_reasons(r) -> bool:
    return isinstance(r, (list, tuple)) and all(isinstance(s, str) for s in r)


# ----------------------------------------------------------------------------- across runs
@dataclass(frozen=True)
class StepSplit(JSONRecord):
    """Where the steps of one completed run went: ms_per_step (milliseconds of wall clock per
    step) and shares (the fraction of the stepping time of each of PHASES, summing to 1).
    """

    model: str
    backend: str
    ms_per_step: float
    shares: Dict[str, float]

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.one_of("model", MODELS)
        f.text("backend")
        f.real("ms_per_step", positive=True)
        f.reals_by_key("shares", PHASES)

    def to_dict(self) -> dict:
        return {
            "model": self.model,
            "backend": self.backend,
            "ms_per_step": self.ms_per_step,
            "shares": dict(self.shares),
        }


@dataclass(frozen=True)
class BackendAgreement(JSONRecord):
    """A later backend's run against the reference backend's run of the same model: the
    largest difference of their max-displacement curves over the reference's peak
    (dimensionless; None when the two did not take the same steps).
    """

    model: str
    backend: str
    reference: str
    relative_difference: Optional[float]

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.one_of("model", MODELS)
        f.text("backend")
        f.text("reference")
        f.real("relative_difference", optional=True)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


# ----------------------------------------------------------------------------- the study
@dataclass(frozen=True)
class LiverData(JSONRecord):
    """A liver study (``comparisons.liver.study.run_liver``; ``liver_study`` adds the oscillation
    study and the protocol).

    The organ: mesh (its label), mesh_description, n_nodes, n_cells, scale (metres per mesh
    unit), numbering (of its node ids), reoriented_cells, unused_nodes (counts) and the
    mesh_warnings. Its supports: fixed_regions (specs), n_fixed, fixed_node_ids (in the
    file's numbering; None when more than 50). quick; duration: simulated seconds of each run;
    parameters: ``LiverParameters.to_dict()`` of the runs. runs: every model once per backend,
    the reference backend first; step_split and backend_agreement over them; terzaghi: the
    Terzaghi check's record (``comparisons.liver.terzaghi.run_terzaghi``); figures and series: the
    files written. oscillation, protocol: None until ``liver_study`` sets them.

    Derived (properties, also written to JSON): backends, fps_table and passed. ``from_dict``
    reads the JSON record back (a StudyResult's ``data``, or ``["data"]`` of a --json file).
    """

    mesh: str
    mesh_description: str
    n_nodes: int
    n_cells: int
    scale: float
    numbering: str
    reoriented_cells: int
    unused_nodes: int
    mesh_warnings: Tuple[str, ...]
    fixed_regions: Tuple[str, ...]
    n_fixed: int
    fixed_node_ids: Optional[Tuple[int, ...]]
    quick: bool
    duration: float
    parameters: Dict[str, Any]
    runs: Tuple[LiverRun, ...]
    step_split: Tuple[StepSplit, ...]
    backend_agreement: Tuple[BackendAgreement, ...]
    terzaghi: TerzaghiResult
    figures: Tuple[str, ...]
    series: Tuple[str, ...]
    oscillation: Optional[OscillationData] = None
    protocol: Optional[str] = None

    def __post_init__(self) -> None:
        f = RecordFields(self)
        for key in ("mesh", "mesh_description", "numbering"):
            f.text(key)
        for key in ("n_nodes", "n_cells", "reoriented_cells", "unused_nodes", "n_fixed"):
            f.count(key)
        f.real("scale", positive=True)
        f.real("duration", positive=True)
        f.flag("quick")
        for key in ("mesh_warnings", "fixed_regions", "figures", "series"):
            f.texts(key)
        f.counts("fixed_node_ids", optional=True)
        for key, kind in _NESTED:
            f.records(key, kind)
        self._check_records(f)

    def _check_records(self, f: RecordFields) -> None:
        """Check the parameters (an object), terzaghi and the optional parts."""
        if not isinstance(self.parameters, Mapping):
            raise f.refusal("parameters", "an object (LiverParameters.to_dict())", self.parameters)
        if not isinstance(self.terzaghi, TerzaghiResult):
            raise f.refusal("terzaghi", "a TerzaghiResult", self.terzaghi)
        if not (self.oscillation is None or isinstance(self.oscillation, OscillationData)):
            raise f.refusal("oscillation", "an OscillationData or None", self.oscillation)
        f.text("protocol", optional=True)

    # ------------------------------------------------------------------ derived
    @property
    def backends(self) -> Tuple[str, ...]:
        """The backends that ran, the reference (first) one first."""
        return tuple(dict.fromkeys(r.backend for r in self.runs))

    @property
    def terzaghi_error(self) -> float:
        """The Terzaghi check's worst relative L2 pressure error over its times."""
        return self.terzaghi.worst_error

    @property
    def passed(self) -> bool:
        """Every run completed and the Terzaghi check is within TERZAGHI_TOL."""
        return all(r.error is None for r in self.runs) and self.terzaghi_error <= TERZAGHI_TOL

    # ------------------------------------------------------------------ JSON
    _DERIVED = ("backends", "fps_table", "passed")

    def to_dict(self) -> dict:
        """The study's JSON record (results.json, --json), keys in their historical order."""
        ids = self.fixed_node_ids
        out = {
            "mesh": self.mesh,
            "mesh_description": self.mesh_description,
            "n_nodes": self.n_nodes,
            "n_cells": self.n_cells,
            "scale": self.scale,
            "numbering": self.numbering,
            "reoriented_cells": self.reoriented_cells,
            "unused_nodes": self.unused_nodes,
            "mesh_warnings": list(self.mesh_warnings),
            "fixed_regions": list(self.fixed_regions),
            "n_fixed": self.n_fixed,
            "fixed_node_ids": None if ids is None else list(ids),
            "quick": self.quick,
            "duration": self.duration,
            "parameters": dict(self.parameters),
        }
        out.update(
            runs=[r.to_dict() for r in self.runs],
            backends=list(self.backends),
            fps_table=[r.fps_row() for r in self.runs],
            step_split=[s.to_dict() for s in self.step_split],
            backend_agreement=[a.to_dict() for a in self.backend_agreement],
            terzaghi=self.terzaghi.to_dict(),
            passed=self.passed,
            figures=list(self.figures),
            series=list(self.series),
        )
        if self.oscillation is not None:
            out["oscillation"] = self.oscillation.to_dict()
        if self.protocol is not None:
            out["protocol"] = self.protocol
        return out

    @classmethod
    def from_fields(cls, f: JSONFields) -> "LiverData":
        nested: Dict[str, Any] = {}
        for key, kind in _NESTED:
            if key in f.obj:
                nested[key] = f.records(key, kind)
        nested["terzaghi"] = TerzaghiResult.from_fields(f.object("terzaghi", "TerzaghiResult"))
        if f.obj.get("oscillation") is not None:
            nested["oscillation"] = OscillationData.from_fields(
                f.object("oscillation", "OscillationData")
            )
        return f.dataclass(cls, derived=cls._DERIVED, **nested)


#: The lists of records a LiverData holds: its key, the record type.
_NESTED = (("runs", LiverRun), ("step_split", StepSplit), ("backend_agreement", BackendAgreement))
