"""The energy wrong while its derivatives are right.

An engine often computes its energy in a routine of its own (a scene's energy output, a line
search's merit function) beside the stress routine that gives force and stiffness. A mistake
there leaves force and stiffness right and the energy wrong, and often only away from simple
states: summed with the mesh's mean cell volume, which is right wherever the density is uniform
(a homogeneous stretch); (tr E)^2 typed as NumPy's tr(E**2), right wherever E is diagonal with
one nonzero entry. On such a state the energy matches and only the probes show the mistake: the
force is not minus the derivative of the engine's energy. Because the force here is the oracle's,
that inconsistency alone proves the energy wrong at the probes, and the kit's probes say by how
much (the oracle's energies there are known).

Named from the states of the case (the state and its probes, each with the engine's energy):
the engine's energies against a small set of declared energy mistakes, each predicted from
the oracle's per-cell energies V0_c W_c (MJED's, used only where their sum is the oracle's
energy at every state) with nothing fitted (a weight per cell from its volume) or one number
fitted over all states (a factor on the whole energy, on its isochoric or its volumetric part,
a constant). When none fits, the finding says the energy
routine alone is wrong, with the figures, and does not guess which formula. NumPy only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.findings import FULL, Finding, ambiguous

__all__ = ["EnergyStates", "WEIGHTINGS", "CHANGES", "energy_states", "energy_alone_findings"]

#: How closely a mistake must predict the engine's energy changes from the state to its probes,
#: relative to the largest change. The probes move the nodes by 1e-3 of an edge, so a change is
#: about 1e-3 of the energy and carries double round-off of about 1e-13 of itself; a mistake
#: that gets the energy's level right but not its slope (a factor fitted where a volume weight
#: belongs) misses by the relative size of the slope's error, far above this.
CHANGES = 1e-6

#: name -> (words, weight q_c (m,) of each cell's oracle energy V0_c W_c from the rest volumes
#: V0 (m,) and the cells' J (m,) at the state): the engine's energy is sum_c q_c V0_c W_c.
WEIGHTINGS: Dict[str, Tuple[str, Callable[[np.ndarray, np.ndarray], np.ndarray]]] = {
    "mean volume": (
        "the energy summed with the mesh's mean cell volume, mean(V0) sum_c W_c, where "
        "sum_c V0_c W_c belongs (right only where the density is uniform)",
        lambda V0, J: np.full_like(V0, V0.mean()) / V0,
    ),
    "no volume": (
        "the energy densities summed without the cell volumes, sum_c W_c, where sum_c V0_c W_c "
        "belongs",
        lambda V0, J: 1.0 / V0,
    ),
    "V0 twice": (
        "each cell's energy multiplied by its rest volume twice, sum_c V0_c^2 W_c",
        lambda V0, J: V0,
    ),
    "deformed volume": (
        "the energy densities integrated over the deformed volume, sum_c J_c V0_c W_c, where "
        "the rest volume belongs",
        lambda V0, J: J,
    ),
}


@dataclass(frozen=True)
class EnergyStates:
    """The case's states as the energy reading sees them.

    engine, oracle: (k,) total energies [J] at the state and its probes; cells: (k, m) the
    oracle's per-cell energies V0_c W_c there (None: MJED cannot split this material, or its
    sum is not the oracle's); J: (k, m) each cell's volume ratio; V0: (m,) rest volumes [m^3];
    scale: the energy scale [J] of the relative figures.
    """

    engine: np.ndarray
    oracle: np.ndarray
    cells: Optional[np.ndarray]
    J: np.ndarray
    V0: np.ndarray
    scale: float
    #: (k,) the declared volumetric energy sum_c V0_c U(J_c) at each state (None: no
    #: volumetric part declared)
    volumetric: Optional[np.ndarray] = None

    def relative(self, predicted: np.ndarray) -> float:
        """Largest |engine - predicted| over the states, relative to the scale."""
        return float(np.max(np.abs(self.engine - predicted))) / self.scale

    def changes(self, predicted: np.ndarray) -> float:
        """Largest miss of the energy changes from the state to its probes, (E_k - E_0), of
        ``predicted`` against the engine's, relative to the engine's largest change (inf when
        the engine's energy does not change).
        """
        de = self.engine[1:] - self.engine[0]
        dp = predicted[1:] - predicted[0]
        top = float(np.max(np.abs(de))) if de.size else 0.0
        return float(np.max(np.abs(de - dp))) / top if top > 0 else float("inf")

    def matches(self, predicted: np.ndarray, tol: float) -> bool:
        """``predicted`` is the engine's energy at every state (within ``tol`` of the scale)
        and its changes over the probes (within :data:`CHANGES`).
        """
        return (
            bool(np.all(np.isfinite(predicted)))
            and self.relative(predicted) <= tol
            and self.changes(predicted) <= CHANGES
        )


def cell_energies(model, points, cells, positions: Sequence[np.ndarray]):
    """(k, m) V0_c W_c from MJED at each of the k ``positions`` (n, 3), one field for all; None
    where MJED has no such material or cannot evaluate a state.
    """
    import mjed
    from mjed.evaluation import Want

    try:
        field = mjed.make_force_field(mjed.TetMesh(points, cells), model)
        return np.stack(
            [np.asarray(field.evaluate(x, want=Want.ENERGY).energy, float) for x in positions]
        )
    except Exception:  # noqa: BLE001 - not an MJED material, or not at this state
        return None


def energy_states(
    model,
    points: np.ndarray,
    cells: np.ndarray,
    positions: Sequence[np.ndarray],
    engine: Sequence[float],
    oracle: Sequence[float],
    scale: float,
    tol: float,
) -> EnergyStates:
    """The states (positions (n, 3) each, the case's first) with both energies per state; the
    per-cell split kept only when it sums to the oracle's energy within ``tol`` everywhere.
    """
    positions = [np.asarray(x, dtype=np.float64) for x in positions]
    oracle = np.asarray(oracle, dtype=np.float64)
    V0 = cell_kinematics(points, cells, positions[0])[0]
    J = np.stack([np.linalg.det(cell_kinematics(points, cells, x)[2]) for x in positions])
    split = cell_energies(model, points, cells, positions)
    if split is not None and np.max(np.abs(split.sum(axis=1) - oracle)) > tol * scale:
        split = None
    engine = np.asarray(engine, dtype=np.float64)
    return EnergyStates(engine, oracle, split, J, V0, float(scale), _volumetric(model, V0, J))


def _volumetric(model, V0: np.ndarray, J: np.ndarray) -> Optional[np.ndarray]:
    """(k,) sum_c V0_c U(J_c) of the model's declared volumetric energy at each state's J (k, m);
    None without one (or a formula that reads more than J and ln J).
    """
    from types import SimpleNamespace

    from conformance.diagnosis.energy_terms import declaration

    declared = declaration(model)
    if declared is None or declared.volumetric is None:
        return None
    try:
        U = declared.volumetric(
            lambda name: float(getattr(model, name)), SimpleNamespace(J=J, lnJ=np.log(J))
        )
    except (AttributeError, TypeError):
        return None
    return (np.asarray(U, dtype=np.float64) * V0).sum(axis=1)


def _candidates(st: EnergyStates) -> List[Tuple[str, str, np.ndarray, Dict[str, float]]]:
    """(code, words, predicted engine energies (k,), figures) of every declared mistake."""
    out = []
    if st.cells is not None:
        for name, (words, weight) in WEIGHTINGS.items():
            q = np.stack([weight(st.V0, J) for J in st.J])
            out.append(("energy-" + name.replace(" ", "-"), words, (q * st.cells).sum(1), {}))
    o, e = st.oracle, st.engine
    if np.dot(o, o) > 0:
        a = float(np.dot(o, e) / np.dot(o, o))
        out.append(
            (
                "energy-factor",
                f"the energy alone scaled by {a:.6g} (a factor written in the energy and not in "
                "the stress, or left out of it)",
                a * o,
                {"factor": a},
            )
        )
    if st.volumetric is not None:
        out += _part_factors(o, e, st.volumetric)
    b = float(np.mean(e - o))
    volume = float(st.V0.sum())
    out.append(
        (
            "energy-constant",
            f"a constant added to the energy density: {b / volume:.6g} Pa over the rest volume "
            "(a constant left in or out of W, e.g. the -3 of I1 - 3, the energy's value at rest)",
            o + b,
            {"offset": b, "density": b / volume},
        )
    )
    return out


#: A part's factor as said when it is one of these.
_SAID = {
    "2": "doubled (scaled by 2)",
    "1/2": "halved (scaled by 1/2)",
    "-1": "with its sign flipped",
}


def _part_factors(o: np.ndarray, e: np.ndarray, vol: np.ndarray):
    """The energy's isochoric part (o - vol) or its volumetric part vol scaled by one number
    fitted over the states, the other part right: (code, words, predicted, figures) each.
    """
    from conformance.diagnosis.fractions import written_number

    out = []
    iso = o - vol
    for code, part, rest, said in (
        ("energy-isochoric-factor", iso, vol, "isochoric part (all but U(J))"),
        ("energy-volumetric-factor", vol, iso, "volumetric part U(J)"),
    ):
        if not np.dot(part, part) > 0:
            continue
        a = float(np.dot(part, e - rest) / np.dot(part, part))
        how = _SAID.get(written_number(a), f"scaled by {written_number(a)}")
        out.append(
            (
                code,
                f"the energy's {said} alone {how} in the energy routine (a factor written in "
                "that part's energy and not in its stress, or left out of it)",
                a * part + rest,
                {"factor": a},
            )
        )
    return out


def energy_alone_findings(st: EnergyStates, tol: float, inconsistency: Optional[float]):
    """Findings for an engine whose force and stiffness are right and whose energy is not: the
    declared mistakes whose predicted energies match the engine's at every state (within
    ``tol`` of the scale) and differ from the oracle's at one; else the energy routine alone,
    with its figures. inconsistency: the probes' relative force-energy inconsistency, if found.
    """
    off = st.relative(st.oracle)
    if off <= tol:
        return []  # the energy is the oracle's at every state, within the verdict's tolerance
    found = []
    for code, words, predicted, figures in _candidates(st):
        left = st.relative(predicted)
        if st.matches(predicted, tol):
            found.append(
                Finding(
                    code,
                    f"your energy is wrong, its force and stiffness right: {words}",
                    FULL,
                    f"at the case's state and its {len(st.engine) - 1} probes your energies "
                    f"differ from the oracle's by up to {off:.1e} (relative), their changes "
                    f"over the probes by {st.changes(st.oracle):.1e}; this mistake predicts "
                    f"them to {left:.1e}, their changes to {st.changes(predicted):.1e}",
                    {"off": off, "left": left, "changes_left": st.changes(predicted), **figures},
                )
            )
    if found:
        return ambiguous(found, "each gives your energies at these states")
    here = abs(st.engine[0] - st.oracle[0]) / st.scale
    where = (
        "here and at the probes"
        if here > tol
        else "at the probes around this state (here it matches: a state that hides the mistake, "
        "such as a uniform or one-directional strain)"
    )
    said = (
        ""
        if inconsistency is None
        else f"; your force is not minus its derivative ({inconsistency:.1e})"
    )
    return [
        Finding(
            "energy",
            "your energy is wrong, its force and stiffness right: the energy routine alone "
            "computes another energy than the one its stress derives from",
            FULL,
            f"force and stiffness match the oracle's; your energy differs from the oracle's "
            f"{where}: by up to {off:.1e} (relative) over the case's state and its "
            f"{len(st.engine) - 1} probes{said}; no declared energy mistake (a volume weight, a "
            "factor, a constant) predicts it: look at the energy's formula where it differs "
            "from the stress's",
            {"off": off, "here": here, "inconsistency": inconsistency},
        )
    ]


def energy_alone_reading(diag, cache, ci, out, ref, s, probes, probe_results):
    """``diag`` (force and stiffness right, the energy wrong here or inconsistent with the
    force at the probes) with the energy mistake named first, replacing the plain "energy
    differs" finding; unchanged without the engine's energies at the probes or the oracle's.
    """
    tol = diag.tolerances
    energies = [r[2] for r in probe_results]
    if out.energy is None or not probes or any(e is None for e in energies):
        return diag
    try:
        oracle = cache.probes(ci, ref, [p.input for p in probes]).probe_energies
    except ValueError:  # the oracle cannot evaluate a probe
        return diag
    scale = max(s.energy, float(np.max(np.abs(oracle))), abs(float(ref.energy)))
    if not scale > 0:
        return diag
    st = energy_states(
        ci.model,
        ci.points,
        ci.cells,
        [ci.positions, *(r[0] for r in probe_results)],
        [float(out.energy), *(float(e) for e in energies)],
        [float(ref.energy), *oracle],
        scale,
        tol.energy,
    )
    if st.relative(st.oracle) <= tol.energy:
        return diag  # the energies agree at every state: nothing to say about the energy
    inconsistent = next((f for f in diag.findings if f.code == "inconsistent-force"), None)
    found = energy_alone_findings(
        st, tol.energy, None if inconsistent is None else inconsistent.figures.get("inconsistency")
    )
    rest = [f for f in diag.findings if f.code not in ("unexplained", "energy")]
    return replace(diag, findings=[*found, *rest])
