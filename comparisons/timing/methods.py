"""The methods the timing study can time, in one registry, and how each one's result is
checked before its time counts.

A method is a :class:`TimedMethod`: how to build it for (points, cells, material), whether it
can run here (and why not), and how to read its force and stiffness in this project's
conventions (f = -dW/dx (n, 3), K = d2W/dx2 CSR with dof 3 node + component). Any object
with ``force_and_stiffness(x)`` (and optionally ``force(x)``, ``stiffness(x)``) plugs in with
:func:`register`. The built-in entries:

- ``mjed``, ``mjed-numba``: MJED, NumPy engine and compiled kernel (mjed.make_force_field);
- ``classical``, ``classical-numba``: the classical Galerkin, NumPy and compiled;
- ``dolfinx``: dolfinx's compiled assembly of the oracle's own forms;
- ``felupe``, ``sfepy``: the peer libraries through conformance/adapters (matched energies;
  a material whose energy the library cannot state is refused with the adapter's reason);
- ``sofa-mjed``, ``sofa-classical``: SOFA's own MJEDTetrahedralForceField (SofaMJEDFEM) and
  TetrahedronHyperelasticityFEMForceField, through the engine program of
  conformance/adapters/sofa (not run, with how to build it, where it is missing). Their
  objects time themselves (``self_timed``): SOFA's calls are timed inside its process, so the
  study records those medians instead of timing a process start per call.

Verification: before a method is timed its force and stiffness at the timing state are
compared with NumPy MJED's (which the equivalence study proves equal to the UFL oracle to
1e-10) with the equivalence tolerances; a method that does not match is not timed. dolfinx's
PETSc objects stay in dolfinx's numbering (renumbering is not part of its cost); it
assembles the oracle's forms, so it is verified by construction, which the result says.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Dict, Optional, Tuple

import numpy as np

__all__ = ["TimedMethod", "METHODS", "register", "get", "Verification", "verify"]

Builder = Callable[[np.ndarray, np.ndarray, Any], Any]


def _always() -> Optional[str]:
    return None


def _supports_all(material) -> Optional[str]:
    return None


@dataclass(frozen=True)
class TimedMethod:
    """name: the key (CLI --methods); label: for tables; family: "mjed", "classical",
    "dolfinx" or "peer"; compiled: whether its element loop is compiled code.
    unavailable(): None, or why it cannot run on this installation.
    unsupported(material): None, or why it cannot compute this material's energy.
    verified_by_construction: a sentence, for methods whose arrays are not compared.
    """

    name: str
    label: str
    family: str
    compiled: bool
    build: Builder
    unavailable: Callable[[], Optional[str]] = _always
    unsupported: Callable[[Any], Optional[str]] = _supports_all
    verified_by_construction: str = ""


METHODS: Dict[str, TimedMethod] = {}


def register(method: TimedMethod) -> TimedMethod:
    """Add (or replace) a method of the registry; returns it."""
    METHODS[method.name] = method
    return method


def get(name: str) -> TimedMethod:
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"unknown method {name!r}; known: {', '.join(METHODS)}") from None


# ------------------------------------------------------------------ the built-in methods
def _mesh(points, cells):
    import mjed

    return mjed.TetMesh(points, cells)


def _mjed(backend: str) -> Builder:
    def build(points, cells, material):
        import mjed

        return mjed.make_force_field(_mesh(points, cells), material, backend=backend)

    return build


def _numba_missing() -> Optional[str]:
    from mjed.compiled import numba_available

    return (
        None if numba_available() else "Numba is not installed (Debian: python3-numba; PyPI: numba)"
    )


def _numba_kernel_refuses(material) -> Optional[str]:
    from mjed.compiled.lowering import lower_groups

    try:
        lower_groups(material.decomposition(), np.zeros((1, 4, 3)))
    except NotImplementedError as exc:
        return str(exc)
    return None


def _classical(points, cells, material):
    from reference_fem.classical import ClassicalGalerkin

    return ClassicalGalerkin(_mesh(points, cells), None, material)


def _classical_numba(points, cells, material):
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    return CompiledClassicalGalerkin(_mesh(points, cells), None, material)


def _dolfinx(points, cells, material):
    from reference_fem.dolfinx_assembly import DolfinxAssembly

    return DolfinxAssembly(points, cells, material)


def _dolfinx_missing() -> Optional[str]:
    from reference_fem import dolfinx_available

    return None if dolfinx_available() else "dolfinx is not installed (Debian: python3-dolfinx)"


def _peer(
    module: str, adapter: str
) -> Tuple[Builder, Callable[[], Optional[str]], Callable[[Any], Optional[str]]]:
    """Builder, availability and support of a conformance adapter module with the checker's
    interface: ``available() -> (ok, why)``, ``supports(model) -> (ok, why)``, Adapter(points,
    cells, model).
    """
    import importlib

    def load():
        return importlib.import_module(module)

    def unavailable() -> Optional[str]:
        try:
            ok, why = load().available()
        except ImportError as exc:
            return f"the adapter {module} cannot be imported: {exc}"
        return None if ok else why

    def unsupported(material) -> Optional[str]:
        ok, why = load().supports(material)
        return None if ok else why

    def build(points, cells, material):
        return getattr(load(), adapter)(points, cells, material)

    return build, unavailable, unsupported


register(TimedMethod("mjed", "MJED (NumPy)", "mjed", False, _mjed("numpy")))
register(
    TimedMethod(
        "mjed-numba",
        "MJED (Numba)",
        "mjed",
        True,
        _mjed("numba"),
        _numba_missing,
        _numba_kernel_refuses,
    )
)
register(TimedMethod("classical", "classical (NumPy)", "classical", False, _classical))
register(
    TimedMethod(
        "classical-numba", "classical (Numba)", "classical", True, _classical_numba, _numba_missing
    )
)
register(
    TimedMethod(
        "dolfinx",
        "dolfinx",
        "dolfinx",
        True,
        _dolfinx,
        _dolfinx_missing,
        verified_by_construction="dolfinx assembles the UFL oracle's own forms "
        "(reference_fem/dolfinx_assembly.py), proven equal to MJED by the equivalence study",
    )
)


def _sofa(forcefield: str) -> Builder:
    def build(points, cells, material):
        from conformance.adapters.sofa.field import SofaField

        return SofaField(points, cells, material, forcefield)

    return build


def _sofa_missing() -> Optional[str]:
    from conformance.adapters.sofa.field import available

    return available()


def _sofa_refuses(forcefield: str) -> Callable[[Any], Optional[str]]:
    def unsupported(material) -> Optional[str]:
        from conformance.adapters.sofa.mapping import NotExpressible, sofa_material_of

        try:
            sofa_material_of(material, forcefield)
        except NotExpressible as why:
            return str(why)
        return None

    return unsupported


for _name, _label, _ff in (
    ("sofa-mjed", "SOFA MJEDTetrahedralForceField", "mjed"),
    ("sofa-classical", "SOFA TetrahedronHyperelasticityFEMForceField", "hyperelasticity"),
):
    register(
        TimedMethod(_name, _label, "peer", True, _sofa(_ff), _sofa_missing, _sofa_refuses(_ff))
    )

for _name, _label, _module, _cls in (
    ("felupe", "FElupe", "conformance.adapters.felupe", "FElupeAdapter"),
    ("sfepy", "SfePy", "conformance.adapters.sfepy", "SfePyAdapter"),
):
    _b, _u, _s = _peer(_module, _cls)
    register(TimedMethod(_name, _label, "peer", False, _b, _u, _s))


# ------------------------------------------------------------------ verification
@dataclass(frozen=True)
class Verification:
    """force_err, stiffness_err: relative errors against NumPy MJED (None when verified by
    construction); passed; note: how it was verified or why it failed.
    """

    force_err: Optional[float]
    stiffness_err: Optional[float]
    passed: bool
    note: str = ""

    def to_dict(self) -> dict:
        return {
            "force_err": self.force_err,
            "stiffness_err": self.stiffness_err,
            "passed": self.passed,
            "note": self.note,
        }


def verify(
    method: TimedMethod,
    obj: Any,
    x: np.ndarray,
    reference: Tuple[np.ndarray, Any],
    force_scale: float,
    tol: float,
) -> Verification:
    """Compare ``obj``'s force and stiffness at x with the reference (NumPy MJED)."""
    from common.tolerances import compare_arrays

    if method.verified_by_construction:
        return Verification(None, None, True, method.verified_by_construction)
    try:
        f, K = obj.force_and_stiffness(x)
        fe, ke, _ = compare_arrays(f, K, reference[0], reference[1], force_scale)
    except Exception as exc:  # a peer raising on evaluation is a verification failure, not a crash
        return Verification(None, None, False, f"evaluation raised {type(exc).__name__}: {exc}")
    ok = bool(fe <= tol and ke <= tol)
    note = "matches NumPy MJED" if ok else f"differs from NumPy MJED by more than {tol:g}"
    return Verification(float(fe), float(ke), ok, note)
