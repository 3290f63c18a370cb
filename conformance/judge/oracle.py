"""The oracle's values for a case: energy, force and stiffness from the UFL oracle, and the parts of
its stiffness for the diagnosis. One oracle per (mesh, model), reused across states and probes.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Callable, Dict, Optional, Sequence, Tuple, Union

import numpy as np
import scipy.sparse as sp

from conformance.judge.colouring import independent_node_groups
from conformance.judge.compare import Scales, Tolerances
from conformance.judge.consistency import ReferenceProbes
from conformance.judge.energy import energy_density
from conformance.judge.parts import PartsOracle
from conformance.judge.precision import sensitivity_of, single_tolerances
from conformance.kit.spec import CaseInput, model_frame, model_to_manifest

__all__ = ["Reference", "OracleCache", "energy_density", "oracle_available"]


def oracle_available() -> bool:
    from reference_fem import dolfinx_available

    return dolfinx_available()


class Reference:
    """The oracle at one state: energy [J], force (n, 3) [N], stiffness CSR (3n, 3n) [N/m].

    The force is assembled at once; the energy and the stiffness may be given as callables,
    assembled (and their forms compiled) when first read: the diagnosis rejects most candidate
    energies on their force alone, and a stiffness form is the costliest of the three to compile.
    """

    __slots__ = ("force", "_energy", "_stiffness")

    def __init__(
        self,
        energy: Union[float, Callable[[], float]],
        force: np.ndarray,
        stiffness: Union[sp.spmatrix, Callable[[], sp.spmatrix]],
    ) -> None:
        self.force = force
        self._energy = energy
        self._stiffness = stiffness

    @property
    def energy(self) -> float:
        if callable(self._energy):
            self._energy = float(self._energy())
        return self._energy

    @property
    def stiffness(self) -> sp.csr_matrix:
        if callable(self._stiffness):
            self._stiffness = sp.csr_matrix(self._stiffness())
        return self._stiffness


def _key(case: CaseInput) -> Tuple[str, str]:
    h = hashlib.sha256()
    for a in (case.points, case.cells):
        h.update(np.ascontiguousarray(a).tobytes())
    frame = model_frame(case.model)
    model = json.dumps(model_to_manifest(case.model), sort_keys=True)
    if frame is not None:
        model += hashlib.sha256(np.ascontiguousarray(frame).tobytes()).hexdigest()
    return h.hexdigest(), model


def _at(oracle: Any, case: CaseInput, lazy: bool = False) -> Reference:
    """``oracle`` evaluated at the case's positions; ``lazy``: the force now, the energy and the
    stiffness when first read (each sets the oracle's state to these positions again), and a
    state the oracle cannot evaluate (ValueError) may then be found only on that reading.
    """
    x = case.positions
    if lazy:
        return Reference(lambda: oracle.energy(x), oracle.force(x), lambda: oracle.stiffness(x))
    f, K = oracle.force_and_stiffness(x)
    return Reference(float(oracle.energy(x)), f, sp.csr_matrix(K))


class OracleCache:
    """UFL oracles and stiffness-part oracles, built once per (mesh, model)."""

    def __init__(self) -> None:
        self._oracles: Dict[Tuple[str, ...], Any] = {}
        self._parts: Dict[Tuple[str, str], Any] = {}
        # The last probes evaluated (key, result): the consistency test and a reading of the
        # same case ask for them in turn.
        self._last_probes: Optional[Tuple[Any, Tuple[tuple, tuple]]] = None

    def reference(self, case: CaseInput, lazy: bool = False) -> Reference:
        """The oracle of the case's model at its positions (``lazy``: see :func:`_at`)."""
        key = _key(case)
        if key not in self._oracles:
            from reference_fem import UFLOracle
            from reference_fem.user_energy import UserEnergy

            if isinstance(case.model, UserEnergy):
                # a user energy's symbolic work is unbounded by its length: compile it first
                # in a child with a time and memory budget (SymbolicBudgetError, a ValueError)
                from reference_fem.symbolic_budget import check_symbolic_budget

                check_symbolic_budget(case.model)
            self._oracles[key] = UFLOracle(case.points, case.cells, case.model)
        return _at(self._oracles[key], case, lazy)

    def evaluate_model(
        self, case: CaseInput, model: Any, key: str, lazy: bool = False
    ) -> Reference:
        """The oracle for another ``model`` on the case's mesh, at the case's positions (a model
        the diagnosis builds: one term of the energy, a mistaken kinematic); ``key`` names it
        (one oracle per (mesh, key), reused across states).
        """
        k = (*_key(case), "variant:" + key)
        if k not in self._oracles:
            from reference_fem import UFLOracle

            self._oracles[k] = UFLOracle(case.points, case.cells, model)
        return _at(self._oracles[k], case, lazy)

    def evaluate_once(self, case: CaseInput, model: Any) -> Reference:
        """The oracle for ``model`` at the case's positions, not kept: a refit asks for many
        models (a parameter or an exponent at each of its trial values), each once. Built from
        the same compiled form as the model's kept oracles where only parameter values differ.
        """
        from reference_fem import UFLOracle

        return _at(UFLOracle(case.points, case.cells, model), case)

    def column_derivatives(
        self, case: CaseInput, step: np.ndarray
    ) -> Tuple[sp.csr_matrix, sp.csr_matrix]:
        """(G1, G2), each (3n, 3n): column j is the first (second) derivative of the oracle's K
        column j along dof j, by central differences of step ``step[j]`` [m].

        One dof of every node of a group that shares no cell is perturbed at once
        (:mod:`conformance.judge.colouring`): each of their columns is then exactly what
        perturbing it alone gives, for 6 x (groups) oracle stiffness assemblies instead of 6n.
        """
        self.reference(case)  # builds the oracle if needed
        oracle = self._oracles[_key(case)]
        x = np.asarray(case.positions, dtype=np.float64).ravel()
        K0 = sp.csc_matrix(oracle.stiffness(case.positions))
        first: list = [None] * x.size
        second: list = [None] * x.size
        for nodes in independent_node_groups(case.cells, case.points.shape[0]):
            for component in range(3):
                dofs = 3 * nodes + component
                cols = []
                for sign in (1.0, -1.0):
                    y = x.copy()
                    y[dofs] += sign * step[dofs]
                    cols.append(sp.csc_matrix(oracle.stiffness(y.reshape(-1, 3)))[:, dofs])
                for i, j in enumerate(dofs):  # the same operations as one dof at a time
                    plus, minus = cols[0][:, i], cols[1][:, i]
                    first[j] = (plus - minus) / (2.0 * step[j])
                    second[j] = (plus - 2.0 * K0[:, j] + minus) / step[j] ** 2
        return sp.hstack(first).tocsr(), sp.hstack(second).tocsr()

    def single_precision(self, case: CaseInput, ref: Reference, s: Scales) -> Tolerances:
        """The case's tolerances at single precision (:mod:`conformance.judge.precision`), measured
        by the oracle on the case's coordinates carrying float32 round-off (one more oracle, on the
        perturbed mesh, not kept).
        """
        from reference_fem import UFLOracle

        def evaluate(points: np.ndarray, positions: np.ndarray):
            oracle = UFLOracle(points, case.cells, case.model)
            f, K = oracle.force_and_stiffness(positions)
            return float(oracle.energy(positions)), f, sp.csr_matrix(K)

        sens = sensitivity_of(
            evaluate, case.points, case.positions, (ref.energy, ref.force, ref.stiffness), s
        )
        return single_tolerances(sens)

    def probes(
        self, case: CaseInput, ref: Reference, probes: Sequence[CaseInput]
    ) -> ReferenceProbes:
        """The oracle's force and energy at the probes of ``case`` (same mesh and model), with
        ``ref`` at the base state: what calibrates the engine's self-consistency test.

        Raises:
            ValueError: the oracle cannot evaluate a probe (e.g. a user energy not finite there).
        """
        mesh_model = _key(case)
        key = (
            mesh_model,
            *(np.asarray(c.positions, dtype=np.float64).tobytes() for c in (case, *probes)),
        )
        if self._last_probes is not None and self._last_probes[0] == key:
            forces, energies = self._last_probes[1]
        else:
            oracle = self._oracles[mesh_model]
            forces = tuple(np.asarray(oracle.force(p.positions)) for p in probes)
            energies = tuple(float(oracle.energy(p.positions)) for p in probes)
            self._last_probes = (key, (forces, energies))
        return ReferenceProbes(ref.force, ref.stiffness, ref.energy, forces, energies)

    def parts(self, case: CaseInput):
        """:class:`conformance.judge.parts.StiffnessParts` at the case's positions."""
        key = _key(case)
        if key not in self._parts:
            self._parts[key] = PartsOracle(case.points, case.cells, case.model)
        return self._parts[key].parts(case.positions)
