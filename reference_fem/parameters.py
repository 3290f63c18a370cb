"""Material parameters as one dolfinx vector Constant, so compiled forms are reused.

With parameters baked in as literals, every new parameter set is a new form for FFCx (the
Ogden stiffness takes ~17 s to compile). With one dolfinx Constant per parameter the
generated code no longer depends on the values, but UFL 2022.2 orders the operands of sums
by comparing terminals' repr, which for a Constant contains its global creation count; the
form signature (the JIT cache key) then changed from one oracle to the next as the count
crossed powers of ten, and the stiffness was recompiled again and again. A single vector
Constant, indexed c[0], c[1], ..., sorts by the fixed indices only and keeps the signature
stable.
"""

from __future__ import annotations

from typing import Any, Callable, List, Tuple

import numpy as np
import ufl

__all__ = ["packed_parameters"]


def packed_parameters(
    build: Callable[[Callable[[Any], Any]], Any],
    make_constant: Callable[[np.ndarray], Any],
) -> Tuple[Any, Any]:
    """Build an expression whose parameters all live in one vector Constant.

    Args:
        build: called as ``build(constant)``, where ``constant`` maps a parameter (a float or
            a (3, 3) array) to a UFL expression; returns the expression (e.g. a partial of
            :func:`reference_fem.energies.strain_energy_density`). It is called twice: once
            to record the parameters, once to build the final expression.
        make_constant: turns the (k,) array of all parameter values into a UFL vector
            constant, e.g. ``lambda v: dolfinx.fem.Constant(mesh, v)``.

    Returns:
        ``(expression, constant)``; the constant is None if there were no parameters.
    """
    values: List[float] = []

    def record(value):
        a = np.asarray(value, dtype=np.float64)
        values.extend(a.ravel().tolist())
        return float(a) if a.ndim == 0 else ufl.as_matrix(a.tolist())

    build(record)  # first pass: only collects the values, in call order
    if not values:
        return build(lambda v: v), None
    c = make_constant(np.array(values, dtype=np.float64))
    position = iter(range(len(values)))

    def index(value):
        a = np.asarray(value)
        if a.ndim == 0:
            return c[next(position)]
        if a.shape != (3, 3):
            raise ValueError(f"array parameters must be (3, 3), got {a.shape}")
        return ufl.as_matrix([[c[next(position)] for _ in range(3)] for _ in range(3)])

    expression = build(index)
    if next(position, None) is not None:
        raise RuntimeError("the two passes over the parameters did not match")
    return expression, c
