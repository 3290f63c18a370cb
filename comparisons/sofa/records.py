"""The SOFA study's records: one verdict per force field, material and mesh; one timing row per
force field, material and mesh.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Optional

__all__ = ["SofaVerdict", "SofaTiming"]


@dataclass(frozen=True)
class SofaVerdict:
    """``mjed-verify check`` on one SOFA force field, material and mesh, every state given.

    passed/cases: cases that passed, of those run (probes aside); force_error and
    stiffness_error: the worst relative errors over the compared cases (None when none was
    compared); diagnosis: the first finding of the first failed case, in the checker's words
    ("" when all passed); bad_input: the first case the engine could not compute, with why.
    """

    forcefield: str
    material: str
    mesh: str
    states: str
    passed: int
    cases: int
    force_error: Optional[float]
    stiffness_error: Optional[float]
    diagnosis: str = ""
    bad_input: str = ""
    command: str = ""

    def __post_init__(self):
        if not 0 <= self.passed <= self.cases:
            raise ValueError(
                f"SofaVerdict {self.forcefield}/{self.material}/{self.mesh}: "
                f"passed {self.passed} of {self.cases}"
            )

    @property
    def all_passed(self) -> bool:
        return self.cases > 0 and self.passed == self.cases

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class SofaTiming:
    """Median seconds per call on one mesh, one thread. ``method``: ``sofa-mjed``,
    ``sofa-hyperelasticity``, ``sofa-standard`` (SOFA's calls timed inside its process) or
    ``mjed-numba``, ``classical-numba`` (the project's compiled kernels, timed from Python in
    the same run). ``dforce``: one addDForce (SOFA only; what a CG iteration costs).
    """

    method: str
    material: str
    mesh: str
    n_cells: int
    force_s: float
    force_stiffness_s: float
    dforce_s: Optional[float] = None

    def __post_init__(self):
        if not (self.force_s > 0 and self.force_stiffness_s > 0):
            raise ValueError(f"SofaTiming {self.method}/{self.material}: times must be > 0")

    def to_dict(self) -> dict:
        return asdict(self)
