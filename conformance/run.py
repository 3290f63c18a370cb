"""Check an engine case by case: get its output (files, a command or a Python callable), compare
with
the oracle, diagnose; a bad case is reported and the others still run.

The engine is reached through an *evaluator*: ``evaluate(kit_case) -> EngineOutput``, raising
:class:`CaseError` (bad output, crash, time limit) for that case only.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from common.result import EXIT_FAILED, EXIT_INPUT, EXIT_PASSED
from common.tolerances import mean_edge_length
from conformance.diagnosis import readings
from conformance.diagnosis.assembly import buffered_assembly_reading
from conformance.diagnosis.cell_weights import cell_weight_reading
from conformance.diagnosis.cells import cell_contribution_reading, spread_cells_reading
from conformance.diagnosis.central_differences import central_difference_reading
from conformance.diagnosis.coincident_stretches import coincident_reading
from conformance.diagnosis.complex_step import complex_step_reading
from conformance.diagnosis.corroborate import corroborate, extend_consistent, extend_covered
from conformance.diagnosis.definiteness import definiteness_findings
from conformance.diagnosis.derivative_rewrites import derivative_rewrite_reading
from conformance.diagnosis.diagnose import Diagnosis, denied_volumetric, diagnose
from conformance.diagnosis.differences import element_difference_reading
from conformance.diagnosis.directional_differences import directional_difference_reading
from conformance.diagnosis.edge_ids import edge_id_reading
from conformance.diagnosis.edge_kinematics import edge_kinematics_reading
from conformance.diagnosis.element_forces import force_node_findings
from conformance.diagnosis.elements import element_reading
from conformance.diagnosis.energy_alone import energy_alone_reading
from conformance.diagnosis.energy_differences import energy_difference_reading
from conformance.diagnosis.entry_steps import entry_step_reading
from conformance.diagnosis.findings import FULL, OBSERVED, PARTIAL, Finding
from conformance.diagnosis.frame_routine import frame_routine_reading
from conformance.diagnosis.frames import frame_variants
from conformance.diagnosis.hand_derived import (
    hand_derived_reading,
    nearby_force_reading,
    tangent_term_reading,
)
from conformance.diagnosis.invariant_gradients import gradient_reading
from conformance.diagnosis.isochoric_curvature import isochoric_curvature_reading
from conformance.diagnosis.mixed_precision import (
    mixed_precision_reading,
    rounded_elements_reading,
)
from conformance.diagnosis.mjed_parts import mjed_part_reading
from conformance.diagnosis.node_blocks import node_block_reading
from conformance.diagnosis.part_powers import part_power_reading
from conformance.diagnosis.permuted_values import permuted_values_reading
from conformance.diagnosis.piola_assembly import piola_assembly_reading
from conformance.diagnosis.piola_slips import piola_slip_reading
from conformance.diagnosis.principal_blocks import principal_block_reading
from conformance.diagnosis.principal_differences import principal_difference_reading
from conformance.diagnosis.rest_tangent import rest_tangent_reading
from conformance.diagnosis.roundoff import signature as roundoff_signature
from conformance.diagnosis.routine_derivatives import routine_derivative_reading
from conformance.diagnosis.routine_inputs import spatial_kinematics_reading
from conformance.diagnosis.second_derivative import second_derivative_reading
from conformance.diagnosis.shape_gradients import shape_gradient_reading
from conformance.diagnosis.sparsity import off_pattern_reading
from conformance.diagnosis.spectral_frames import spectral_frame_reading
from conformance.diagnosis.split_parts import split_part_reading
from conformance.diagnosis.states import other_state_reading
from conformance.diagnosis.stiffness_noise import NOISE_RANGE, stiffness_noise_reading
from conformance.diagnosis.strain_differences import strain_difference_reading
from conformance.diagnosis.stress_forms import stress_form_reading
from conformance.diagnosis.stress_side import stress_side_reading
from conformance.diagnosis.stress_terms import b_for_c_reading
from conformance.diagnosis.svd_blocks import svd_block_reading
from conformance.diagnosis.term_differences import (
    pressure_difference_reading,
    term_difference_reading,
)
from conformance.diagnosis.transposed_blocks import transposed_blocks_reading
from conformance.diagnosis.variant_energy import variant_energy_reading
from conformance.diagnosis.voigt_maps import voigt_map_reading
from conformance.diagnosis.volumes import volume_findings
from conformance.judge.compare import DOUBLE, Scales, scales
from conformance.judge.consistency import Consistency, consistency, safe_norm
from conformance.judge.oracle import OracleCache, Reference
from conformance.judge.precision import U32
from conformance.kit.cases import KitCase, primary_and_probes, probe_lengths
from conformance.kit.exchange import CaseError, EngineOutput, FormatError
from conformance.kit.spec import CaseInput

__all__ = [
    "CaseError",
    "CaseOutcome",
    "CheckRun",
    "CaseReadings",
    "Reading",
    "READINGS",
    "run_check",
]


Evaluator = Callable[[KitCase], EngineOutput]


@dataclass(frozen=True)
class CaseOutcome:
    """status: "passed", "failed" or "bad input"; diagnosis for compared cases, message
    otherwise.
    """

    case_id: str
    model: str
    mesh: str
    state: str
    status: str
    diagnosis: Optional[Diagnosis] = None
    message: str = ""
    seconds: float = 0.0
    n_nodes: int = 0

    def to_dict(self) -> dict:
        d = {
            "case": self.case_id,
            "model": self.model,
            "mesh": self.mesh,
            "state": self.state,
            "status": self.status,
            "message": self.message,
            "seconds": self.seconds,
        }
        if self.diagnosis is not None:
            d.update(self.diagnosis.to_dict())
        return d


@dataclass
class CheckRun:
    """Every case's outcome, plus kit-level errors (unreadable cases)."""

    outcomes: List[CaseOutcome] = field(default_factory=list)
    input_errors: Dict[str, str] = field(default_factory=dict)

    @property
    def n_passed(self) -> int:
        return sum(o.status == "passed" for o in self.outcomes)

    @property
    def exit_code(self) -> int:
        """2 when some case had bad input (the others still ran), else 1 if one failed, else 0."""
        if self.input_errors or any(o.status == "bad input" for o in self.outcomes):
            return EXIT_INPUT
        if any(o.status != "passed" for o in self.outcomes) or not self.outcomes:
            return EXIT_FAILED
        return EXIT_PASSED

    def summary(self) -> str:
        bad = sum(o.status == "bad input" for o in self.outcomes) + len(self.input_errors)
        failed = sum(o.status == "failed" for o in self.outcomes)
        return (
            f"{self.n_passed}/{len(self.outcomes) + len(self.input_errors)} cases passed, {failed} "
            f"failed, {bad} with bad input"
        )

    def text(self) -> str:
        lines = [self.summary()]
        for o in self.outcomes:
            if o.diagnosis is not None:
                lines.append(o.diagnosis.text())
            else:
                lines.append(f"case {o.case_id}: BAD INPUT: {o.message}")
        lines += [f"BAD INPUT: {msg}" for msg in self.input_errors.values()]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "summary": self.summary(),
            "exit_code": self.exit_code,
            "cases": [o.to_dict() for o in self.outcomes],
            "input_errors": dict(self.input_errors),
        }


@dataclass(frozen=True)
class CaseReadings:
    """A compared case as the readings of its mistakes see it: the oracles (``cache``), the kit
    case, the engine's output and the oracle's (``ref``), the scales, the kit's cases by model
    and mesh (``kin``: the other states an output may have been computed at), where the energy
    reading keeps the case's term system for the fit over the kit; read_mistakes: a failed case
    that the first diagnosis does not explain and that is not float32 round-off within single
    precision; read_causes: False for ``--verdict-only``; probes: the case's probe cases and
    probe_results the engine's (positions (n, 3), force (n, 3), energy) at each (empty when a
    probe's output was unusable), probe_stiffness its stiffness at each (empty likewise).
    """

    cache: OracleCache
    case: KitCase
    out: EngineOutput
    ref: Reference
    s: Scales
    kin: Dict[tuple, List[KitCase]]
    keep_terms: Callable[[Any], None]
    read_mistakes: bool
    read_causes: bool
    probes: Tuple[KitCase, ...] = ()
    probe_results: Tuple[tuple, ...] = ()
    probe_stiffness: Tuple[Any, ...] = ()

    @property
    def ci(self) -> CaseInput:
        return self.case.input


@dataclass(frozen=True)
class Reading:
    """One reading of a failed case: its name, when it runs (on the diagnosis so far) and the
    call, which returns the diagnosis with what it finds (unchanged when it finds nothing).
    """

    name: str
    when: Callable[[Diagnosis, CaseReadings], bool]
    read: Callable[[Diagnosis, CaseReadings], Diagnosis]


def _mistakes_read(d: Diagnosis, c: CaseReadings) -> bool:
    return c.read_mistakes


def _nothing_named(d: Diagnosis, c: CaseReadings) -> bool:
    return c.read_mistakes and not d.causes


def _nothing_named_but_volumetric(d: Diagnosis, c: CaseReadings) -> bool:
    """Nothing named yet, or only the diagnosis's per-cell volumetric fit (which then leaves the
    mistakes unread): a piece of the split along C^-1 (x) C^-1 (P~'s, p~'s) fits it too, and the
    split reading, which fits nothing per cell, goes first when it explains.
    """
    only_volumetric = all(f.code == "volumetric" for f in d.causes)
    if c.read_mistakes:
        return only_volumetric
    return c.read_causes and bool(d.causes) and only_volumetric


def _energy_alone(d: Diagnosis, c: CaseReadings) -> bool:
    """Force and stiffness right, an energy given, and either it differs here (the plain
    "energy" finding, no other cause) or the probes found the force not its derivative.
    """
    tol, e = d.tolerances, d.errors
    if not (c.read_causes and e.force <= tol.force and e.stiffness <= tol.stiffness):
        return False
    if c.out.energy is None:
        return False
    if any(f.code != "energy" for f in d.causes):
        return False
    return any(f.code in ("energy", "inconsistent-force") for f in d.findings)


def _force_wrong(d: Diagnosis, c: CaseReadings) -> bool:
    return _nothing_named(d, c) and d.errors.force > d.tolerances.force


def _force_right(d: Diagnosis, c: CaseReadings) -> bool:
    return _nothing_named(d, c) and d.errors.force <= d.tolerances.force


def _headline_unexplained(d: Diagnosis, c: CaseReadings) -> bool:
    """The force right and no reading (not even a partial one) has taken the headline."""
    return _force_right(d, c) and bool(d.findings) and d.findings[0].code == "unexplained"


def _localised_only(d: Diagnosis, c: CaseReadings) -> bool:
    """The force right, and the only cause named is where the error is (a few cells): a place,
    not a mechanism.
    """
    return (
        c.read_causes  # a named place leaves the mistake readings off (read_mistakes)
        and d.errors.force <= d.tolerances.force
        and bool(d.causes)
        and all(f.code == "localised" for f in d.causes)
    )


def _differences_past_localisation(d: Diagnosis, c: CaseReadings) -> Diagnosis:
    """A finite-difference tangent whose error sits in a few cells (the step's error grows with
    each cell's curvature: a stiff exponential in two cells of a fibre law): the difference
    readings run as on an unexplained case; one that names its scheme leads, the localisation
    kept as an observation below it. Unchanged when none does.
    """
    located = [replace(f, strength=OBSERVED) if f.code == "localised" else f for f in d.findings]
    blank = replace(d, findings=[Finding("unexplained", "unexplained", OBSERVED, "", {}), *located])
    for read in (
        lambda x: strain_difference_reading(x, c.ci, c.out, c.ref, c.s),
        lambda x: central_difference_reading(x, c.ci, c.out, c.ref, c.s),
        lambda x: principal_difference_reading(x, c.ci, c.out, c.ref, c.s),
    ):
        out = read(blank)
        if out.findings and out.findings[0].code != "unexplained":
            return replace(out, findings=[f for f in out.findings if f.code != "unexplained"])
    return d


def _only_a_place(d: Diagnosis, c: CaseReadings) -> bool:
    """The only cause named is where the error is (a few cells), whatever the force."""
    return c.read_causes and bool(d.causes) and all(f.code == "localised" for f in d.causes)


def _graded_localisation(d: Diagnosis, c: CaseReadings) -> Diagnosis:
    """``d`` with a place demoted to an observation where its cells are the stiffest of the mesh
    (:func:`conformance.diagnosis.cells.stiffest_cells`): an error that grows steeply with the
    state (a step's truncation, an exponential rounded) sits there, and the rest of the mesh
    is at round-off; a mistake confined to some cells lands on the stiffest ones by chance
    only. Unchanged otherwise.
    """
    from conformance.diagnosis.cells import stiffest_cells
    from conformance.diagnosis.elements import element_split

    place = next(f for f in d.causes if f.code == "localised")
    located = sorted(place.figures.get("cells", []))
    if not located:
        return d
    ci, tol = c.ci, d.tolerances
    split = element_split(
        ci.model, ci.points, ci.cells, ci.positions, c.ref.force, c.ref.stiffness, c.s, tol
    )
    if split is None or sorted(stiffest_cells(split, len(located))) != located:
        return d
    said = replace(
        place,
        strength=OBSERVED,
        title=place.title + ": the stiffest cells of the mesh",
        evidence=place.evidence
        + f"; these are the {len(located)} cell(s) with the largest stiffness per volume in the "
        "oracle's element matrices: an error that grows steeply with the state (a step's "
        "truncation, an exponential rounded) sits there and leaves the rest at round-off, so "
        "this is where the error shows, not a mistake confined to these cells",
    )
    head = Finding("unexplained", "unexplained", OBSERVED, "", {})
    return replace(d, findings=[head, said, *(f for f in d.findings if f is not place)])


def _stiffness_slightly_off(d: Diagnosis, c: CaseReadings) -> bool:
    """Nothing has taken the headline, the force right and the stiffness off by less than any
    formula slip leaves (:data:`conformance.diagnosis.stiffness_noise.NOISE_RANGE`).
    """
    low, high = NOISE_RANGE
    return _headline_unexplained(d, c) and low <= d.errors.stiffness <= high


def _energy_wrong(d: Diagnosis, c: CaseReadings) -> bool:
    """An energy given that differs from the oracle's, and nothing named yet but (force and
    stiffness right) the energy routine's own formula.
    """
    if not (c.read_causes and c.out.energy is not None):
        return False
    if d.errors.energy <= d.tolerances.energy:
        return False
    generic = bool(d.causes) and all(f.code == "energy" for f in d.causes)
    return _nothing_named(d, c) or generic


def _named_force_right(d: Diagnosis, c: CaseReadings) -> bool:
    return c.read_causes and bool(d.causes) and d.errors.force <= d.tolerances.force


def _other_states(d: Diagnosis, c: CaseReadings) -> Diagnosis:
    """Computed at another state of the kit (cheap: an assembly a state)."""
    ci = c.ci
    others = [
        k
        for k in c.kin[(readings.model_key(ci.model), c.case.mesh)]
        if k.case_id != c.case.case_id and np.array_equal(k.input.points, ci.points)
    ]
    return other_state_reading(d, c.cache, ci, c.out, c.s, others)


#: The readings of a failed case's mistakes, in the order they are tried; each runs when its
#: condition holds on the diagnosis so far (most: nothing named yet). The force-right readings
#: ask first for a known approximation, then for hand-derived terms, then for differences.
READINGS: Tuple[Reading, ...] = (
    Reading(
        "the energy alone wrong, force and stiffness right (a volume weight, a factor, a "
        "constant, or the energy routine's formula)",
        _energy_alone,
        lambda d, c: energy_alone_reading(
            d, c.cache, c.ci, c.out, c.ref, c.s, c.probes, c.probe_results
        ),
    ),
    Reading("another state of the kit", _mistakes_read, _other_states),
    Reading(
        "stiffness entries where the mesh has none (indices wrong)",
        _nothing_named,
        lambda d, c: off_pattern_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "element vectors or matrices, or the per-cell tangent, in float32, assembled in double",
        _nothing_named,
        lambda d, c: rounded_elements_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "energy hypotheses (terms, variants, parameters)",
        _nothing_named,
        lambda d, c: readings.read(d, c.cache, c.ci, c.out, c.ref, c.s, keep_terms=c.keep_terms),
    ),
    Reading(
        "one part of the energy multiplied per cell by a power of J (an exponent typed wrongly "
        "in its value)",
        _nothing_named,
        lambda d, c: part_power_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "the deformation gradient formed from the edge matrices wrongly (edges as rows, the "
        "product's order)",
        _nothing_named,
        lambda d, c: edge_kinematics_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a fibre-frame strain routine's stress or tangent taken back to the axes wrongly",
        _nothing_named,
        lambda d, c: frame_routine_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "inside the element: local order, stress measure, volume, the element forces' nodes",
        _nothing_named,
        lambda d, c: element_reading(
            d, c.ci, c.out, c.ref, c.s, volume_findings, force_node_findings, definiteness_findings
        ),
    ),
    Reading(
        "shape-function gradients built wrongly",
        _nothing_named,
        lambda d, c: shape_gradient_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "shared entries written once, not summed",
        _nothing_named,
        lambda d, c: buffered_assembly_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "3x3 blocks of K stored untransposed",
        _nothing_named,
        lambda d, c: transposed_blocks_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after the named storage patterns (transposed blocks, entries not summed), which are
        # permutations too
        "the right stiffness values at the wrong entries (values out of order with indices)",
        _nothing_named,
        lambda d, c: permuted_values_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "vertex and edge blocks of K scaled apart (an edge added from both orientations, the "
        "vertex blocks twice or left out)",
        _nothing_named,
        lambda d, c: node_block_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "an edge-based engine's table of edge ids read in the other layout (pair-major as "
        "cell-major, or back)",
        _nothing_named,
        lambda d, c: edge_id_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "each cell weighted by V0 twice, or the mean volume",
        _nothing_named,
        lambda d, c: cell_weight_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "cells skipped or doubled here and there",
        _nothing_named,
        lambda d, c: spread_cells_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a hand-written stress with B where C belongs",
        _nothing_named,
        lambda d, c: b_for_c_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "one piece of Holzapfel's isochoric/volumetric split wrong (S_iso, DEV, P, P~, p~)",
        _nothing_named_but_volumetric,
        lambda d, c: split_part_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after the split: a term of d2I1b/dC2 off is a piece of P~ off there, said in
        # Holzapfel's words first
        "a user routine's packed second derivatives (UHYPER's UI2) taken wrongly by its driver, "
        "or the driver's own second derivatives of the invariants",
        _nothing_named,
        lambda d, c: routine_derivative_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # first of the force-wrong readings: one unknown (the step) accounting for 99 % of the
        # force error is stronger evidence than the pieces below, which fit a piece each
        "the stress by differences of the energy density (forward or central, in F or in E)",
        _force_wrong,
        lambda d, c: energy_difference_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "one piece of a hand-derived stress wrong (dJ/dC, dI2/dC, Voigt shear stresses, an SVD "
        "engine's dI/dsigma in its stress and plus quotient)",
        _force_wrong,
        lambda d, c: hand_derived_reading(d, c.cache, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "one of MJED's chain-rule parts of a term wrong: the force's J or C part, f'(J)",
        _force_wrong,
        lambda d, c: mjed_part_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after MJED's parts: an MJED engine's own geometric block is one of its parts; here the
        # geometric stiffness follows a wrong stress, the material tangent its own formula
        "a stress written wrongly, its tangent derived separately (a term's coefficient, a "
        "grouped term's gradient part)",
        _force_wrong,
        lambda d, c: stress_side_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a derivative dW/dI typed wrongly in a hand-written stress, the energy right (a sign, a "
        "number, an exponent, a parameter, an invariant, a power of J)",
        _force_wrong,
        lambda d, c: derivative_rewrite_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "one invariant's gradient typed wrongly in a hand-written P, the stiffness derived apart "
        "and right (in I1, I2, J or in tr C, tr C^2, J)",
        _force_wrong,
        lambda d, c: gradient_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after the rewrites and MJED's parts, which name a component's formula: here the
        # whole Voigt vector is mapped, one 6 x 6 map for every cell
        "a Voigt stress vector read through another map (order, shear factor, sign)",
        _force_wrong,
        lambda d, c: voigt_map_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a known approximation of the tangent",
        _force_right,
        lambda d, c: _approximation_reading(d, c.ci, c.out),
    ),
    Reading(
        "one invariant's curvature term wrong in the tangent",
        _force_right,
        lambda d, c: second_derivative_reading(d, c.ci, c.out, c.ref),
    ),
    Reading(
        "the curvature p (p - 1) J^(p-2) of the isochoric factor J^p written wrongly in the "
        "tangent (p^2, p, the sign, left out)",
        _force_right,
        lambda d, c: isochoric_curvature_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "one piece of a hand-derived tangent wrong, or its 1/J, or an SVD engine's divided "
        "difference of an invariant's gradient",
        _force_right,
        lambda d, c: hand_derived_reading(d, c.cache, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # the stress slip that vanishes at this state (C F for F C where F is diagonal) still
        # shows in its tangent: the same rewrites, the force right
        "a derivative dW/dI or an invariant's gradient typed wrongly in a hand-written stress, "
        "its error zero at this state but not its tangent",
        _force_right,
        lambda d, c: derivative_rewrite_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a total-Lagrangian Voigt material tangent unpacked with a slip (shear order, a shear "
        "factor, the mirror entries)",
        _force_right,
        lambda d, c: voigt_map_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "Ogden's coaxial tangent, Costa's d2Q unsymmetrised",
        _force_right,
        lambda d, c: tangent_term_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "the tangent where two principal stretches coincide (one shared error, in their plane)",
        _force_right,
        lambda d, c: coincident_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a spectral tangent with one block wrong in the principal frame of C (the principal "
        "block, its diagonal or off-diagonal, the pair terms)",
        _force_right,
        lambda d, c: principal_block_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # a material's own formula too (Teran's SVD-basis blocks); before MJED's parts and the
        # differences, which would read a wrong block as a wrong term or a step
        "one of Teran's blocks of dP/dF in the SVD basis wrong (2x2 blocks, their quotients, "
        "the 3x3 block, the definiteness fix)",
        _force_right,
        lambda d, c: svd_block_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "one of MJED's stiffness blocks of a term wrong (J-Hessian, cross, J-J, material "
        "blocks), or f'(J) of a term",
        _force_right,
        lambda d, c: mjed_part_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after the tangents' own pieces: a frozen tangent is what a template leaves behind
        "the tangent frozen at the rest state (a linear-elastic template's lam I (x) I + 2 mu II)",
        _force_right,
        lambda d, c: rest_tangent_reading(d, c.cache, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "differences of the force",
        _force_right,
        lambda d, c: _finite_difference_reading(d, c.cache, c.ci, c.out, c.ref),
    ),
    Reading(
        "differences whose error sits in a few cells (the only cause named is where it is)",
        _localised_only,
        _differences_past_localisation,
    ),
    Reading(
        "a place that is the stiffest cells of the mesh (an error graded by the state)",
        _only_a_place,
        _graded_localisation,
    ),
    Reading(
        "differences with a step per cell",
        _headline_unexplained,
        lambda d, c: element_difference_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "differences in the strain, or a perturbation of F (Miehe's, or one of another form)",
        _headline_unexplained,
        lambda d, c: strain_difference_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a complex step or central differences of S in the components of E or C (the step's "
        "truncation), or a relative step's divisor",
        _headline_unexplained,
        lambda d, c: complex_step_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "the elasticity tensor applied to each node direction by differences of the stress "
        "along it (forward or central; one triangle of a cell's blocks mirrored, or not)",
        _headline_unexplained,
        lambda d, c: directional_difference_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "central differences of P in each component of F (a first elasticity tensor)",
        _headline_unexplained,
        lambda d, c: central_difference_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a spectral engine's principal block d tau_a / d ln lambda_b by differences of the "
        "principal Kirchhoff stresses (forward or central in ln lambda, or a relative step)",
        _headline_unexplained,
        lambda d, c: principal_difference_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "an updated-Lagrangian assembly's kinematics, or its material routine handed F_bar, U, "
        "F^T or a corotated frame",
        _nothing_named,
        lambda d, c: spatial_kinematics_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a total-Lagrangian assembly's first Piola stress and first elasticity tensor",
        _nothing_named,
        lambda d, c: piola_assembly_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "a spectral engine's principal frame: the eigenvectors of b for those of C, or the "
        "eigenvalues paired with the wrong eigenvectors",
        _nothing_named,
        lambda d, c: spectral_frame_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after the total-Lagrangian assembly's own slips (P and A built from S and CC): here P
        # and A themselves are slipped (SVD factors, the 9 x 9 flattening, dP/dDs, F = Dm^-1 Ds,
        # a difference quotient's divisor, named only with the differences' noise left)
        "the first Piola stress or dP/dF with an index or operand slip",
        _nothing_named,
        lambda d, c: piola_slip_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after the slips: a difference divisor slip leaves noise too, but in every column
        "differences of P with a step relative to each entry of F (the zero entries' columns "
        "noise)",
        _force_right,
        lambda d, c: entry_step_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # one unknown per cell: after the readings that predict with nothing fitted
        "a Cauchy stress wrong by one tensor form per cell (a term not pushed forward, a "
        "coefficient kept twice), the initial-stress stiffness following it, the tangent right",
        _nothing_named,
        lambda d, c: stress_form_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        # after every reading that predicts force and stiffness together
        "one of MJED's chain-rule parts giving the force alone, the stiffness right or with a "
        "slip of its own",
        _force_wrong,
        lambda d, c: mjed_part_reading(d, c.ci, c.out, c.ref, c.s, force_alone=True),
    ),
    Reading(
        # last of the stiffness readings: noise is what no formula fits, and a formula's
        # small error must have had its chance above
        "the stiffness off by round-off alone: node blocks in float32, or differences with "
        "too small a step (noise drawn anew at every probe)",
        _stiffness_slightly_off,
        lambda d, c: stiffness_noise_reading(
            d, c.cache, c.ci, c.out, c.ref, c.s, c.probes, c.probe_stiffness
        ),
    ),
    Reading(
        "the energy computed with a mistaken frame or kinematics, the stress derived otherwise",
        _energy_wrong,
        lambda d, c: variant_energy_reading(d, c.cache, c.ci, c.out, c.probes, c.probe_results),
    ),
    Reading(
        # before the J-only stress is said as such: that stress as a difference quotient
        "the pressure U'(J) by differences of U (a J-only stress error, U'' right)",
        _nothing_named,
        lambda d, c: pressure_difference_reading(d, c.ci, c.out, c.ref, c.s),
    ),
    Reading(
        "last: the J-only stress the energy denied",
        _nothing_named,
        lambda d, c: denied_volumetric(d),
    ),
    Reading(
        "one tangent term named: wrong, or a tiny perturbation of it (differences)?",
        _named_force_right,
        lambda d, c: term_difference_reading(d, c.ci, c.out, c.ref),
    ),
)


def run_check(cases: Sequence[KitCase], evaluate: Evaluator, **options: Any) -> CheckRun:
    """:func:`_run_check` with NumPy's floating-point warnings silenced: every figure is checked
    for finiteness and a non-finite one is said in the verdict, so no raw RuntimeWarning reaches
    the terminal.
    """
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return _run_check(cases, evaluate, **options)


def _diagnose(case_id: str, ci, out, ref, s, **options):
    """:func:`conformance.diagnosis.diagnose.diagnose` of an engine's output against the oracle's at
    one case's positions; options: consistency, tol, parts, frame_variants.
    """
    return diagnose(
        case_id,
        f=out.force,
        K=out.stiffness,
        W=out.energy,
        f_o=ref.force,
        K_o=ref.stiffness,
        W_o=ref.energy,
        s=s,
        points=ci.points,
        cells=ci.cells,
        x=ci.positions,
        **options,
    )


def _run_check(
    cases: Sequence[KitCase],
    evaluate: Evaluator,
    *,
    cache: Optional[OracleCache] = None,
    input_errors: Optional[Dict[str, str]] = None,
    progress: Optional[Callable[[str], None]] = None,
    on_case: Optional[Callable[..., None]] = None,
    precision: str = "auto",
    read_causes: bool = True,
) -> CheckRun:
    """Evaluate, compare and diagnose every primary case (its probes feed the consistency test).

    read_causes: False judges only (``mjed-verify check --verdict-only``): the verdicts, the
    errors and the consistency test, without any reading of a failed case's cause (neither the
    first diagnosis' hypotheses nor the readings of mistakes, which compile and evaluate many
    variant forms). A failure then says that its cause was not looked for, not "unexplained".

    precision: "double" (tolerance 1e-10), "single" (tolerances from float32 round-off and the
    case's conditioning, :mod:`conformance.judge.precision`) or "auto": single for an output the
    engine wrote in float32, double otherwise.

    on_case(case, output, reference, diagnosis) is called for every compared case (e.g. to write
    its per-node error field).
    """
    cache = OracleCache() if cache is None else cache
    run = CheckRun(input_errors=dict(input_errors or {}))
    kept_terms: Dict[str, list] = {}  # model -> [(outcome index, labels, TermCase)]
    pairs = primary_and_probes(cases)
    # The kit's cases by model and mesh: the other states an output may have been computed at.
    kin: Dict[tuple, List[KitCase]] = {}
    for c, _ in pairs:
        kin.setdefault((readings.model_key(c.input.model), c.mesh), []).append(c)
    for case, probes in pairs:
        t0 = time.perf_counter()
        ci = case.input
        label = dict(
            case_id=case.case_id,
            model=_model_name(ci.model),
            mesh=case.mesh,
            state=case.state,
            n_nodes=ci.n_nodes,
        )
        if progress:
            progress(case.case_id)
        try:
            out = evaluate(case)
        except FormatError as exc:
            run.outcomes.append(
                CaseOutcome(
                    status="bad input", message=str(exc), seconds=time.perf_counter() - t0, **label
                )
            )
            continue
        probe_results, probe_errors, probe_stiffness = [], [], []
        for p in probes:
            try:
                po = evaluate(p)
                probe_results.append((p.input.positions, po.force, po.energy))
                probe_stiffness.append(po.stiffness)
            except FormatError as exc:
                probe_errors.append(str(exc))
        try:
            ref = cache.reference(ci)
        except (
            ValueError
        ) as exc:  # e.g. a user energy that is not finite at this state (ln of J <= 0)
            run.outcomes.append(
                CaseOutcome(
                    status="bad input",
                    message=f"case {case.case_id}: the oracle cannot evaluate this case: {exc}",
                    seconds=time.perf_counter() - t0,
                    **label,
                )
            )
            continue
        single = precision == "single" or (precision == "auto" and out.precision == "single")
        cons = (
            Consistency(None, None, note="; ".join(probe_errors))
            if probe_errors
            else _self_consistency(cache, ci, ref, out, probes, probe_results, single)
        )
        s = scales(mean_edge_length(ci.points, ci.cells), ref.energy, ref.force, ref.stiffness)
        tol = cache.single_precision(ci, ref, s) if single else DOUBLE
        diag = _diagnose(
            case.case_id,
            ci,
            out,
            ref,
            s,
            parts=_lazy(lambda: cache.parts(ci)),
            consistency=cons if probes else None,
            tol=tol,
            frame_variants=_lazy(lambda: frame_variants(ci, cache)),
            explain=read_causes,
        )
        if read_causes and diag.causes and diag.causes[0].code == "volumetric":
            diag = readings.refine_volumetric(diag, cache, ci, out, s)  # which U(J) exactly?
        if diag.causes and diag.causes[0].code == "localised":  # those cells missing, or twice?
            diag = cell_contribution_reading(diag, ci, out, ref, s)
        if read_causes and not diag.causes and probes:  # right here, the force wrong nearby
            diag = nearby_force_reading(diag, cache, ci, probe_results, s)
        # Force and stiffness wrong against the oracle, and no correction named: which energy,
        # or which tangent, is it? (A failure by the probes alone is not about the energy.)
        if tol.capped and not diag.passed:
            diag = replace(
                diag,
                findings=[
                    *diag.findings,
                    Finding(
                        "beyond-single-precision",
                        "this case is beyond what float32 resolves",
                        OBSERVED,
                        tol.basis,
                        {"capped": list(tol.capped)},
                    ),
                ],
            )
        unexplained = (
            not diag.passed
            and not diag.causes
            and not diag.tolerances.within(diag.errors, energy=False)
        )
        # A force about as inexact as float32 makes it: a float32 value carries a relative
        # error of u / sqrt(3) on average, and a float32 stress field summed in double over
        # the cells of a node leaves a few times less (corpus 12's float32 P: 0.2 u); below
        # that, a small exact-looking error is a mistake.
        nf = safe_norm(ref.force)
        inexact = nf == 0 or diag.errors.force * s.force >= U32 / 16 * nf
        # float32's own signature is read first (NumPy only): an output that is float32
        # round-off and within single precision's tolerances skips the readings of mistakes,
        # which cannot explain round-off and would have the oracle compile and evaluate many
        # variant energies for nothing.
        sig = tol32 = None
        if read_causes and not single and unexplained and inexact:
            sig = roundoff_signature(out.force, out.stiffness, ref.force, ref.stiffness)
            if sig.float32_like:
                tol32 = cache.single_precision(ci, ref, s)
        read_mistakes = (
            read_causes and unexplained and not (tol32 is not None and tol32.within(diag.errors))
        )
        if unexplained and not read_causes:
            diag = _causes_not_read(diag)
        case_readings = CaseReadings(
            cache,
            case,
            out,
            ref,
            s,
            kin,
            lambda tc, k=label["model"]: kept_terms.setdefault(k, []).append(
                (len(run.outcomes), *tc)
            ),
            read_mistakes,
            read_causes,
            tuple(probes),
            tuple(probe_results) if not probe_errors else (),
            tuple(probe_stiffness) if not probe_errors else (),
        )
        for reading in READINGS:
            if reading.when(diag, case_readings):
                diag = reading.read(diag, case_readings)
        # Last: would the output pass as a float32 engine's? Only when no mistake was named, and
        # only for an inexact force (above).
        if read_causes and not single and unexplained and not diag.causes and inexact:
            if tol32 is None:
                tol32 = cache.single_precision(ci, ref, s)
            if sig is None:
                sig = roundoff_signature(out.force, out.stiffness, ref.force, ref.stiffness)
            if tol32.within(diag.errors) and not sig.float32_like:
                # Small enough for float32 with the balance kept: float32 inside a double
                # engine (noise at the probes, the rounding's pattern), else systematic.
                diag = mixed_precision_reading(diag, cache, ci, out, ref, s, probes, probe_results)
                if not diag.causes:
                    diag = _systematic_reading(diag, sig, tol32)
            elif tol32.within(diag.errors):
                cons32 = (
                    _self_consistency(cache, ci, ref, out, probes, probe_results, True)
                    if probes and not probe_errors
                    else None
                )
                diag32 = _diagnose(
                    case.case_id,
                    ci,
                    out,
                    ref,
                    s,
                    consistency=cons32,
                    tol=tol32,
                )
                diag = _single_precision_reading(diag, diag32, sig)
        status = diag.verdict
        message = ""
        if probe_errors:
            status, message = "bad input", "probe output unusable: " + "; ".join(probe_errors)
        run.outcomes.append(
            CaseOutcome(
                status=status,
                diagnosis=diag,
                message=message,
                seconds=time.perf_counter() - t0,
                **label,
            )
        )
        if on_case is not None:
            on_case(case, out, ref, diag)
    _kit_term_fit(run, kept_terms)
    _settle_ambiguity(run)
    _corroborate(run)
    return run


def _causes_not_read(diag: Diagnosis) -> Diagnosis:
    """A failed case checked with read_causes=False: its "unexplained" headline (which would say
    that nothing fits) replaced by what was done, the quick readings' evidence kept.
    """
    if not diag.findings or diag.findings[0].code != "unexplained":
        return diag
    first = diag.findings[0]
    not_read = Finding(
        "causes-not-read",
        "cause not looked for (--verdict-only): check without it to have the cause named",
        OBSERVED,
        first.evidence,
        first.figures,
    )
    return replace(diag, findings=[not_read, *diag.findings[1:]])


def _settle_ambiguity(run: CheckRun) -> None:
    """An ambiguous case given the cause that another case of the same model and mesh names
    alone (:func:`conformance.diagnosis.disambiguate.settle_ambiguity`).
    """
    from conformance.diagnosis.disambiguate import settle_ambiguity

    _by_group(run, settle_ambiguity)


def _corroborate(run: CheckRun) -> None:
    """A cause named on one case not named where it leaves another case of the same model and
    mesh unexplained (:func:`conformance.diagnosis.corroborate.corroborate`); a case that fits it
    exactly but cannot tell it apart given it (:func:`~conformance.diagnosis.corroborate.
    extend_consistent`); a case whose causes another case's cause covers (a parameter off by
    float32's size on a state of alike cells: :func:`~conformance.diagnosis.corroborate.
    extend_covered`).
    """
    _by_group(run, corroborate)
    _by_group(run, extend_consistent)
    _by_group(run, extend_covered)


def _by_group(run: CheckRun, rule: Callable[..., list]) -> None:
    """The outcomes' diagnoses passed through ``rule(diagnoses, groups, case_ids)``, the groups
    being the cases of one model and mesh; each diagnosis it changes replaced in place.
    """
    groups: Dict[tuple, List[int]] = {}
    for i, o in enumerate(run.outcomes):
        groups.setdefault((o.model, o.mesh), []).append(i)
    changed = rule(
        [o.diagnosis for o in run.outcomes],
        list(groups.values()),
        [o.case_id for o in run.outcomes],
    )
    for i, d in enumerate(changed):
        if d is not run.outcomes[i].diagnosis:
            run.outcomes[i] = replace(run.outcomes[i], diagnosis=d)


def _kit_term_fit(run: CheckRun, kept: Dict[str, list]) -> None:
    """The term fit over all failed cases of one model in the kit: where a case alone could not
    tell its terms apart (or nothing explained it), and the fit over the kit agrees on every one
    of them, its reading is given to each (:func:`conformance.diagnosis.readings.kit_term_reading`).
    """
    for entries in kept.values():
        if len(entries) < 2:
            continue
        idx = [i for i, *_ in entries]
        found = readings.kit_term_reading(
            [o.diagnosis for o in (run.outcomes[i] for i in idx)], entries
        )
        if found is None:
            continue
        for i, diag in zip(idx, found):
            run.outcomes[i] = replace(run.outcomes[i], diagnosis=diag)


def _approximation_reading(diag: Diagnosis, ci, out: EngineOutput) -> Diagnosis:
    """The force is right and nothing explains the stiffness: is it a known, published
    approximation of the tangent (:mod:`conformance.diagnosis.approximations`)?
    """
    from conformance.diagnosis.approximations import match_approximation

    match = match_approximation(
        ci.model, ci.points, ci.cells, ci.positions, out.stiffness, diag.tolerances.stiffness
    )
    if match is None:
        return diag
    finding = Finding(
        "tangent-approximation",
        f"your engine's tangent is a known approximation: {match.words}",
        FULL,
        f"K equals that approximation to {match.error:.1e} (tolerance "
        f"{diag.tolerances.stiffness:.0e}); the force matches; against the exact Hessian the "
        f"stiffness error is {diag.errors.stiffness:.1e}, so Newton's method converges linearly "
        "instead of quadratically",
        {"option": match.option, "error": match.error},
    )
    return replace(diag, findings=[finding, *(f for f in diag.findings if f.code != "unexplained")])


#: Largest mesh (nodes) on which a finite-difference tangent is looked for: 3n oracle assemblies.
FD_MAX_NODES = 400


def _finite_difference_reading(
    diag: Diagnosis, cache: OracleCache, ci, out: EngineOutput, ref
) -> Diagnosis:
    """The force is right and nothing explains the stiffness: is it differences of the force?
    The scheme (forward, backward, central), the step rule (absolute, relative) and the step are
    fitted (:func:`conformance.diagnosis.tangent.fit_finite_difference`) and named when they
    account for nearly all of the error (99 %).
    """
    from conformance.diagnosis.tangent import fit_finite_difference

    if ci.n_nodes > FD_MAX_NODES:
        return diag
    step = 1e-3 * np.repeat(probe_lengths(ci.points, ci.cells), 3)
    G1, G2 = cache.column_derivatives(ci, step)
    D = (out.stiffness - ref.stiffness).tocsr()
    fit = fit_finite_difference(D, G1, G2, ref.stiffness, ci.positions)
    if fit is None or fit.explained < 0.99:
        return diag
    finding = Finding(
        "finite-difference",
        f"a finite-difference tangent: {fit.words()}",
        PARTIAL,
        f"K - K_oracle is the leading error of that scheme (the derivative of each column of K "
        f"along its own dof, times the step), fitted with one unknown: it accounts for "
        f"{100 * fit.explained:.2f} % of the stiffness error (left: {fit.residual:.1e}, the "
        "higher orders and round-off of the differences); the force matches",
        {
            "step": fit.step,
            "scheme": fit.scheme,
            "rule": fit.rule,
            "symmetrised": fit.symmetrised,
            "explained": fit.explained,
            "residual": fit.residual,
        },
    )
    return replace(diag, findings=[finding, *(f for f in diag.findings if f.code != "unexplained")])


def _systematic_reading(diag: Diagnosis, sig, tol32) -> Diagnosis:
    """The errors are as small as float32's, but they keep the balance laws: a systematic
    mistake, said so (never float32 round-off); the other findings stand.
    """
    finding = Finding(
        "systematic-small",
        "a small systematic error, not float32 round-off",
        OBSERVED,
        f"force {diag.errors.force:.1e}, stiffness {diag.errors.stiffness:.1e} are below what "
        f"float32 leaves on this case ({tol32.text()}), but {sig.text()}",
        sig.to_dict(),
    )
    return replace(diag, findings=[*diag.findings, finding])


def _single_precision_reading(diag: Diagnosis, diag32: Diagnosis, sig=None) -> Diagnosis:
    """A case failed at double precision and ``diag32``, the same case judged as a float32
    engine's, passes: the failure is named as float32 round-off, first, with what the probes
    show at that precision; the double-precision verdict stands.
    """
    if not diag32.passed:
        return diag
    e, tol = diag.errors, diag32.tolerances
    finding = Finding(
        "single-precision",
        "the errors are single-precision (float32) round-off",
        FULL,
        f"force {e.force:.1e}, stiffness {e.stiffness:.1e} are within what float32 leaves on this "
        f"case ({tol.text()}; {tol.basis}), and "
        + ("they look like float32's" if sig is None else sig.text())
        + ": an engine computing in float32 passes with --precision single "
        '(or "precision": "single" in the kit, or .f32 output files)',
        {
            "single_force_tol": tol.force,
            "single_stiffness_tol": tol.stiffness,
            **({} if sig is None else sig.to_dict()),
        },
    )
    return replace(diag, findings=[finding, *diag32.findings], consistency=diag32.consistency)


def _self_consistency(
    cache: OracleCache,
    ci,
    ref,
    out: EngineOutput,
    probes: Sequence[KitCase],
    probe_results: list,
    single: bool,
) -> Consistency:
    """The engine's Taylor test, calibrated by the oracle at the same probes (its floor on this
    case); uncalibrated, and said so, when the oracle cannot evaluate a probe.
    """
    try:
        reference = cache.probes(ci, ref, [p.input for p in probes]) if probes else None
    except ValueError as exc:
        c = consistency(ci.positions, out.force, out.stiffness, out.energy, probe_results)
        return replace(
            c,
            note=(c.note + "; " if c.note else "") + f"not calibrated: the oracle cannot evaluate "
            f"a probe ({exc})",
        )
    return consistency(
        ci.positions,
        out.force,
        out.stiffness,
        out.energy,
        probe_results,
        reference,
        roundoff=U32 if single else 2.0**-53,
    )


def _lazy(make: Callable[[], Any]) -> Callable[[], Any]:
    """Build once on first call (the stiffness parts compile UFL forms: only when a case fails)."""
    box: List[Any] = []

    def get():
        if not box:
            box.append(make())
        return box[0]

    return get


def _model_name(model: Any) -> str:
    from conformance.kit.spec import model_label

    return model_label(model)
