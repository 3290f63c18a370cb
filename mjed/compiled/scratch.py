"""Scratch arrays on the stack of a compiled kernel (no heap allocation, no reference counts).

A kernel's small work arrays (3x3 for the eigen-decomposition, ...) made with ``np.empty``
live on the heap: the compiler cannot prove they do not alias the output arrays, so every
store to an output forces them to be reloaded, and passing them to a compiled helper costs
reference-count updates. These arrays are ``alloca`` slots of the calling function instead
(allocated once, in its entry block, however often the call runs), viewed as C-contiguous
float64 arrays. The sizes must be compile-time constants. Importing this module imports Numba.
"""

from __future__ import annotations

from numba import carray, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["local_vector", "local_matrix"]


@intrinsic
def _stack_doubles(typingctx, n0, n1):
    """A pointer to n0 * n1 (literal ints) float64 slots in the caller's entry block."""
    if not (isinstance(n0, types.IntegerLiteral) and isinstance(n1, types.IntegerLiteral)):
        return None
    n = n0.literal_value * n1.literal_value

    def codegen(context, builder, signature, args):
        return cgutils.alloca_once(
            builder, context.get_value_type(types.float64), size=context.get_constant(types.intp, n)
        )

    return types.CPointer(types.float64)(n0, n1), codegen


@njit(inline="always")
def local_vector(n):
    """A (n,) float64 stack array, uninitialised; n a literal."""
    return carray(_stack_doubles(n, 1), (n,))


@njit(inline="always")
def local_matrix(n0, n1):
    """A (n0, n1) float64 stack array, uninitialised; n0, n1 literals."""
    return carray(_stack_doubles(n0, n1), (n0, n1))
