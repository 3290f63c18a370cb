"""Choose the implementation of MJED by a parameter: ``make_force_field(..., backend=...)``."""

from __future__ import annotations

from mjed.forcefield import HyperelasticForceField

__all__ = ["BACKENDS", "make_force_field"]

#: The backends, in order of preference of nothing: "numpy" always works, "numba" needs Numba.
BACKENDS = ("numpy", "numba")


def make_force_field(mesh, material, backend: str = "numpy", **options):
    """A force field with energy/force/stiffness/force_and_stiffness for ``mesh`` and ``material``.

    backend: "numpy" (:class:`mjed.HyperelasticForceField`, NumPy and SciPy only) or "numba"
    (:class:`mjed.compiled.CompiledForceField`). The returned object's ``backend`` attribute
    names it. options: ``regularize``, ``allow_inverted`` (both backends).

    Raises ValueError for an unknown backend and mjed.compiled.BackendUnavailable when the
    numba backend is asked for without Numba.
    """
    if backend == "numpy":
        return HyperelasticForceField(mesh, material, **options)
    if backend == "numba":
        from mjed.compiled import CompiledForceField

        return CompiledForceField(mesh, material, **options)
    raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
