"""Force or stiffness evaluated at another state: the tangent kept from the rest state (the
reference configuration, or a first Newton step), or the positions of another case of the kit.

The kit holds the rest state (x = X) and the other cases of the same model and mesh; the oracle
is evaluated there (one assembly per state, the compiled form shared) and the engine's force and
stiffness compared with each. A quantity is said to be another state's only when it is wrong at
its own state and within the case's tolerance of the oracle's at that state; several states that
fit equally are shown as ambiguous. The force at rest is zero, so it is never matched there (a
zero force is not evidence of a state).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import List, Sequence

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import FULL, Finding, ambiguous
from conformance.judge.compare import Errors, Scales, Tolerances, errors

__all__ = ["OtherState", "other_state_findings", "other_state_reading", "MAX_STATES"]

#: Other cases of the kit compared with (besides the rest state): one oracle assembly each.
MAX_STATES = 8


@dataclass(frozen=True)
class OtherState:
    """A state of the kit the engine may have evaluated instead: name (words), the oracle's
    force (n, 3) and stiffness (3n, 3n) there, and that state's error scales.
    """

    name: str
    force: np.ndarray
    stiffness: sp.csr_matrix
    scales: Scales
    rest: bool = False


def other_state_findings(
    f: np.ndarray,
    K: sp.spmatrix,
    own: Errors,
    own_scales: Scales,
    tol: Tolerances,
    states: Sequence[OtherState],
) -> List[Finding]:
    """The states whose oracle force and/or stiffness the engine's are (f (n, 3), K (3n, 3n);
    ``own``: its errors at its own state): a finding for each, ambiguous when several fit.
    """
    f_own = own.force <= tol.force
    K_own = own.stiffness <= tol.stiffness
    found = []
    for st in states:
        e = errors(f, K, None, st.force, st.stiffness, 0.0, st.scales)
        # A state's force is evidence only where it is not zero (the rest state's is).
        has_force = float(np.linalg.norm(st.force)) > tol.force * own_scales.force
        f_there = has_force and e.force <= tol.force
        K_there = e.stiffness <= tol.stiffness
        # residual: what is left of the output with each quantity against the state it is from
        if K_there and f_there and not (f_own and K_own):
            which, code, left = "force and stiffness are", "other-state", (e.force, e.stiffness)
        elif K_there and f_own and not K_own:
            which, code, left = (
                "the stiffness is",
                "stiffness-other-state",
                (own.force, e.stiffness),
            )
        elif f_there and K_own and not f_own:
            which, code, left = "the force is", "force-other-state", (e.force, own.stiffness)
        else:
            continue
        found.append(
            Finding(
                code,
                f"{which} the oracle's at {st.name}, not at this case's positions",
                FULL,
                f"against the oracle at that state: force error {e.force:.1e}, stiffness error "
                f"{e.stiffness:.1e}; at this case's own positions: force error {own.force:.1e}, "
                f"stiffness error {own.stiffness:.1e}",
                {"state": st.name, "rest": st.rest, "residual": max(left)},
            )
        )
    return ambiguous(found, "those states have the same force and stiffness within tolerance")


def other_state_reading(diag, cache, ci, out, s: Scales, others: Sequence):
    """``diag`` (a failed case nothing explained yet) with the other states the engine's output
    (``out``) belongs to, named first; unchanged when none fits. ``others``: the kit's other
    cases (KitCase) of the same model and mesh; the first :data:`MAX_STATES` are compared, and
    the rest state always (one oracle assembly each, on the case's compiled form).
    """
    from common.tolerances import mean_edge_length
    from conformance.judge.compare import scales

    h = mean_edge_length(ci.points, ci.cells)
    rest = replace(ci, case_id=ci.case_id + "~rest", positions=ci.points)
    candidates = [("the rest state (x = X, the reference configuration)", rest, True)]
    candidates += [
        (f"the kit's state '{c.state}' (case {c.case_id})", c.input, False)
        for c in list(others)[:MAX_STATES]
    ]
    states = []
    for name, inp, is_rest in candidates:
        if np.array_equal(inp.positions, ci.positions):
            continue  # the same positions: not another state
        try:
            r = cache.reference(inp)
        except ValueError:  # the oracle is not finite there: that state says nothing
            continue
        sc = scales(h, r.energy, r.force, r.stiffness)
        states.append(OtherState(name, r.force, r.stiffness, sc, is_rest))
    found = other_state_findings(
        out.force, sp.csr_matrix(out.stiffness), diag.errors, s, diag.tolerances, states
    )
    if not found:
        return diag
    return replace(diag, findings=[*found, *(f for f in diag.findings if f.code != "unexplained")])
