"""The Python way in: a small protocol for an implementation, and a pytest-friendly assertion.

An implementation is any callable taking a :class:`conformance.kit.spec.CaseInput` (rest points,
cells, current positions, model) and returning the force (n, 3), the stiffness (3n, 3n, dense
or scipy sparse) and optionally the energy: as an :class:`EngineOutput`, a tuple
``(force, stiffness)`` / ``(force, stiffness, energy)``, or a mapping with those keys.

    from conformance import assert_matches_oracle

    def test_my_engine_matches_the_oracle():
        assert_matches_oracle(my_engine, material="NeoHookean", mesh="single-tet")

A failure raises AssertionError whose message is the diagnosis of every failing case.
"""

from __future__ import annotations

from typing import (
    Any,
    Callable,
    Iterable,
    Mapping,
    Optional,
    Protocol,
    Sequence,
    Union,
    runtime_checkable,
)

import numpy as np
import scipy.sparse as sp

from conformance.judge.oracle import OracleCache
from conformance.kit.cases import KitCase, build_cases
from conformance.kit.exchange import EngineOutput
from conformance.kit.spec import CaseInput
from conformance.run import CaseError, CheckRun, run_check

__all__ = [
    "Implementation",
    "as_engine_output",
    "check_implementation",
    "assert_matches_oracle",
    "resolve_models",
    "python_evaluator",
]


@runtime_checkable
class Implementation(Protocol):
    """Force, stiffness and optionally energy of a case (docs/conventions.md for signs and
    order).
    """

    def __call__(self, case: CaseInput) -> Any: ...


def as_engine_output(
    result: Any, n_nodes: int, case_id: str, source: str = "implementation"
) -> EngineOutput:
    """Normalise and validate what an implementation returned (shape, node count, finiteness)."""
    where = f"case {case_id}: {source}"
    if isinstance(result, EngineOutput):
        f, K, W = result.force, result.stiffness, result.energy
    elif isinstance(result, Mapping):
        if "force" not in result or "stiffness" not in result:
            raise CaseError(f"{where}: a mapping result needs 'force' and 'stiffness' keys")
        f, K, W = result["force"], result["stiffness"], result.get("energy")
    elif isinstance(result, tuple) and len(result) in (2, 3):
        f, K = result[:2]
        W = result[2] if len(result) == 3 else None
    else:
        raise CaseError(
            f"{where}: returned {type(result).__name__}; expected (force, stiffness[, energy]), a "
            "mapping or an EngineOutput"
        )
    # float32 arrays: the engine computes in single precision (the check's "auto" precision).
    single = np.asarray(f).dtype == np.float32 or getattr(K, "dtype", None) == np.float32
    precision = "single" if single else "double"
    f = np.asarray(f, dtype=np.float64)
    N = 3 * n_nodes
    if f.size != N:
        raise CaseError(
            f"{where}: force has {f.size} values (shape {f.shape}), expected (n, 3) = ({n_nodes}, "
            "3)"
        )
    f = f.reshape(n_nodes, 3)
    K = (
        sp.csr_matrix(K, dtype=np.float64)
        if sp.issparse(K)
        else sp.csr_matrix(np.asarray(K, dtype=np.float64))
    )
    if K.shape != (N, N):
        raise CaseError(f"{where}: stiffness has shape {K.shape}, expected (3n, 3n) = ({N}, {N})")
    for name, arr in (("force", f), ("stiffness", K.data)):
        bad = ~np.isfinite(arr)
        if bad.any():
            raise CaseError(
                f"{where}: {name} has {int(bad.sum())} non-finite value(s) (NaN or inf)"
            )
    if W is not None:
        W = float(W)
        if not np.isfinite(W):
            raise CaseError(f"{where}: energy is not finite ({W})")
    return EngineOutput(f, K, W, precision)


def python_evaluator(impl: Callable[[CaseInput], Any]) -> Callable[[KitCase], EngineOutput]:
    """An evaluator for :func:`conformance.run.run_check` that calls ``impl``; an exception it
    raises
    becomes a bad-input outcome for that case (named with the exception).
    """

    def evaluate(case: KitCase) -> EngineOutput:
        try:
            result = impl(case.input)
        except CaseError:
            raise
        except Exception as exc:  # the user's code failed on this case: report it, run the others
            raise CaseError(
                f"case {case.case_id}: implementation raised {type(exc).__name__}: {exc}"
            ) from exc
        return as_engine_output(result, case.input.n_nodes, case.case_id)

    return evaluate


def resolve_models(
    material: Union[None, str, Any, Sequence[Any]] = None, energy: Any = None
) -> list:
    """Models from a material name ('all', 'NeoHookean', ...), material instance(s) or a user
    energy.
    """
    from common.cases import parse_materials

    models: list = []
    if material is not None:
        items = (
            [material]
            if isinstance(material, str) or not isinstance(material, Iterable)
            else list(material)
        )
        for m in items:
            models.extend(parse_materials(m) if isinstance(m, str) else [m])
    if energy is not None:
        models.append(energy)
    if not models:
        raise ValueError("give a material (name or instance) or a user energy")
    return models


def _meshes(mesh: Union[str, tuple, Sequence]) -> list:
    import meshes

    items = [mesh] if isinstance(mesh, (str, tuple)) else list(mesh)
    out = []
    for m in items:
        if isinstance(m, tuple) and len(m) == 2:
            out.append(
                ("user-mesh", np.asarray(m[0], dtype=float), np.asarray(m[1], dtype=np.int64))
            )
        else:
            pts, cells, label = meshes.resolve(m)
            out.append((label, pts, cells))
    return out


def check_implementation(
    impl: Callable[[CaseInput], Any],
    *,
    material: Any = None,
    energy: Any = None,
    mesh: Any = "single-tet",
    states: Sequence[str] = ("uniaxial", "shear", "random"),
    probes: bool = True,
    precision: str = "auto",
    read_causes: bool = True,
    cache: Optional[OracleCache] = None,
) -> CheckRun:
    """Run ``impl`` on every model x mesh x state (with probes) and diagnose each case.

    mesh: a built-in name, a file path, a (points, cells) pair, or a list of them.
    precision: "double", "single" or "auto" (single when ``impl`` returns float32 arrays).
    read_causes: False judges only (the verdicts and errors; a failed case's cause is not
    looked for: ``mjed-verify check --verdict-only``).
    cache: the oracles (the reference and the diagnosis' candidate energies) to reuse across
    several checks on the same meshes and materials; a new one by default.
    """
    if precision not in ("auto", "double", "single"):
        raise ValueError(f"precision must be 'auto', 'double' or 'single', not {precision!r}")
    cases = build_cases(
        resolve_models(material, energy), _meshes(mesh), list(states), probes=4 if probes else 0
    )
    return run_check(
        cases, python_evaluator(impl), precision=precision, read_causes=read_causes, cache=cache
    )


def assert_matches_oracle(
    impl: Callable[[CaseInput], Any],
    *,
    material: Any = None,
    energy: Any = None,
    mesh: Any = "single-tet",
    states: Sequence[str] = ("uniaxial", "shear", "random"),
    probes: bool = True,
) -> CheckRun:
    """:func:`check_implementation`, raising AssertionError with the diagnosis unless every case
    passes.
    """
    run = check_implementation(
        impl, material=material, energy=energy, mesh=mesh, states=states, probes=probes
    )
    if run.exit_code != 0:
        failing = [o for o in run.outcomes if o.status != "passed"]
        body = "\n".join(
            o.diagnosis.text()
            if o.diagnosis is not None
            else f"case {o.case_id}: BAD INPUT: {o.message}"
            for o in failing
        )
        raise AssertionError(f"{run.summary()}\n{body}")
    return run
