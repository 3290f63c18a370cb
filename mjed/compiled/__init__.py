"""The optional compiled backend of mjed (Numba).

    >>> from mjed.compiled import CompiledForceField
    >>> field = CompiledForceField(mesh, material)        # same methods as HyperelasticForceField
    >>> f, K = field.force_and_stiffness(x)

or, choosing the backend by a parameter, ``mjed.make_force_field(mesh, material, backend="numba")``.

How the kernel stays generic (one engine, no kernel written per material): a material is
still its declared list of MJED terms. :mod:`mjed.compiled.lowering` turns that list into a
table of integer codes (the kind of each f(J) and g(C), chosen by a registry keyed by the
term's type), float parameters and the tangent slots. :mod:`mjed.compiled.shape` reads the
table's *structure* (which kinds, in which groups, which slots, what varies per cell);
:mod:`mjed.compiled.codegen` writes, from that structure alone, the Python source of one
cell loop: kinematics, every term, the group aggregates (u, S-bar, S-hat, h, g2, the slot
weights) exactly as the NumPy engine sums them, the gradient, the six edge blocks and the
node blocks, each 3x3 quantity spelt as scalar locals, and nothing a material does not have
(a quantity that is structurally zero is dropped while writing). The numbers stay arguments,
so materials of one structure (e.g. every Neo-Hookean) share one compiled kernel.
:mod:`mjed.compiled.specialise` writes that source to a cache directory outside the
repository, named by its hash, and imports it; Numba compiles it once per machine
(``cache=True``). Adding a material needs nothing here; a new *kind* of term needs a registry
entry and a branch in the generator.

Why generate code rather than keep one table-driven kernel (the first design): measured on
cube-paper (20,599 cells) on the 2-core test machine, the table-driven kernel spent about
190 ns per cell on NeoHookean's arithmetic, because its 3x3 quantities lived in small arrays
the compiler could not keep in registers (every store into the output arrays forced them to
be reloaded), and it looped and branched over terms, slots and groups per cell. Moving its
scratch arrays to the stack gave 20 %; the generated scalar kernel takes NeoHookean's
force + stiffness from 5.6-6.8 ms to 2.3 ms and the force alone from 1.9 to 0.75 ms
(NumPy engine: 7.4 and 1.3 ms). The cost: the first call of a shape compiles its kernel
(1.7 to 4 s cold; 19 s for the seven default materials) where the table-driven kernel
compiled once for all materials (9 s); a second process loads every kernel from Numba's cache
(0.2 s for all seven). The generated source can be read in the cache directory.

All cores: ``CompiledForceField(mesh, material, parallel=True)`` (or ``make_force_field(...,
backend="numba", parallel=True)``) runs the same cell body from a parallel driver: slabs of
cells coloured so that no two slabs of a colour share a node run on Numba's threads, the
colours one after the other (:mod:`mjed.compiled.schedule`, and the argument for colouring in
:class:`mjed.compiled.codegen.ParallelTarget`). The default stays one thread.
``CompiledForceField(mesh, material, batch=16)`` runs the cell body over 16 cells at once,
one per SIMD lane (:mod:`mjed.compiled.batched`; serial or with ``parallel=True``); the
default stays one cell at a time. The same generator writes the CUDA kernel of
:mod:`mjed.cuda` (a fourth target).

Importing :mod:`mjed` or this package does not import Numba; building a compiled field does,
and raises :class:`BackendUnavailable` with the reason when Numba is missing. Terms without a
compiled kind (e.g. :class:`mjed.porous.PorousVolume`) are refused with NotImplementedError.
"""

from mjed.compiled.availability import BackendUnavailable, numba_available, require_numba
from mjed.compiled.forcefield import CompiledForceField

__all__ = ["CompiledForceField", "BackendUnavailable", "numba_available", "require_numba"]
