"""What the liver's oscillation study records, as typed records.

``comparisons.liver.oscillation`` measures each max-displacement curve into an
:class:`OscillationMetrics` and returns the study as an :class:`OscillationData`: one
:class:`OscillationCurve` and one :class:`OscillationRow` per (model, dt). ``liver_study`` keeps
it in ``LiverData.oscillation`` (``comparisons.liver.records``, which imports this module, not the
other way round). ``to_dict()`` gives the JSON form (the key ``oscillation`` of the liver's
``results.json``), ``from_dict()`` reads it back, refusing a missing, unexpected or bad key by
name. Times are in seconds, lengths in metres, rates in 1/s, frame rates in steps per second.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Optional, Tuple

from common.json_fields import JSONFields, JSONRecord, json_keys
from common.record_fields import RecordFields
from comparisons.liver.setup import MODELS

__all__ = ["OscillationMetrics", "OscillationCurve", "OscillationRow", "OscillationData"]


@dataclass(frozen=True)
class OscillationMetrics:
    """What one max-displacement curve shows
    (``comparisons.liver.oscillation.oscillation_metrics``).

    extrema: the significant extrema (0: no oscillation); first_peak: the first maximum (m);
    period (s); decay_rate: of the swings between extrema (1/s; None with fewer than two
    swings); overshoot: first peak over the final value; final and peak: the last and the
    largest value (m). None where the curve does not show it.
    """

    extrema: int
    first_peak: Optional[float]
    period: Optional[float]
    decay_rate: Optional[float]
    overshoot: Optional[float]
    final: float
    peak: float

    def __post_init__(self) -> None:
        _check_metrics(RecordFields(self))


def _check_metrics(f: RecordFields) -> None:
    """The fields of OscillationMetrics, on it or on an OscillationRow."""
    f.count("extrema")
    for key in ("first_peak", "period", "decay_rate", "overshoot"):
        f.real(key, optional=True)
    f.real("final")
    f.real("peak")


@dataclass(frozen=True)
class OscillationCurve(JSONRecord):
    """One run of the oscillation study, as its figure and results.json keep it (a part of
    its ``LiverRun``): time (s), max_displacement (m), fps (steps per second).
    """

    model: str
    dt: float
    time: Tuple[float, ...]
    max_displacement: Tuple[float, ...]
    error: Optional[str]
    steps: int
    steps_planned: int
    steps_split: int
    substeps_total: int
    fps: Optional[float]

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.one_of("model", MODELS)
        f.real("dt", positive=True)
        f.reals("time")
        f.reals("max_displacement")
        f.text("error", optional=True)
        for key in ("steps", "steps_planned", "steps_split", "substeps_total"):
            f.count(key)
        f.real("fps", optional=True)
        if len(self.time) != len(self.max_displacement):
            raise f.refusal(
                "max_displacement",
                f"{len(self.time)} values (one per time)",
                len(self.max_displacement),
            )

    @classmethod
    def of_run(cls, run) -> "OscillationCurve":
        """The curve of one ``comparisons.liver.records.LiverRun`` (its fields of those names)."""
        return cls(**{k: getattr(run, k) for k in json_keys(cls)})

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out.update(time=list(self.time), max_displacement=list(self.max_displacement))
        return out


@dataclass(frozen=True)
class OscillationRow(JSONRecord):
    """One (model, dt) of the oscillation study: whether it completed (``error`` None), its
    steps taken in substeps, its curve's :class:`OscillationMetrics` (the same fields: lengths
    in m, times in s, rates in 1/s) and backward Euler's decay rate at this dt
    (``euler_decay_rate``, 1/s) on the angular frequency the model shows at the smallest dt
    (``omega_smallest_dt``, rad/s; both None when it does not oscillate there).
    """

    model: str
    dt: float
    error: Optional[str]
    steps_split: int
    extrema: int
    first_peak: Optional[float]
    period: Optional[float]
    decay_rate: Optional[float]
    overshoot: Optional[float]
    final: float
    peak: float
    omega_smallest_dt: Optional[float]
    euler_decay_rate: Optional[float]

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.one_of("model", MODELS)
        f.real("dt", positive=True)
        f.text("error", optional=True)
        f.count("steps_split")
        _check_metrics(f)
        f.real("omega_smallest_dt", optional=True)
        f.real("euler_decay_rate", optional=True)

    @classmethod
    def of_run(cls, run, metrics: OscillationMetrics) -> "OscillationRow":
        """The row of one ``comparisons.liver.records.LiverRun`` and its curve's metrics, before
        the Euler rates are known.
        """
        return cls(
            model=run.model,
            dt=run.dt,
            error=run.error,
            steps_split=run.steps_split,
            **dataclasses.asdict(metrics),
            omega_smallest_dt=None,
            euler_decay_rate=None,
        )

    @property
    def completed(self) -> bool:
        return self.error is None

    _DERIVED = ("completed",)

    def to_dict(self) -> dict:
        out = {"model": self.model, "dt": self.dt, "completed": self.completed}
        out.update({k: getattr(self, k) for k in json_keys(type(self))[2:]})
        return out


@dataclass(frozen=True)
class OscillationData(JSONRecord):
    """The oscillation study (paper Fig. 4 as described): every model at every dt (s) over
    ``duration`` (s) on ``mesh`` without Rayleigh damping (``rayleigh``: r_M in 1/s, r_K in
    s, both 0); the curves, one metrics row per run, the models by peak amplitude at
    ``amplitude_ordering_dt`` (largest first) and the figures written.
    """

    mesh: str
    dts: Tuple[float, ...]
    duration: float
    rayleigh: Tuple[float, ...]
    curves: Tuple[OscillationCurve, ...]
    table: Tuple[OscillationRow, ...]
    amplitude_ordering: Tuple[str, ...]
    amplitude_ordering_dt: float
    figures: Tuple[str, ...]

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.text("mesh")
        f.reals("dts")
        f.real("duration", positive=True)
        f.reals("rayleigh")
        f.records("curves", OscillationCurve)
        f.records("table", OscillationRow)
        f.texts("amplitude_ordering")
        f.real("amplitude_ordering_dt", positive=True)
        f.texts("figures")

    def to_dict(self) -> dict:
        return {
            "mesh": self.mesh,
            "dts": list(self.dts),
            "duration": self.duration,
            "rayleigh": list(self.rayleigh),
            "curves": [c.to_dict() for c in self.curves],
            "table": [r.to_dict() for r in self.table],
            "amplitude_ordering": list(self.amplitude_ordering),
            "amplitude_ordering_dt": self.amplitude_ordering_dt,
            "figures": list(self.figures),
        }

    @classmethod
    def from_fields(cls, f: JSONFields) -> "OscillationData":
        """The study from its JSON object as read by ``f`` (e.g. nested in the liver's)."""
        nested = {}
        for key, kind in (("curves", OscillationCurve), ("table", OscillationRow)):
            if key in f.obj:
                nested[key] = f.records(key, kind)
        return f.dataclass(cls, **nested)
