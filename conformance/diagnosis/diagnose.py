"""The diagnosis of one case: verdict, relative errors, and the mistake that explains a failure.

Order of the tests (each named cause must bring force and stiffness within tolerance of the
oracle once corrected; otherwise it is reported as partly explaining, with the residual):

1. conventions: sign of force and/or stiffness; component-major dof order; node offsets and
   permutations; 3x3 blocks of K transposed; an unsymmetric K whose symmetric part is right;
2. a global factor (fitted; 2, 1/2, 6, the rest volume named); lengths in other units (force
   and stiffness scaled by s^2 and s of one length factor s, :mod:`conformance.diagnosis.units`);
   then, for a model with a fibre frame, the frame mistakes: the oracle with the identity, the
   transposed or a single frame, or the columns in another order
   (:mod:`conformance.diagnosis.frames`);
3. the part of the tangent (geometric / material, volumetric / isochoric, Voigt blocks) that
   explains a stiffness error when the force is right (:mod:`conformance.diagnosis.tangent`);
4. a different volumetric (J-only) energy, fitted per cell;
5. localisation: the error confined to a few nodes (and the cells they span).

The engine's own consistency (probes, :mod:`conformance.judge.consistency`) is reported as an
observed fact. When nothing explains the error the diagnosis says so.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any, Callable, List, Optional, Sequence

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.findings import FULL, OBSERVED, PARTIAL, Finding
from conformance.diagnosis.hypotheses import (
    common_factor_name,
    convention_corrections,
    scale_corrections,
)
from conformance.diagnosis.j_functions import (
    J_ONLY,
    j_function_line,
    j_function_residual,
    j_function_steps,
)
from conformance.diagnosis.roundoff import energy_precision
from conformance.diagnosis.units import (
    FORCE_POWER,
    STIFFNESS_POWER,
    fit_derivative_scale,
    fit_length_scale,
)
from conformance.diagnosis.volumes import uniform_volume_words
from conformance.judge.compare import DOUBLE, Errors, Scales, Tolerances, errors
from conformance.judge.consistency import FLOOR_FACTOR, PROBE_TOL, RESOLUTION, Consistency

__all__ = ["Diagnosis", "diagnose", "denied_volumetric", "node_error_field"]

SIGN_CODES = ("force-sign", "stiffness-sign", "both-signs")

#: "both-signs" where the engine's energy is negated too.
ENERGY_NEGATED = (
    "energy, force and stiffness all negated: the energy's own sign, e.g. each cell's volume or "
    "quadrature weight negative (the determinant of the reference map negative: the reference "
    "element's nodes in another order than the mesh's), or W written with its sign flipped"
)

#: scale correction code -> (power on the force, on the stiffness) of its factor.
_SCALE_POWERS = {"scale": (1, 1), "scale-stiffness": (0, 1), "scale-force": (1, 0)}


@dataclass(frozen=True)
class Diagnosis:
    """case_id, verdict ("passed" / "failed"), errors, findings (named causes first), and
    node_error: (n,) per-node relative error (force and stiffness rows), for ParaView.
    """

    case_id: str
    verdict: str
    errors: Errors
    findings: Sequence[Finding]
    node_error: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    consistency: Optional[Consistency] = None
    tolerances: Tolerances = DOUBLE

    @property
    def passed(self) -> bool:
        return self.verdict == "passed"

    @property
    def causes(self) -> List[Finding]:
        return [f for f in self.findings if f.strength == FULL]

    def text(self) -> str:
        e = self.errors
        energy = "not given" if e.energy is None else f"{e.energy:.2e}"
        at = " at single precision" if self.tolerances.precision == "single" else ""
        lines = [
            f"case {self.case_id}: {self.verdict.upper()}{at} (relative errors: "
            f"force {e.force:.2e}, "
            f"stiffness {e.stiffness:.2e}, energy {energy}; {self.tolerances.text()})"
        ]
        lines += [f"  - {f.text()}" for f in self.findings]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "case": self.case_id,
            "verdict": self.verdict,
            "errors": self.errors.to_dict(),
            "findings": [f.to_dict() for f in self.findings],
            "consistency": None if self.consistency is None else self.consistency.to_dict(),
            "tolerances": self.tolerances.to_dict(),
        }


def node_error_field(
    f: np.ndarray, K: sp.csr_matrix, f_o: np.ndarray, K_o: sp.csr_matrix, s: Scales
) -> np.ndarray:
    """(n,) per-node error: sqrt(|f_a - f_o,a|^2 / s_f^2 + ||rows of node a of K - K_o||^2 /
    s_K^2).
    """
    # Divided before squaring: forces of 1e160 (an exponential energy on a sliver) stay finite.
    df = (f - f_o) / s.force if s.force > 0 else f - f_o
    df2 = np.sum(df**2, axis=1)
    D = sp.csr_matrix(K - K_o) / (s.stiffness if s.stiffness > 0 else 1.0)
    dk2 = np.asarray(D.multiply(D).sum(axis=1)).ravel().reshape(-1, 3).sum(axis=1)
    return np.sqrt(df2 + dk2)


def _within(e: Errors, tol: Tolerances) -> bool:
    return tol.within(e, energy=False)


def _evidence(e: Errors) -> str:
    return f"after the correction: force error {e.force:.1e}, stiffness error {e.stiffness:.1e}"


def diagnose(
    case_id: str,
    *,
    f: np.ndarray,
    K: sp.spmatrix,
    W: Optional[float],
    f_o: np.ndarray,
    K_o: sp.spmatrix,
    W_o: float,
    s: Scales,
    points: np.ndarray,
    cells: np.ndarray,
    x: np.ndarray,
    parts: Optional[Callable[[], Any]] = None,
    consistency: Optional[Consistency] = None,
    tol: Tolerances = DOUBLE,
    frame_variants: Optional[Callable[[], Sequence[Any]]] = None,
    explain: bool = True,
) -> Diagnosis:
    """Diagnose one case.

    Args:
        f, K, W: the engine's force (n, 3), stiffness (3n, 3n), energy or None.
        f_o, K_o, W_o: the oracle's; s: the error scales (:func:`conformance.judge.compare.scales`).
        points, cells, x: the mesh and the current positions.
        parts: a callable returning the oracle's stiffness parts (built only if needed).
        consistency: the probes' result, if any.
        tol: the tolerances the case is held to (double precision by default).
        frame_variants: a callable returning the oracle with mistaken frames
            (:class:`conformance.diagnosis.frames.FrameVariant`; built only if needed).
        explain: False judges only: the errors, the verdict and the consistency findings, and
            a failure left "unexplained" without any hypothesis tried (``--verdict-only``).
    """
    K = sp.csr_matrix(K)
    K_o = sp.csr_matrix(K_o)
    err = errors(f, K, W, f_o, K_o, W_o, s)
    field_ = node_error_field(f, K, f_o, K_o, s)
    findings: List[Finding] = []
    if consistency is not None:
        findings += _consistency_findings(consistency)
    inconsistent = any(
        x_.code.startswith("inconsistent") or x_.code == "consistency-not-measured"
        for x_ in findings
    )
    if tol.within(err) and not inconsistent:
        return Diagnosis(case_id, "passed", err, findings, field_, consistency, tol)
    if _within(err, tol):  # force and stiffness right: only the energy (or the consistency) is off
        if err.energy is not None and err.energy > tol.energy:
            findings.insert(0, _energy_finding(W, W_o, err, _rest_volumes(points, cells).sum()))
        if inconsistent and consistency is not None and consistency.stiffness_consistent is False:
            findings.insert(
                0,
                Finding(
                    "force-wrong-nearby",
                    "the force is wrong away from this state",
                    OBSERVED,
                    "force and stiffness match the oracle here, but the stiffness is not the "
                    "derivative of the engine's own force at the probes: the force changes wrongly "
                    "as the mesh deforms (check a deformed state, where the diagnosis can name the "
                    "mistake)",
                    {},
                ),
            )
        return Diagnosis(case_id, "failed", err, findings, field_, consistency, tol)

    # The engine's own energy denies an energy mistake: it equals the oracle's, or the engine's
    # force is not its derivative (the probes). A reading of the energy must then not be named.
    energy_right = W is not None and err.energy is not None and err.energy <= tol.energy
    energy_denies = energy_right or (
        consistency is not None and consistency.force_consistent is False
    )
    args = (f, K, W, f_o, K_o, W_o, s, err, points, cells, x, parts, field_, tol, frame_variants)
    causes, partial = _explain(*args, energy_denies=energy_denies) if explain else ([], [])
    if causes:
        findings = causes + findings
    else:
        best = sorted(partial, key=lambda p: p.figures.get("residual", np.inf))[:2]
        unexplained = Finding(
            "unexplained",
            "unexplained",
            PARTIAL if best else OBSERVED,
            "no tested hypothesis (signs, dof order, node offsets and permutations, transposed or "
            "unsymmetric K, global factor, length units, fibre frame where the model has one, "
            "tangent parts, volumetric energy, localisation) brings the error within tolerance"
            + ("; closest: " + "; ".join(p.text() for p in best) if best else "")
            + _where_to_look(err, tol, consistency, inconsistent, energy_right),
            {
                "force": err.force,
                "stiffness": err.stiffness,
                # the causes that fit this case exactly but that it cannot tell from others
                "fits_codes": sorted({c for p in partial for c in p.figures.get("fits_codes", ())}),
            },
        )
        denied = [p for p in partial if p.figures.get("denied")]
        findings = [unexplained, *denied] + findings
    return Diagnosis(case_id, "failed", err, findings, field_, consistency, tol)


def _where_to_look(err, tol, consistency, inconsistent: bool, energy_right: bool) -> str:
    """Where to look when nothing is named but the engine's own figures localise the mistake
    (the probes' ``consistency``; ``inconsistent``: they found something inconsistent):

    - the force right and the stiffness not its derivative: the tangent alone;
    - the energy the oracle's, the force not its derivative and the stiffness the derivative of
      the force: the force departs from the derivative of a right energy and the stiffness was
      derived from that force (or from the same stress): the stress formula.

    Empty where neither is measured and holds.
    """
    if inconsistent and err.force <= tol.force:
        return (
            "; the force is right and the stiffness is not the derivative of the engine's own "
            "force (below): the mistake is in the tangent alone"
        )
    if not (energy_right and err.force > tol.force and consistency is not None):
        return ""
    if consistency.stiffness_consistent is not True or consistency.force_consistent is not False:
        return ""
    return (
        "; your energy is the oracle's, your force is not its derivative and your stiffness is "
        "the derivative of your force (below): the mistake is in the force's stress formula, "
        "which the stiffness inherits"
    )


def denied_volumetric(diag: Diagnosis) -> Diagnosis:
    """``diag`` (nothing named after every reading) with the volumetric reading that the
    engine's energy denied (its force and stiffness are exactly a J-only change's, its energy
    is not) named as a difference of the volumetric stress and tangent; unchanged otherwise.
    """
    if diag.causes:
        return diag
    held = [f for f in diag.findings if f.code == "volumetric" and f.figures.get("denied")]
    if not held:
        return diag
    cause = replace(held[0], strength=FULL)
    rest = [f for f in diag.findings if f.code != "unexplained" and f is not held[0]]
    return replace(diag, findings=[cause, *rest])


def _rest_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(m,) rest cell volumes [m^3]."""
    return (
        np.abs(np.linalg.det(np.swapaxes(points[cells][:, 1:] - points[cells][:, :1], 1, 2))) / 6.0
    )


def _energy_finding(W, W_o, err: Errors, volume: float) -> Finding:
    ratio = W / W_o if W_o else float("nan")
    words = (
        "sign flipped"
        if abs(ratio + 1) < 1e-9
        else (f"engine/oracle ratio {ratio:.6g}" if W_o else "")
    )
    # Force and stiffness agree, so a difference that is a constant density (e.g. W without its '-
    # 3')
    # is the likely reading: say what density it would be, as a figure, not as a claim.
    offset = (W - W_o) / volume
    p = energy_precision(W, W_o)
    if p.float32:
        # The energy alone off by float32's rounding, and itself a float32 number: a float32
        # energy (or sum), not a formula (a double result is a float32 number with odds 2^-29).
        return Finding(
            "energy-float32",
            "the energy is computed in single precision (float32): its error is float32's rounding",
            FULL,
            f"force and stiffness match; energy {W:.9e} J against {W_o:.9e} J: relative error "
            f"{p.relative:.1e} = {p.in_units:.2g} float32 unit round-offs, and the engine's "
            "energy is exactly a float32 number (a double result is one with odds 2^-29)",
            {"energy": W, "oracle_energy": W_o, **asdict(p)},
        )
    size = (
        f"; the error is of float32 rounding's size ({p.in_units:.2g} float32 unit round-offs) "
        "but the value is not a float32 number: a float32 intermediate, or a small mistake in the "
        "energy alone"
        if p.float32_size
        else ""
    )
    return Finding(
        "energy",
        "energy differs while force and stiffness match",
        FULL,
        f"energy {W:.6e} J against {W_o:.6e} J (relative error "
        f"{err.energy:.1e}){'; ' + words if words else ''}; as a constant density over the rest "
        f"volume: {offset:.6g} Pa{size}",
        {"energy": W, "oracle_energy": W_o, "offset_density": offset},
    )


def _consistency_findings(c: Consistency) -> List[Finding]:
    """What the probes show, each figure with the limit it was held to on this case."""
    out = []
    if c.non_finite:
        out.append(
            Finding(
                "consistency-not-measured",
                "the engine's self-consistency could not be measured",
                OBSERVED,
                c.note + "; the case cannot pass on figures that are not finite",
                {},
            )
        )
    if c.force_stiffness is not None:
        rates = ", ".join("-" if not np.isfinite(r) else f"{r:.2f}" for r in c.rates_force)
        if c.stiffness_excess is not None:
            calib = (
                f"the oracle's exact tangent leaves {c.stiffness_floor:.1e} on the same probes, so "
                "the part "
                f"not explained by the fit is {c.stiffness_excess:.1e} (limit "
                f"{c.stiffness_limit:.1e} = "
                f"max({PROBE_TOL:g}, {FLOOR_FACTOR:g} x that floor))"
            )
        else:
            calib = f"not calibrated by the oracle (limit {c.stiffness_limit:.1e})"
        figures = {
            "inconsistency": c.force_stiffness,
            "floor": c.stiffness_floor,
            "excess": c.stiffness_excess,
            "limit": c.stiffness_limit,
        }
        if c.stiffness_consistent is False:
            out.append(
                Finding(
                    "inconsistent-stiffness",
                    "stiffness is not the derivative of the engine's own force",
                    OBSERVED,
                    f"||df/dx d + K d|| / ||K d|| = {c.force_stiffness:.1e} along a random "
                    f"direction; {calib}; Taylor rates {rates} (2 when consistent)",
                    {**figures, "rates": [_finite_or_none(r) for r in c.rates_force]},
                )
            )
        elif c.stiffness_limit > RESOLUTION:
            out.append(
                Finding(
                    "consistency-unresolved",
                    "the probes do not resolve the tangent on this case",
                    OBSERVED,
                    f"round-off and the fit leave {c.stiffness_floor:.1e} of K d over the "
                    f"probes' step (limit {c.stiffness_limit:.1e} would be above {RESOLUTION:g}): "
                    "no "
                    "verdict on the engine's own consistency",
                    figures,
                )
            )
        elif c.stiffness_consistent is True:
            out.append(
                Finding(
                    "consistent-stiffness",
                    "stiffness is the derivative of the engine's own force",
                    OBSERVED,
                    f"relative inconsistency {c.force_stiffness:.1e}; {calib}; Taylor rates "
                    f"{rates}",
                    figures,
                )
            )
    if c.energy_force is not None and c.force_consistent is None:
        out.append(
            Finding(
                "energy-consistency-unresolved",
                "the probes do not resolve the force against the energy",
                OBSERVED,
                f"round-off of the energies leaves {c.energy_floor or 0.0:.1e} of the energy "
                "change "
                f"over the probes' step (limit {c.energy_limit:.1e}): no verdict on whether the "
                "force is minus the derivative of the engine's energy",
                {"floor": c.energy_floor, "limit": c.energy_limit},
            )
        )
    if c.force_consistent is False:
        calib = (
            ""
            if c.energy_excess is None
            else f"; beyond the oracle's {c.energy_floor:.1e} on the same probes: "
            f"{c.energy_excess:.1e}"
        )
        out.append(
            Finding(
                "inconsistent-force",
                "force is not minus the derivative of the engine's own energy",
                OBSERVED,
                f"relative inconsistency {c.energy_force:.1e}{calib} (limit "
                f"{c.energy_limit:.1e}); Taylor rates "
                + ", ".join("-" if not np.isfinite(r) else f"{r:.2f}" for r in c.rates_energy),
                {
                    "inconsistency": c.energy_force,
                    "excess": c.energy_excess,
                    "limit": c.energy_limit,
                },
            )
        )
    return out


def _finite_or_none(v: float) -> Optional[float]:
    return float(v) if np.isfinite(v) else None


def _explain(
    f,
    K,
    W,
    f_o,
    K_o,
    W_o,
    s,
    err,
    points,
    cells,
    x,
    parts,
    field_,
    tol: Tolerances,
    frame_variants=None,
    energy_denies: bool = False,
):
    """(causes that fully explain, partial explanations); energy_denies: the engine's energy
    contradicts an energy mistake (it is the oracle's, or the force is not its derivative).
    """
    full: List[Finding] = []
    partial: List[Finding] = []
    worst = max(err.force, err.stiffness)

    def judge(
        code: str,
        title: str,
        corrected_errors: Errors,
        extra: str = "",
        figures: Optional[dict] = None,
    ):
        figs = {
            "force_after": corrected_errors.force,
            "stiffness_after": corrected_errors.stiffness,
            "residual": max(corrected_errors.force, corrected_errors.stiffness),
            **(figures or {}),
        }
        text = _evidence(corrected_errors) + (f"; {extra}" if extra else "")
        if _within(corrected_errors, tol):
            full.append(Finding(code, title, FULL, text, figs))
        elif figs["residual"] < 0.1 * worst:
            partial.append(
                Finding(code, title, PARTIAL, text + " (residual above tolerance)", figs)
            )

    # The energy negated too: the whole energy's sign, not the stress's alone.
    energy_negated = (
        W is not None
        and W_o is not None
        and abs(W_o) > tol.energy * s.energy
        and abs(W + W_o) <= tol.energy * s.energy
    )
    for c in convention_corrections(f_o, K_o, f, K):
        out = c.apply(f, K, W)
        if out is not None:
            e = errors(*out[:2], None, f_o, K_o, W_o, s)
            extra = ""
            if c.code == "both-signs" and energy_negated:
                judge(c.code, ENERGY_NEGATED, e, "your energy is the oracle's negated as well")
                continue
            if c.code == "unsymmetric":
                from scipy.sparse.linalg import norm as sparse_norm

                skew = float(sparse_norm(K - K.T)) / 2 / max(float(sparse_norm(K)), 1e-300)
                extra = (
                    f"antisymmetric part ||K - K^T||/2 = {skew:.1e} of ||K||; symmetric part "
                    "matches"
                )
                if err.symmetry <= 1e-12:
                    continue  # a symmetric K: the correction is the identity
            judge(c.code, c.title, e, extra)
    if full:
        return full, partial
    # Two convention mistakes at once: a sign flip on top of a reordering (each pair is one more
    # correction, named only if together they bring the error within tolerance).
    signs = [c for c in convention_corrections(f_o, K_o, f, K) if c.code in SIGN_CODES]
    for sign in signs:
        f1, K1, W1 = sign.apply(f, K, W)
        for c in convention_corrections(f_o, K_o, f1, K1):
            if c.code in SIGN_CODES or c.code == "unsymmetric":
                continue
            out = c.apply(f1, K1, W1)
            judge(
                f"{c.code}+{sign.code}",
                f"{c.title}, and {sign.title}",
                errors(*out[:2], None, f_o, K_o, W_o, s),
            )
    if full:
        return full, partial

    V0 = _rest_volumes(points, cells)
    uniform = bool(np.ptp(V0) <= 1e-9 * V0.mean())
    J = None
    for code, which, ratio, out in scale_corrections(f_o, K_o, f, K, W_o, W):
        e = errors(*out[:2], None, f_o, K_o, W_o, s)
        name = common_factor_name(ratio, float(V0.mean()), uniform)
        if J is None:
            from conformance.diagnosis.elements import cell_kinematics

            J = np.linalg.det(cell_kinematics(points, cells, x)[2])
        # A factor that is the J of every cell is the volume confused, not a constant.
        name = uniform_volume_words(*_SCALE_POWERS[code], ratio, J) or name
        judge(
            code, f"{which} scaled: {name}", e, f"engine / oracle = {ratio:.6g}", {"ratio": ratio}
        )
        if full:
            return full, partial
    unit = fit_length_scale(f_o, K_o, f, K)
    if unit is not None:
        judge(
            "length-units",
            unit.words(),
            errors(unit.force, unit.stiffness, None, f_o, K_o, W_o, s),
            f"force / s^{FORCE_POWER}, stiffness / s^{STIFFNESS_POWER} with s = {unit.s:.9g}, "
            "the powers of a length in a P1 element's force (V0 P D) and stiffness (V0 D A D)",
            {"s": unit.s, "force_ratio": unit.force_ratio, "stiffness_ratio": unit.stiffness_ratio},
        )
        if full:
            return full, partial
    # Derivatives per another unit leave the energy as it is: a wrong energy denies them.
    per_unit = fit_derivative_scale(f_o, K_o, f, K)
    if per_unit is not None and (err.energy is None or err.energy <= tol.energy):
        judge(
            "derivative-units",
            per_unit.words(),
            errors(per_unit.force, per_unit.stiffness, None, f_o, K_o, W_o, s),
            f"force / t, stiffness / t^2 with t = {per_unit.t:.9g}"
            + ("" if err.energy is None else "; your energy is the oracle's"),
            {"t": per_unit.t},
        )
        if full:
            return full, partial

    if frame_variants is not None:
        _frame_findings(f, K, W_o, frame_variants(), judge)
        if full:
            return full, partial

    # A localised error cannot be a global convention or a part of the tangent everywhere: test it
    # first (it is cheap; the fits below are not on large meshes).
    _locality_findings(f, K, f_o, K_o, s, cells, field_, tol, full, partial)
    if full:
        return full, partial

    if parts is not None and err.force <= tol.force:
        _tangent_findings(K, K_o, parts(), err, tol, full, partial, (points, cells, x))
        if full:
            return full, partial

    if parts is not None:
        p = parts()
        if p["geometric_volumetric"] is not None:
            _volumetric_findings(
                points,
                cells,
                x,
                f - f_o,
                (K - K_o).tocsr(),
                s,
                worst,
                tol,
                full,
                partial,
                energy_denies,
            )
            if full:
                return full, partial

    return full, partial


def _frame_findings(
    f: np.ndarray, K: sp.csr_matrix, W_o: float, variants: Sequence[Any], judge: Callable[..., None]
) -> None:
    """The engine against the oracle evaluated with each mistaken frame: a frame mistake is named
    when the engine agrees with that variant (the error lives inside the energy, so it cannot be
    undone on the output).
    """
    for v in variants:
        e = errors(f, K, None, v.force, v.stiffness, W_o, v.scales)
        judge(v.code, v.title, e, "errors measured against the oracle evaluated with that frame")


def _tangent_findings(
    K, K_o, parts, err: Errors, tol: Tolerances, full, partial, mesh=None
) -> None:
    """The tangent parts that explain K - K_o; mesh: (points, cells, x), to recognise a material
    stiffness scaled by the state's J (a spatial tangent pushed forward without its 1/J).
    """
    from conformance.diagnosis.spatial_tangent import spatial_factor_words
    from conformance.diagnosis.tangent import candidate_parts, describe_coefficient, fit_parts

    D = (K - K_o).tocsr()
    cands = candidate_parts(parts, K_o)
    ok, best = fit_parts(D, K_o, cands, tol.stiffness)
    if ok is not None and ok.residual > EXPLAINED_SHARE * err.stiffness:
        # Within the tolerance but most of the error left: an error just above the tolerance
        # (a step's truncation, 1e-10) is brought under it by any part that leans its way.
        ok = None
    fit = ok or best
    if fit is None:
        return
    words = " and ".join(describe_coefficient(n, c) for n, c in zip(fit.names, fit.coefficients))
    figs = {
        "parts": list(fit.names),
        "coefficients": list(fit.coefficients),
        "residual": fit.residual,
    }
    text = (
        "K - K_oracle = "
        + " + ".join(f"{c:+.6g} x [{n}]" for n, c in zip(fit.names, fit.coefficients))
        + f" leaves a stiffness error of {fit.residual:.1e}; the force matches"
    )
    if ok is not None:
        title = f"tangent error in one part: {words}"
        if mesh is not None and fit.names == ("material stiffness",):
            from conformance.diagnosis.elements import cell_kinematics

            F = cell_kinematics(*mesh)[2]
            spatial = spatial_factor_words(1.0 + fit.coefficients[0], np.linalg.det(F))
            if spatial is not None:
                ratio = 1.0 + fit.coefficients[0]
                title = spatial
                text += f"; the factor {ratio:.9g} is the J (or 1/J) of every cell here"
        if mesh is not None and fit.names == ("geometric stiffness",):
            title += _geometric_volume_words(1.0 + fit.coefficients[0], mesh)
        full.append(Finding("tangent-part", title, FULL, text, figs))
    elif fit.residual < 0.1 * err.stiffness:
        partial.append(
            Finding("tangent-part", f"tangent error mostly in: {words}", PARTIAL, text, figs)
        )


def _geometric_volume_words(ratio: float, mesh) -> str:
    """Words for a geometric stiffness scaled by the J (or 1/J) that every cell shares: that
    part integrated over the other configuration's volume; "" otherwise.
    """
    from conformance.diagnosis.elements import cell_kinematics

    J = np.linalg.det(cell_kinematics(*mesh)[2])
    if np.ptp(J) > 1e-9 * np.abs(J).max() or abs(J[0] - 1.0) < 1e-6:
        return ""
    if abs(ratio * J[0] - 1.0) < 1e-9:
        return (
            " (= 1/J of every cell here: e.g. that part integrated over the rest volume V0 "
            "where the deformed volume v = J V0 belongs)"
        )
    if abs(ratio / J[0] - 1.0) < 1e-9:
        return (
            " (= J of every cell here: e.g. that part integrated over the deformed volume "
            "v = J V0 where the rest volume V0 belongs)"
        )
    return ""


#: Largest relative error that float32 rounding of one intermediate makes (2^-24 times a few
#: hundred): beyond it, a change along C^-1 (x) C^-1 on one J is no rounding.
ROUNDED_SIZE = 1e-5


def _volumetric_findings(
    points,
    cells,
    x,
    df,
    D,
    s: Scales,
    worst: float,
    tol: Tolerances,
    full,
    partial,
    energy_denies: bool = False,
) -> None:
    """The error as a per-cell change of the volumetric energy: named "energy differs" only when
    the change is one function of J (on a state where J varies) and the engine's energy does not
    deny it; otherwise said as a spherical stress and tangent difference, partly explaining.
    """
    from conformance.diagnosis.tangent import fit_volumetric

    fit = fit_volumetric(points, cells, x, df, D, s.force, s.stiffness)
    if fit is None:
        return
    J1 = float(np.median(fit.J))
    figs = {
        "force_after": fit.force_residual,
        "stiffness_after": fit.stiffness_residual,
        "residual": max(fit.force_residual, fit.stiffness_residual),
        "variant": fit.variant,
        "dU1_median": float(np.median(fit.dU1)),
        "dU2_median": float(np.median(fit.dU2)),
    }
    text = (
        f"a per-cell change of the J-only energy U(J) leaves force error {fit.force_residual:.1e} "
        f"and stiffness error {fit.stiffness_residual:.1e}; fitted engine-minus-oracle dU/dJ "
        f"{np.median(fit.dU1):.4g} Pa and d2U/dJ2 {np.median(fit.dU2):.4g} Pa at the median J = "
        f"{J1:.4g}"
    )
    if fit.variant:
        text += f"; recognised: {fit.variant}"
    elif np.unique(np.round(fit.J, 12)).size < 3:
        text += (
            "; the state has a single J, so the form of U cannot be identified from this case alone"
        )
    force_ok = np.linalg.norm(df) / s.force <= tol.force
    title = (
        "volumetric (J-only) tangent differs (the force matches)"
        if force_ok
        else "volumetric (J-only) energy differs from the oracle's"
    )
    spread = j_function_residual(fit.J, fit.dU1, fit.dU2)
    figs["j_function_residual"] = spread
    named = True
    steps = j_function_steps(fit.J, fit.dU2)
    figs["j_function_steps"] = steps
    if force_ok:
        # The tangent alone claims no energy, but "the volumetric tangent" claims U''(J): its
        # per-cell change must be one function of J. Another term along C^-1 (x) C^-1 (in a
        # decoupled engine, the isochoric projection's) fits the same per-cell form.
        if not np.isfinite(steps):
            named = False  # two causes fit equally: said as the closest reading, not named
            if fit.force_residual <= tol.force and fit.stiffness_residual <= tol.stiffness:
                # exact here, and the same reading named on a case where J varies is what
                # this one cannot tell apart, not a contradiction (corroborate.fits_codes)
                # (a term's f''(J) in an MJED engine, its J-J block, is along it too)
                figs["fits_codes"] = [
                    "volumetric",
                    "mjed-d2f",
                    "finite-difference-term:J",
                    "mjed-difference:J",
                ]
            title = (
                "a tangent term along C^-1 (x) C^-1 differs (the force matches): the volumetric "
                "tangent U''(J), or another term along C^-1 (x) C^-1 such as an isochoric "
                "projection's; this case has too few distinct J to tell them apart"
            )
        elif steps > j_function_line(fit.J, fit.dU2):
            named = False
            title = (
                "a tangent term along C^-1 (x) C^-1 differs per cell, not as one function of J "
                "(the force matches): not the volumetric tangent U''(J)"
            )
            text += (
                f"; the fitted d2U/dJ2 of a cell differs from what its neighbours in J predict "
                f"by {steps:.2f} of its spread: it depends on more than J (e.g. an isochoric "
                "invariant: a term of the isochoric tangent along C^-1 (x) C^-1)"
            )
    # Only an energy is one function of J; the tangent alone (the force right) claims none.
    if spread > J_ONLY and not force_ok:  # a pressure per cell, not one U(J)'s
        named = False
        title = "a spherical (pressure-like) stress and tangent differ per cell, not as one U(J)"
        text += (
            f"; the fitted dU/dJ and d2U/dJ2 are not one function of J over the cells (the "
            f"steps of dU/dJ against d2U/dJ2 integrated in J leave {spread:.1e}): not a J-only "
            "energy"
        )
    elif energy_denies and not force_ok:
        named = False
        # Kept (in the findings) for readings.denied_volumetric: the readings of the energy go
        # first; if none names a cause, this statement of the stress and tangent is the cause.
        # Only where J varies: on one J the one-function test cannot fail, so nothing is held.
        exact = fit.force_residual <= tol.force and fit.stiffness_residual <= tol.stiffness
        figs["denied"] = bool(np.isfinite(spread) and exact)
        if exact and not np.isfinite(spread):
            # One J: any slip in U'(J) or U''(J) (a term's f'(J) or f''(J), a hand-written
            # dW/dJ) fits here exactly; named where J varies, it is consistent with this case
            # (corroborate.fits_codes; "code:J": that cause only where it reads a J derivative).
            figs["fits_codes"] = [
                "volumetric",
                "mjed-dfdj",
                "mjed-d2f",
                "stress-derivative-rewritten:J",
                "finite-difference-pressure",
            ]
        title = (
            "volumetric (J-only) stress and tangent differ from the oracle's, but the engine's "
            "energy does not say so"
        )
        text += (
            "; the engine's energy equals the oracle's or its force is not the energy's "
            "derivative (the probes): the volumetric energy itself is not what differs"
        )
    if named and not force_ok and np.unique(np.round(fit.J, 12)).size < 3:
        # One J (a homogeneous state): whatever changes only the J-terms here fits as well,
        # e.g. every shape-function gradient scaled (F = k F: I1b, I2b unchanged, J times
        # k^3); a case of the kit that tells them apart settles it (corroborate.fits_codes)
        figs["fits_codes"] = [
            "volumetric",
            "gradients-scaled",
            "finite-difference-pressure",
            "stress-derivative-rewritten:J",
        ]
    if "fits_codes" in figs and worst <= ROUNDED_SIZE:
        # Alike cells round alike: a per-cell scalar in float32 (an invariant, a coefficient)
        # is one systematic change on a homogeneous state, exact along C^-1 (x) C^-1 here; a
        # case of the kit whose cells differ shows it drawn per cell (corroborate.fits_codes).
        figs["fits_codes"] = [
            *figs["fits_codes"],
            "single-precision-intermediate",
            "single-precision-part-scalar",
        ]
    if named and fit.force_residual <= tol.force and fit.stiffness_residual <= tol.stiffness:
        full.append(Finding("volumetric", title, FULL, text, figs))
    elif figs["residual"] < 0.1 * worst:
        partial.append(Finding("volumetric", title, PARTIAL, text, figs))


#: A fitted tangent part explains the stiffness error only where it leaves at most this share
#: of it (besides the tolerance).
EXPLAINED_SHARE = 0.1

#: A place is named only where the error outside it is at most this share of the whole (the
#: rest at round-off): more is one error graded over the mesh, its tail below the tolerance.
SPREAD_SHARE = 1e-3


def _locality_findings(
    f, K, f_o, K_o, s: Scales, cells, field_, tol: Tolerances, full, partial
) -> None:
    n = field_.size
    total = float(np.sum(field_**2))
    if total == 0:
        return
    order = np.argsort(field_)[::-1]
    # tail[k]: the squared error outside the k largest nodes, summed from the small end (exact
    # where 1 - cumsum would round to 1e-16 of the total).
    tail = np.append(np.cumsum((field_[order] ** 2)[::-1])[::-1], 0.0)
    limit = max(4, int(0.05 * n))
    # The nodes that hold all of the error but what the tolerance lets pass: an engine's own
    # round-off elsewhere (1e-16 of its values) must not spread a one-cell error over the mesh.
    floor = max(1e-20 * total, (0.5 * min(tol.force, tol.stiffness)) ** 2)
    k = max(1, int(np.argmax(tail <= floor)))
    if k > limit or 2 * k > n:
        return  # not localised: the error is on most of the mesh
    nodes = np.sort(order[:k])
    mask = np.ones(n, dtype=bool)
    mask[nodes] = False
    dofs = np.flatnonzero(np.repeat(mask, 3))
    from scipy.sparse.linalg import norm as sparse_norm

    fout = float(np.linalg.norm((f - f_o)[mask])) / s.force
    kout = float(sparse_norm((K - K_o).tocsr()[dofs][:, dofs])) / s.stiffness
    fall = float(np.linalg.norm(f - f_o)) / s.force
    kall = float(sparse_norm((K - K_o).tocsr())) / s.stiffness
    if fout > SPREAD_SHARE * fall or kout > SPREAD_SHARE * kall:
        # The same error, smaller, on the rest of the mesh (a step's truncation or a rounded
        # exponential grows with each cell's strain, and the most strained cells carry it past
        # the tolerance): graded over the mesh, not a place. A mistake in a few cells leaves
        # the others at round-off.
        return
    in_set = np.isin(cells, nodes).all(axis=1)
    cell_ids = np.flatnonzero(in_set)
    where = f"nodes {', '.join(map(str, nodes[:12]))}{' ...' if nodes.size > 12 else ''}"
    if cell_ids.size:
        where += (
            f" (cells {', '.join(map(str, cell_ids[:8]))}{' ...' if cell_ids.size > 8 else ''})"
        )
    figs = {
        "nodes": nodes.tolist(),
        "cells": cell_ids.tolist(),
        "force_outside": fout,
        "stiffness_outside": kout,
        "residual": max(fout, kout),
    }
    text = (
        f"the error is confined to {k} of {n} nodes: {where}; elsewhere force error {fout:.1e}, "
        f"stiffness error {kout:.1e}; see the per-node error field"
    )
    if fout <= tol.force and kout <= tol.stiffness:
        full.append(
            Finding(
                "localised",
                f"error localised to {nodes.size} node(s)"
                + (f" / {cell_ids.size} cell(s)" if cell_ids.size else ""),
                FULL,
                text,
                figs,
            )
        )
