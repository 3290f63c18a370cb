"""What the rheometer study is given and what it measures, as typed records.

:class:`RheometerSpec` is the study's input; the sweep builds one :class:`FrequencyRow` per
frequency, summarises their errors in :class:`SweepErrors` and returns a :class:`Sweep`;
:func:`comparisons.rheometer.study.run_rheometer` wraps it with the spec, the mesh and the figures
in a :class:`RheometerResult`. The checks, tables, figures and tutorial read them by attribute;
``to_dict()`` gives the JSON written to ``--json`` and ``results.json`` (keys as before this module
existed: the field names, pairs as two-element lists), and ``from_dict()`` reads it back, naming the
file and the key of anything missing or mistyped. Units are SI: moduli in Pa, angular frequencies in
rad/s, times in s, torque in N m.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Dict, Tuple

import numpy as np

from common.json_fields import JSONFields
from common.record_fields import RecordFields
from mjed.materials import StVenantKirchhoff
from mjed.viscous import Prony

__all__ = [
    "RheometerSpec",
    "FrequencyRun",
    "FrequencyRow",
    "ErrorSummary",
    "SweepErrors",
    "Sweep",
    "SampleMesh",
    "RheometerResult",
]

#: A (storage, loss) pair: G' then G'' (Pa), or their relative errors.
Pair = Tuple[float, float]


@dataclass(frozen=True)
class RheometerSpec:
    """Parameters of the study (SI units).

    radius, height: the sample (m); target_cells: tetrahedra of the gmsh cylinder.
    G0 (Pa), poisson: St Venant-Kirchhoff's mu = G0 and lam from Poisson's ratio.
    alphas, taus: the Prony series. amplitude: theta0 (rad).
    samples_per_period: time steps per period (dt = 2 pi / (omega N)).
    warmup_periods, measured_periods: periods integrated before and during the fit.
    n_frequencies: omega log-spaced from 0.1 / max(tau) to 10 / min(tau).
    """

    radius: float = 0.010
    height: float = 0.004
    target_cells: int = 1000
    G0: float = 770.0
    poisson: float = 0.45
    alphas: Tuple[float, ...] = (0.235, 0.333)
    taus: Tuple[float, ...] = (0.27, 0.03)
    amplitude: float = 1e-6
    samples_per_period: int = 64
    warmup_periods: int = 1
    measured_periods: int = 2
    n_frequencies: int = 13

    def __post_init__(self):
        f = RecordFields(self)
        for name in ("radius", "height", "G0", "amplitude"):
            f.real(name, positive=True)
        f.real("poisson")
        if not (-1.0 < self.poisson < 0.5):
            raise f.refusal("poisson", "a number in (-1, 0.5)", self.poisson)
        for name, low in (
            ("target_cells", 1),
            ("samples_per_period", 8),
            ("warmup_periods", 0),
            ("measured_periods", 1),
            ("n_frequencies", 1),
        ):
            f.count(name, minimum=low)
        self.prony  # validates alphas and taus

    @property
    def prony(self) -> Prony:
        return Prony(self.alphas, self.taus)

    @property
    def material(self) -> StVenantKirchhoff:
        return StVenantKirchhoff(
            mu=self.G0, lam=2.0 * self.G0 * self.poisson / (1.0 - 2.0 * self.poisson)
        )

    def omegas(self) -> np.ndarray:
        """(n_frequencies,) angular frequencies (rad/s), omega tau_i from 0.1 to 10 for every
        term.
        """
        lo, hi = 0.1 / max(self.taus), 10.0 / min(self.taus)
        return (
            np.geomspace(lo, hi, self.n_frequencies)
            if self.n_frequencies > 1
            else np.array([np.sqrt(lo * hi)])
        )

    def to_dict(self) -> Dict[str, Any]:
        """The fields by name, the Prony tuples as lists."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, payload: Any, source: str = "<dict>") -> "RheometerSpec":
        """Inverse of :meth:`to_dict`; every field must be present.

        Raises:
            RecordError: a field missing, mistyped or out of range (named, with ``source``).
        """
        return _spec_from(JSONFields(payload, source))


def _spec_from(f: JSONFields) -> RheometerSpec:
    values: Dict[str, Any] = {}
    for name in (field.name for field in fields(RheometerSpec)):
        if name in ("alphas", "taus"):
            values[name] = tuple(f.numbers(name))
        elif name in _SPEC_INTEGERS:
            values[name] = f.integer(name)
        else:
            values[name] = f.number(name)
    return f.build(RheometerSpec, **values)


_SPEC_INTEGERS = (
    "target_cells",
    "samples_per_period",
    "warmup_periods",
    "measured_periods",
    "n_frequencies",
)


@dataclass(frozen=True)
class FrequencyRun:
    """One sinusoidal run at omega, before it is compared with the references.

    omega: rad/s; dt: the time step (s); G: the fitted G*/G0 (dimensionless, complex);
    steps: time steps integrated; cg_iterations_per_step: mean CG iterations of a step.
    """

    omega: float
    dt: float
    G: complex
    steps: int
    cg_iterations_per_step: float


@dataclass(frozen=True)
class FrequencyRow:
    """One frequency of the sweep: the simulated moduli and both references.

    omega (rad/s), frequency_hz (Hz), dt (s), steps and cg_iterations_per_step: as in
    :class:`FrequencyRun`. G_storage, G_loss: the simulated G' and G'' (Pa). continuous,
    discrete: (G', G'') of the generalised Maxwell model and of the exact backward-Euler
    recursion at this dt (Pa). rel_err_continuous, rel_err_discrete: |simulated - reference| /
    |reference| for G' and for G''.
    """

    omega: float
    dt: float
    steps: int
    cg_iterations_per_step: float
    frequency_hz: float
    G_storage: float
    G_loss: float
    continuous: Pair
    discrete: Pair
    rel_err_continuous: Pair
    rel_err_discrete: Pair

    def __post_init__(self) -> None:
        f = RecordFields(self)
        for name in ("omega", "dt", "frequency_hz"):
            f.real(name, positive=True)
        f.count("steps", minimum=1)
        for name in ("continuous", "discrete", "rel_err_continuous", "rel_err_discrete"):
            f.reals(name)
            if len(getattr(self, name)) != 2:
                raise f.refusal(name, "2 numbers (G', G'')", getattr(self, name))

    def to_dict(self) -> Dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_fields(cls, f: JSONFields) -> "FrequencyRow":
        pairs = ("continuous", "discrete", "rel_err_continuous", "rel_err_discrete")
        return f.build(
            cls,
            **{k: f.number(k) for k in ("omega", "dt", "cg_iterations_per_step")},
            steps=f.integer("steps"),
            **{k: f.number(k) for k in ("frequency_hz", "G_storage", "G_loss")},
            **{k: tuple(f.numbers(k, length=2)) for k in pairs},
        )


@dataclass(frozen=True)
class ErrorSummary:
    """Relative errors of the sweep against one reference: mean and max over G' and G'' of
    every frequency, and the mean of each modulus alone.
    """

    mean: float
    max: float
    mean_storage: float
    mean_loss: float

    @classmethod
    def of(cls, errors: np.ndarray) -> "ErrorSummary":
        """From the (n_frequencies, 2) relative errors, G' in column 0 and G'' in column 1."""
        return cls(
            mean=float(errors.mean()),
            max=float(errors.max()),
            mean_storage=float(errors[:, 0].mean()),
            mean_loss=float(errors[:, 1].mean()),
        )

    @classmethod
    def from_fields(cls, f: JSONFields) -> "ErrorSummary":
        return f.build(
            cls, **{k: f.number(k) for k in ("mean", "max", "mean_storage", "mean_loss")}
        )


@dataclass(frozen=True)
class SweepErrors:
    """The sweep's errors against the continuous Maxwell moduli and the exact discrete ones."""

    continuous: ErrorSummary
    discrete: ErrorSummary

    def to_dict(self) -> Dict[str, Any]:
        return {"continuous": asdict(self.continuous), "discrete": asdict(self.discrete)}

    @classmethod
    def from_fields(cls, f: JSONFields) -> "SweepErrors":
        return cls(
            continuous=ErrorSummary.from_fields(f.object("continuous")),
            discrete=ErrorSummary.from_fields(f.object("discrete")),
        )


@dataclass(frozen=True)
class Sweep:
    """What :func:`comparisons.rheometer.study.sweep` measures on one sample.

    elastic_torque_per_radian: the sample's elastic torque per radian of twist (N m / rad),
    the normalisation of G*; frequencies: one row per omega, in sweep order; errors: their
    summary against both references.
    """

    elastic_torque_per_radian: float
    frequencies: Tuple[FrequencyRow, ...]
    errors: SweepErrors

    def __post_init__(self) -> None:
        RecordFields(self).records("frequencies", FrequencyRow)
        if not self.frequencies:
            raise ValueError("Sweep: no frequencies")


@dataclass(frozen=True)
class SampleMesh:
    """The sample's mesh: node and cell counts, and the nodes on the lower and upper plates."""

    n_nodes: int
    n_cells: int
    n_bottom: int
    n_top: int

    def __post_init__(self) -> None:
        f = RecordFields(self)
        for name in ("n_nodes", "n_cells", "n_bottom", "n_top"):
            f.count(name, minimum=1)

    @classmethod
    def from_fields(cls, f: JSONFields) -> "SampleMesh":
        return f.build(
            cls, **{k: f.integer(k) for k in ("n_nodes", "n_cells", "n_bottom", "n_top")}
        )


@dataclass(frozen=True)
class RheometerResult:
    """The whole rheometer study: the spec, the sample, the sweep and the figures.

    spec: what was run; mesh: the gmsh cylinder's counts; elastic_torque_per_radian (N m / rad),
    frequencies (one :class:`FrequencyRow` per ``spec.omegas()``) and errors: the sweep;
    figures: the figure files written (paths); elapsed_s: the study's wall time (s).
    """

    spec: RheometerSpec
    mesh: SampleMesh
    elastic_torque_per_radian: float
    frequencies: Tuple[FrequencyRow, ...]
    errors: SweepErrors
    figures: Tuple[str, ...] = ()
    elapsed_s: float = 0.0

    def __post_init__(self) -> None:
        f = RecordFields(self)
        f.records("frequencies", FrequencyRow)
        f.texts("figures")
        if len(self.frequencies) != self.spec.n_frequencies:
            raise ValueError(
                f"RheometerResult: {len(self.frequencies)} frequency rows for "
                f"n_frequencies = {self.spec.n_frequencies}"
            )

    @property
    def study(self) -> str:
        return "rheometer"

    @property
    def lam(self) -> float:
        """St Venant-Kirchhoff's lam (Pa), from G0 and Poisson's ratio."""
        return self.spec.material.lam

    @classmethod
    def of(
        cls, spec: RheometerSpec, mesh: SampleMesh, sweep: Sweep, figures=(), elapsed_s=0.0
    ) -> "RheometerResult":
        """The record of ``sweep`` run on a sample of ``mesh`` for ``spec``."""
        return cls(
            spec=spec,
            mesh=mesh,
            elastic_torque_per_radian=sweep.elastic_torque_per_radian,
            frequencies=sweep.frequencies,
            errors=sweep.errors,
            figures=tuple(figures),
            elapsed_s=elapsed_s,
        )

    def to_dict(self) -> Dict[str, Any]:
        """The JSON form (the keys and their order as the study has always written them)."""
        return {
            "study": self.study,
            "spec": self.spec.to_dict(),
            "lam": self.lam,
            "mesh": asdict(self.mesh),
            "elastic_torque_per_radian": self.elastic_torque_per_radian,
            "frequencies": [r.to_dict() for r in self.frequencies],
            "errors": self.errors.to_dict(),
            "figures": list(self.figures),
            "elapsed_s": self.elapsed_s,
        }

    @classmethod
    def from_dict(cls, payload: Any, source: str = "<dict>") -> "RheometerResult":
        """Inverse of :meth:`to_dict`, validated.

        Raises:
            RecordError: a key missing or mistyped, a value out of range, or a ``study`` or
                ``lam`` that does not belong to this record (each named, with ``source``).
        """
        f = JSONFields(payload, source)
        if f.text("study") != "rheometer":
            raise f.error("study", f"expected 'rheometer', got {f.text('study')!r}")
        spec = _spec_from(f.object("spec"))
        if not math.isclose(f.number("lam"), spec.material.lam, rel_tol=1e-12):
            raise f.error("lam", f"{f.number('lam')!r} is not the spec's {spec.material.lam!r}")
        return f.build(
            cls,
            spec=spec,
            mesh=SampleMesh.from_fields(f.object("mesh")),
            elastic_torque_per_radian=f.number("elastic_torque_per_radian"),
            frequencies=tuple(FrequencyRow.from_fields(r) for r in f.objects("frequencies")),
            errors=SweepErrors.from_fields(f.object("errors")),
            figures=tuple(f.texts("figures")),
            elapsed_s=f.number("elapsed_s"),
        )
