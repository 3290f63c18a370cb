"""A kit's cases: model x mesh x state, each primary case with its probes.

Each primary case has PROBES probe cases: the same model and mesh at x + eps_k d with
eps_k = eps_0 / 2^k, d a seeded random direction, eps_0 = 1e-4 of the mean edge length at each
node, or of the smallest height of the node's cells if smaller (:func:`probe_lengths`). The check
uses them for a Taylor test of the engine's stiffness against its own forces (and of its forces
against its own energy), which needs no oracle. :mod:`conformance.kit.write` writes them into a
kit folder, :mod:`conformance.kit.read` reads them back.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from common.frames import with_default_frame
from common.states import apply_state
from common.tolerances import mean_edge_length
from conformance.kit.confine import (
    MAX_CASE_ID,
    check_case_id,
)
from conformance.kit.spec import CaseInput, model_label

__all__ = [
    "KitCase",
    "PROBES",
    "PROBE_STEP",
    "build_cases",
    "case_id",
]

PROBES = 4
PROBE_STEP = 1e-4  # eps_0 as a fraction of the mean edge length


@dataclass(frozen=True)
class KitCase:
    """A case of the kit: its input, and where it belongs.

    role: "case" (compared with the oracle) or "probe" (a perturbed state of ``probe_of``).
    """

    input: CaseInput
    role: str
    mesh: str
    state: str
    probe_of: Optional[str] = None
    step: int = 0
    # Where a kit read back keeps this case (confined to the kit): the engine is given exactly
    # the input directory whose hashes were checked, and its output is read from output_dir.
    input_dir: Optional[str] = None
    output_dir: Optional[str] = None

    @property
    def case_id(self) -> str:
        return self.input.case_id


def case_id(model: Any, mesh: str, state: str) -> str:
    raw = f"{model_label(model)}.{os.path.splitext(os.path.basename(mesh))[0]}.{state}"
    # one safe path component (conformance.kit.confine.check_case_id): no '..', no leading dot
    safe = re.sub(r"\.{2,}", ".", re.sub(r"[^A-Za-z0-9_.+-]", "_", raw)).lstrip(".")
    return safe[: MAX_CASE_ID - 8]  # room for a probe's "~probeK"


def probe_direction(points: np.ndarray, seed: int) -> np.ndarray:
    """A seeded random nodal direction (n, 3) scaled to eps_0 = PROBE_STEP x mean edge at its
    largest node.
    """
    rng = np.random.default_rng(seed)
    d = rng.standard_normal(points.shape)
    return d / np.linalg.norm(d, axis=1).max()


StateSpec = Union[str, Tuple[str, Callable[[np.ndarray, np.ndarray], np.ndarray]]]


def probe_lengths(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(n,) per node, the length its probe displacement is a fraction of: the mean edge, or the
    smallest height of the cells around the node when smaller. A step of 1e-4 of the mean edge
    is a strain of 10 % in a cap of quality 1e-3, where no fit can resolve the tangent; scaled
    by each node's own cells, every cell is strained by about 1e-4, the large cells of a graded
    mesh as much as its tiny ones. points (n, 3), cells (m, 4) [length unit of points].
    """
    from meshes.hard import heights

    out = np.full(len(points), mean_edge_length(points, cells))
    h = np.repeat(heights(points, cells), 4)
    np.minimum.at(out, np.asarray(cells).ravel(), h)
    return out


def build_cases(
    models: Sequence[Any],
    meshes: Sequence[Tuple[str, np.ndarray, np.ndarray]],
    states: Sequence[StateSpec],
    *,
    probes: int = PROBES,
) -> List[KitCase]:
    """Every model x mesh x state, each followed by its probes (seeded, reproducible).

    A state is a name of :data:`common.states.STATES` or a pair (name, function(X, cells) -> x).

    A model whose energy needs material directions and has none (Costa without a frame, a user
    energy using I4/I5 without a fibre) is given the mesh's helical frame field
    (:func:`common.frames.with_default_frame`), so that the kit carries a frame that varies
    from cell to cell and an engine that ignores or mis-rotates it fails.
    """
    out: List[KitCase] = []
    named = [
        (s, lambda X, c, s=s: apply_state(s, X, c)) if isinstance(s, str) else s for s in states
    ]
    states = [name for name, _ in named]
    for mesh_label, points, cells in meshes:
        h = probe_lengths(np.asarray(points, dtype=float), np.asarray(cells))[:, None]
        xs = {name: fn(np.asarray(points, dtype=float), np.asarray(cells)) for name, fn in named}
        for given in models:
            model = with_default_frame(given, points, cells)
            for k_state, state in enumerate(states):
                cid = case_id(model, mesh_label, state)
                out.append(
                    KitCase(
                        CaseInput(cid, points, cells, xs[state], model), "case", mesh_label, state
                    )
                )
                d = probe_direction(np.asarray(points), seed=1000 + k_state) * (PROBE_STEP * h)
                for k in range(probes):
                    x = xs[state] + d / 2**k
                    out.append(
                        KitCase(
                            CaseInput(f"{cid}~probe{k}", points, cells, x, model),
                            "probe",
                            mesh_label,
                            state,
                            probe_of=cid,
                            step=k,
                        )
                    )
    ids = [c.case_id for c in out]
    for i in ids:
        check_case_id(i, "case id")
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise ValueError(
            f"two cases share an id ({', '.join(dup[:3])}): give the meshes distinct names"
        )
    return out


def primary_and_probes(cases: Iterable[KitCase]) -> List[Tuple[KitCase, List[KitCase]]]:
    """Each primary case with its probes in step order."""
    cases = list(cases)
    probes: Dict[str, List[KitCase]] = {}
    for c in cases:
        if c.role == "probe":
            probes.setdefault(c.probe_of or "", []).append(c)
    return [
        (c, sorted(probes.get(c.case_id, []), key=lambda p: p.step))
        for c in cases
        if c.role == "case"
    ]
