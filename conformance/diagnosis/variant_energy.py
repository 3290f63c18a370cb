"""The engine's energy is a mistaken variant's, its force not: the energy routine has the
mistake, the stress routine another derivation.

An engine's energy and stress are often separate routines. When the kinematic or frame mistake
sits in a helper that both call (a strain rotated into the fibre frame twice, the strain of
the isochoric C_bar for Green's) but the stress is differentiated by hand for the right
kinematics (rotated back once, no chain rule through J^(-2/3)), the force matches no variant
while the energy matches one exactly. The energy is one number per state, so a match is
required at the case and at every probe of the kit (each a different state), within the energy
tolerance: chance agreement at five states to 1e-10 is not a risk worth naming.

The variants are those of :mod:`conformance.diagnosis.frames` (the oracle with each mistaken
frame), :mod:`conformance.diagnosis.kinematics` (the oracle of each kinematic variant) and
:mod:`conformance.diagnosis.variants` (each rewritten formula: an invariant typed wrongly in a
routine both the energy and the stress call), compiled once per mesh and variant and usually
already compiled by the readings of the force.
Named fully when force and stiffness are right (the energy routine alone has it), partly
otherwise.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Callable, Iterator, Sequence, Tuple

import numpy as np

from conformance.diagnosis.findings import FULL, PARTIAL, Finding
from conformance.kit.spec import CaseInput

__all__ = ["variant_energies", "variant_energy_reading"]

#: (code, the mistake in words, energy of the variant at positions (n, 3))
Candidate = Tuple[str, str, Callable[[np.ndarray], float]]


def variant_energies(ci: CaseInput, cache: Any) -> Iterator[Candidate]:
    """The frame variants of the case's model, then its kinematic variants, then its rewritten
    formulas (:mod:`conformance.diagnosis.variants`), each with its energy as a function of the
    positions (the oracle, built when first asked).
    """
    from conformance.diagnosis.frames import frame_models
    from conformance.diagnosis.kinematics import kinematic_variants
    from conformance.diagnosis.readings import model_key
    from conformance.diagnosis.variants import variants

    for code, title, model in frame_models(ci.model, ci.cells, ci.points):
        yield (
            code,
            title,
            lambda x, model=model: float(
                cache.reference(replace(ci, positions=x, model=model)).energy
            ),
        )
    base = model_key(ci.model)
    for v in kinematic_variants(ci.model):
        yield (
            f"kinematic-{v.code}",
            v.title,
            lambda x, v=v: float(
                cache.evaluate_model(
                    replace(ci, positions=x), v.oracle_model(ci.model), base + v.key(), lazy=True
                ).energy
            ),
        )
    for w in variants(ci.model):
        yield (
            f"formula-{w.rewrite.code}",
            f"formula W' = {w.expression} ({w.rewrite.words})",
            lambda x, w=w: float(
                cache.reference(replace(ci, positions=x, model=w.model), lazy=True).energy
            ),
        )


def variant_energy_reading(
    diag, cache, ci: CaseInput, out, probes: Sequence[Any], probe_results: Sequence[tuple]
):
    """``diag`` (the energy wrong, nothing named but the energy routine's formula) with the
    variant whose energy is the engine's at the case and at every probe named first;
    unchanged when none is, or the kit has no probes. probes: the case's probe KitCases;
    probe_results: the engine's (positions, force, energy) at each.
    """
    W = out.energy
    energies = [r[2] for r in probe_results]
    if W is None or not probes or len(energies) != len(probes) or None in energies:
        return diag
    tol = diag.tolerances.energy

    def close(a: float, b: float) -> bool:
        return bool(np.isfinite(b) and abs(a - b) <= tol * max(abs(a), abs(b), 1e-300))

    states = [(ci.positions, float(W))] + [
        (p.input.positions, float(e)) for p, e in zip(probes, energies)
    ]
    for code, title, energy_at in variant_energies(ci, cache):
        try:
            if not all(close(e, energy_at(x)) for x, e in states):
                continue
        except ValueError:  # the variant cannot be evaluated at a state (J <= 0 in a log)
            continue
        right = diag.tolerances.within(diag.errors, energy=False)
        found = Finding(
            "variant-energy",
            f"your energy is that of this mistake: {title}"
            + (
                "; your force and stiffness are right: the energy routine alone has it"
                if right
                else "; your force is not its derivative (the stress routine derives another "
                "energy, or this one wrongly)"
            ),
            FULL if right else PARTIAL,
            f"the oracle of that variant gives your energy to {tol:.0e} at this state and at "
            f"each of the {len(probes)} probes near it (the kit's energy: "
            f"{diag.errors.energy:.1e} off here)"
            + ("" if right else ", while your force is not that variant's"),
            {"variant": code, "states": len(states)},
        )
        rest = [f for f in diag.findings if f.code not in ("unexplained", "energy")]
        return replace(diag, findings=[found, *rest])
    return diag
