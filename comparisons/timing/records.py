"""What the timing and scaling studies measure, as typed records.

The studies build these while measuring; the checks, tables and figures read them by
attribute; ``to_dict()`` gives the JSON form written to ``results.json`` (the keys are the
field names, so the file documents itself). Times are in seconds, memory in bytes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Optional, Tuple

from comparisons.timing.bandwidth import Bandwidth
from comparisons.timing.methods import Verification

__all__ = [
    "MeshInfo",
    "TimedCall",
    "Ratio",
    "Floor",
    "Verified",
    "Skipped",
    "MemoryRecord",
    "Rounds",
    "TimingSettings",
    "TimingData",
    "ScalingRow",
    "ScalingSettings",
    "ScalingData",
    "MEMORY_NOTE",
]


@dataclass(frozen=True)
class MeshInfo:
    """The timed mesh: its label, cell and node counts and the stiffness's stored entries."""

    name: str
    n_cells: int
    n_nodes: int
    nnz: int


@dataclass(frozen=True)
class TimedCall:
    """One (material, method, what) summarised over its rounds: seconds per call."""

    material: str
    method: str
    what: str
    median_s: float
    min_s: float
    max_s: float
    repeats: int
    calls_per_repeat: int
    spread: float
    stopped_by: str
    protocol: str


@dataclass(frozen=True)
class Ratio:
    """numerator/denominator times (``ratio`` names the pair), formed within each round."""

    material: str
    what: str
    ratio: str
    median: float
    min: float
    max: float
    per_repeat: List[float]


@dataclass(frozen=True)
class Floor:
    """The least time force+stiffness can take: the bytes it must move at the copy bandwidth."""

    bytes: int
    seconds: float
    what: str


@dataclass(frozen=True)
class Verified:
    """A method's result against NumPy MJED's at the timing state, before it is timed."""

    material: str
    method: str
    check: Verification

    def to_dict(self) -> dict:
        return {"material": self.material, "method": self.method, **self.check.to_dict()}


@dataclass(frozen=True)
class Skipped:
    material: str
    method: str
    reason: str


@dataclass(frozen=True)
class MemoryRecord:
    """Peak resident-set growth of one method (``error`` says why it was not measured)."""

    material: str
    method: str
    peak_bytes: Optional[int] = None
    resident_after_bytes: Optional[int] = None
    error: Optional[str] = None

    def to_dict(self) -> dict:
        return {
            k: v for k, v in asdict(self).items() if v is not None or k in ("material", "method")
        }


@dataclass(frozen=True)
class Rounds:
    rounds: int
    stopped_by: str


@dataclass(frozen=True)
class TimingSettings:
    protocol: str
    protocol_text: str
    methods: List[str]
    labels: Dict[str, str]
    quick: bool
    iterations: Any
    repeats: int
    state: str = "smooth_random (seed 0)"
    timer: str = "time.perf_counter, mean per call, gc off"


MEMORY_NOTE = (
    "peak_bytes: resident-set high-water mark (VmHWM) of a fresh process after building the method "
    "and one force+stiffness call, minus its resident set before building"
)


@dataclass
class TimingData:
    """Everything the timing study measured on one mesh (filled in as it measures)."""

    mesh: MeshInfo
    settings: TimingSettings
    bandwidth: Bandwidth
    floor: Floor
    results: List[TimedCall] = field(default_factory=list)
    ratios: List[Ratio] = field(default_factory=list)
    opcount: Dict[str, dict] = field(default_factory=dict)
    verification: List[Verified] = field(default_factory=list)
    skipped: List[Skipped] = field(default_factory=list)
    memory: List[MemoryRecord] = field(default_factory=list)
    setup_s: Dict[Tuple[str, str], float] = field(default_factory=dict)
    rounds: Dict[str, Rounds] = field(default_factory=dict)
    load_average: Dict[str, Optional[List[float]]] = field(default_factory=dict)
    provenance: Dict[str, Any] = field(default_factory=dict)
    figures: List[str] = field(default_factory=list)
    targets: List[dict] = field(default_factory=list)

    @property
    def materials(self) -> List[str]:
        """The timed materials, in the order they were timed."""
        return list(dict.fromkeys(r.material for r in self.results))

    def call(
        self, material: str, method: str, what: str = "force+stiffness"
    ) -> Optional[TimedCall]:
        return next(
            (r for r in self.results if (r.material, r.method, r.what) == (material, method, what)),
            None,
        )

    def median(self, material: str, method: str, what: str = "force+stiffness") -> Optional[float]:
        r = self.call(material, method, what)
        return None if r is None else r.median_s

    def ratio(self, material: str, pair: str, what: str = "force+stiffness") -> Optional[Ratio]:
        return next(
            (r for r in self.ratios if (r.material, r.ratio, r.what) == (material, pair, what)),
            None,
        )

    def skipped_pairs(self) -> set:
        return {(s.material, s.method) for s in self.skipped}

    def to_dict(self) -> dict:
        return {
            "mesh": asdict(self.mesh),
            "results": [asdict(r) for r in self.results],
            "ratios": [asdict(r) for r in self.ratios],
            "opcount": self.opcount,
            "bandwidth": self.bandwidth.to_dict(),
            "floor": asdict(self.floor),
            "verification": [v.to_dict() for v in self.verification],
            "skipped": [asdict(s) for s in self.skipped],
            "memory": [m.to_dict() for m in self.memory],
            "memory_note": MEMORY_NOTE,
            "setup_s": [
                {"material": n, "method": m, "seconds": s} for (n, m), s in self.setup_s.items()
            ],
            "rounds": {n: asdict(r) for n, r in self.rounds.items()},
            "settings": asdict(self.settings),
            "load_average": self.load_average,
            "provenance": self.provenance,
            "figures": list(self.figures),
            "targets": list(self.targets),
        }


@dataclass(frozen=True)
class ScalingRow:
    """One (method, size) of the scaling study, from a fresh process."""

    method: str
    target_cells: int
    n_cells: int
    n_nodes: int
    seconds: float
    seconds_per_cell: float
    peak_bytes: int
    peak_bytes_per_cell: float
    setup_s: float
    wall_s: float


@dataclass(frozen=True)
class ScalingSettings:
    sizes: List[int]
    repeats: int
    time_budget_s: float
    quick: bool
    methods: List[str]
    labels: Dict[str, str]
    mesh: str = "structured unit cube, 6 tetrahedra per hexahedron (meshes.structured)"


@dataclass
class ScalingData:
    """The scaling study's rows, and how far each method went (``stopped``)."""

    material: str
    settings: ScalingSettings
    rows: List[ScalingRow] = field(default_factory=list)
    stopped: Dict[str, str] = field(default_factory=dict)
    load_average: Optional[List[float]] = None
    provenance: Dict[str, Any] = field(default_factory=dict)
    figures: List[str] = field(default_factory=list)
    targets: List[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "material": self.material,
            "rows": [asdict(r) for r in self.rows],
            "stopped": dict(self.stopped),
            "settings": asdict(self.settings),
            "load_average": self.load_average,
            "provenance": self.provenance,
            "figures": list(self.figures),
            "targets": list(self.targets),
        }
