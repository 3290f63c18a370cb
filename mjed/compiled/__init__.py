"""The optional compiled backend of mjed (Numba).

    >>> from mjed.compiled import CompiledForceField
    >>> field = CompiledForceField(mesh, material)        # same methods as HyperelasticForceField
    >>> f, K = field.force_and_stiffness(x)

or, choosing the backend by a parameter, ``mjed.make_force_field(mesh, material, backend="numba")``.

How the kernel stays generic (one kernel, not one per material): a material is still its
declared list of MJED terms. :mod:`mjed.compiled.lowering` turns that list into a table of
integer codes (the kind of each f(J) and g(C), chosen by a registry keyed by the term's type)
and float parameters, plus the per-mesh edge quantities of the paper (D_a x D_b and
D_a . M D_b of every second-kind tangent slot). One compiled kernel
(:func:`mjed.compiled.kernels.mjed_cells`) walks the cells; in each cell it evaluates every
term of the table by its code (small compiled functions per term kind), sums the group
aggregates exactly as the NumPy engine does (u, S-bar, S-hat, h, g2, the slot weights), forms
the gradient and the six edge blocks from them, and scatters the blocks, their transposes and
the node blocks (translation invariance) straight into the CSR data array of
:class:`mjed.sparse.CSRPattern`. Adding a material therefore needs no new kernel; adding a
new *kind* of term needs one branch in the kernel and one registry entry.

We chose a table read by one kernel over generating source per material because the kernel
is compiled once (and cached on disk) for every material, the per-cell branch on a term code
costs far less than the arithmetic it selects, and the code stays reviewable. The cost of
the choice: the kernel cannot specialise away terms a material does not have, beyond the
per-cell flags it keeps (no S-hat, no spectral pair, ...).

Importing :mod:`mjed` or this package does not import Numba; building a compiled field does,
and raises :class:`BackendUnavailable` with the reason when Numba is missing. Terms without a
compiled kind (e.g. :class:`mjed.porous.PorousVolume`) are refused with NotImplementedError.
"""

from mjed.compiled.availability import BackendUnavailable, numba_available, require_numba
from mjed.compiled.forcefield import CompiledForceField

__all__ = ["CompiledForceField", "BackendUnavailable", "numba_available", "require_numba"]
