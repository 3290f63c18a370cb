"""Choose the implementation of MJED by a parameter: ``make_force_field(..., backend=...)``."""

from __future__ import annotations

from mjed.forcefield import HyperelasticForceField

__all__ = ["BACKENDS", "ALL_BACKENDS", "make_force_field"]

#: The CPU backends, in order of preference of nothing: "numpy" always works, "numba" needs
#: Numba. (What the studies run by default.)
BACKENDS = ("numpy", "numba")
#: Every backend make_force_field knows: the CPU ones and "cuda" (Numba's CUDA target; an
#: NVIDIA GPU, or Numba's CUDA simulator with NUMBA_ENABLE_CUDASIM=1).
ALL_BACKENDS = BACKENDS + ("cuda",)


def make_force_field(mesh, material, backend: str = "numpy", **options):
    """A force field with energy/force/stiffness/force_and_stiffness for ``mesh`` and ``material``.

    backend: "numpy" (:class:`mjed.HyperelasticForceField`, NumPy and SciPy only), "numba"
    (:class:`mjed.compiled.CompiledForceField`) or "cuda" (:class:`mjed.cuda.CudaForceField`).
    The returned object's ``backend`` attribute names it. options: ``regularize``,
    ``allow_inverted`` (every backend); ``parallel``, ``slabs`` (numba: all cores); ``batch``
    (numba: cells per batch of the cell-batched, SIMD kernel; 0, the default, one at a time);
    ``dtype`` (cuda: np.float64, the default, or np.float32).

    Raises ValueError for an unknown backend and mjed.compiled.BackendUnavailable when the
    numba backend is asked for without Numba, or the cuda backend without Numba's CUDA
    target and a device (or its simulator).
    """
    if backend == "numpy":
        return HyperelasticForceField(mesh, material, **options)
    if backend == "numba":
        from mjed.compiled import CompiledForceField

        return CompiledForceField(mesh, material, **options)
    if backend == "cuda":
        from mjed.cuda import CudaForceField

        return CudaForceField(mesh, material, **options)
    raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(ALL_BACKENDS)}")
