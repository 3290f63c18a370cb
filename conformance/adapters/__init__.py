"""Adapters that run third-party finite-element libraries in this project's conventions.

Each adapter is built from (points, cells, model) on a P1 tetrahedral mesh and answers, at
current positions x (n, 3):

* ``force(x)`` -> f (n, 3) with f = -dW/dx (W the library's total strain energy);
* ``stiffness(x)`` -> K, scipy CSR (3n, 3n), K = d2W/dx2, dof index 3*node + component;
* ``force_and_stiffness(x)`` -> both with one state update;
* ``energy(x)`` -> the library's total energy, where the library computes one.

``model`` is one of this project's materials, a :class:`reference_fem.user_energy.UserEnergy`
that states the library's own energy exactly, or the library's own material object. Which
ones an adapter can run is answered by its module's ``supports(model) -> (bool, reason)``;
the reason says how the library's energy relates to the model (equal, or equal up to a
constant, with the constant). ``library_energy`` on an adapter is the energy the library
computes, written as a UserEnergy, so that the UFL oracle can check exactly that.

The libraries are optional: importing an adapter module never fails; ``available()`` in it
tells whether the library can be used, and why not.
"""

from __future__ import annotations

import abc
from typing import Tuple

import numpy as np
import scipy.sparse as sp

from reference_fem.validation import check_cells, check_points, check_positions

__all__ = ["Unsupported", "MeshAdapter", "LibraryImplementation"]


class Unsupported(ValueError):
    """The library has no energy that matches the model; the message says why."""


class MeshAdapter(abc.ABC):
    """Validated mesh and the shared conversions of every adapter (subclasses implement
    ``_evaluate(u, want_force, want_stiffness)`` with u = x - X of shape (n, 3)).
    """

    #: The library's name, for messages and reports.
    library = "library"

    def __init__(self, points, cells):
        self._X = check_points(points)
        self._cells = check_cells(cells, self._X)
        self._X.setflags(write=False)
        self._cells.setflags(write=False)

    @property
    def points(self) -> np.ndarray:
        return self._X

    @property
    def cells(self) -> np.ndarray:
        return self._cells

    @property
    def n_nodes(self) -> int:
        return self._X.shape[0]

    def _displacement(self, x) -> np.ndarray:
        return check_positions(x, self.n_nodes) - self._X

    def force(self, x) -> np.ndarray:
        """F = -dW/dx, shape (n, 3)."""
        return self.force_and_stiffness(x, stiffness=False)[0]

    def stiffness(self, x) -> sp.csr_matrix:
        """K = d2W/dx2, scipy CSR (3n, 3n), dof index 3*node + component."""
        return self.force_and_stiffness(x, force=False)[1]

    def force_and_stiffness(self, x, *, force: bool = True, stiffness: bool = True) -> Tuple:
        u = self._displacement(x)
        f, K = self._evaluate(u, force, stiffness)
        if f is not None:
            f = np.asarray(f, dtype=np.float64).reshape(self.n_nodes, 3)
            self._require_finite(f, "force")
        if K is not None:
            K = sp.csr_matrix(K, dtype=np.float64)
            n3 = 3 * self.n_nodes
            if K.shape != (n3, n3):
                raise RuntimeError(
                    f"{self.library}: stiffness has shape {K.shape}, expected ({n3}, {n3})"
                )
            K.sum_duplicates()
            K.sort_indices()
            self._require_finite(K.data, "stiffness")
        return f, K

    def _require_finite(self, values: np.ndarray, what: str) -> None:
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{self.library}: non-finite {what} (inverted or flattened cells?)")

    @abc.abstractmethod
    def _evaluate(self, u: np.ndarray, want_force: bool, want_stiffness: bool):
        """(f or None, K or None) in the project's conventions for displacement u (n, 3)."""


class LibraryImplementation:
    """An adapter class as an implementation of conformance/protocol.py: ``impl(case)`` with a
    case carrying ``points``, ``cells``, ``positions`` and ``model`` returns
    ``(force, stiffness, energy or None)``. One adapter is built per (mesh, model) and reused
    for every state of it (the library's set-up is the slow part).
    """

    def __init__(self, adapter_class):
        self.adapter_class = adapter_class
        self._built: dict = {}

    def adapter(self, points, cells, model) -> MeshAdapter:
        try:
            key = (np.asarray(points).tobytes(), np.asarray(cells).tobytes(), model)
            hash(key)
        except TypeError:  # an unhashable model (e.g. with an array field): build afresh
            return self.adapter_class(points, cells, model)
        if key not in self._built:
            self._built[key] = self.adapter_class(points, cells, model)
        return self._built[key]

    def __call__(self, case):
        adapter = self.adapter(case.points, case.cells, case.model)
        f, K = adapter.force_and_stiffness(case.positions)
        energy = getattr(adapter, "energy", None)
        return f, K, None if energy is None else energy(case.positions)
