"""The classical Galerkin compiled (Numba): the same per-element algebra as
:class:`reference_fem.classical.ClassicalGalerkin`, one compiled pass over the cells.

This is the like-for-like opponent of :class:`mjed.compiled.CompiledForceField`: both
compiled by the same compiler, serial, same geometry (mjed.mesh.TetMesh), same CSR pattern
(mjed.sparse.CSRPattern) written in place, fresh force and data arrays per call. The laws are
those of :mod:`reference_fem.classical_materials` (chosen by
:func:`reference_fem.classical_materials.classical_law`), lowered to an integer code and
parameters by a registry keyed by the law's type; the formulas themselves are in
:mod:`reference_fem.classical_kernels`. No MJED term code is used.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Dict, Tuple

import numpy as np
import scipy.sparse as sp

from mjed.compiled.assembly import CompiledAssembly
from mjed.compiled.availability import require_numba
from mjed.forcefield import checked_positions, refuse_inverted
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern
from reference_fem import classical_materials as cm

__all__ = ["CompiledClassicalGalerkin", "lower_law"]

# Codes and parameter layouts shared with reference_fem/classical_kernels.py (kept equal by
# tests/test_compiled_classical.py; this module must not import Numba at import time).
LAW_SVK, LAW_NEOHOOKE, LAW_DECOUPLED, LAW_OGDEN, LAW_COSTA = 0, 1, 2, 3, 4
PSI_MOONEY, PSI_VERONDA, PSI_ARRUDA = 0, 1, 2
_NO_TENSOR = np.zeros((1, 6, 6))


def _svk(law: cm.StVenantKirchhoffLaw):
    return LAW_SVK, [law.mu, law.lam], _NO_TENSOR


def _neo(law: cm.NeoHookeanLaw):
    return LAW_NEOHOOKE, [law.mu, law.lam], _NO_TENSOR


def _decoupled(psi: int, params):
    # P[0] = k0, P[1..7] psi parameters, P[8] psi kind.
    P = np.zeros(9)
    P[0] = params[0]
    P[1:1 + len(params) - 1] = params[1:]
    P[8] = psi
    return LAW_DECOUPLED, P, _NO_TENSOR


def _mooney(law: cm.MooneyRivlinLaw):
    return _decoupled(PSI_MOONEY, [law.k0, law.c1, law.c2])


def _veronda(law: cm.VerondaWestmannLaw):
    return _decoupled(PSI_VERONDA, [law.k0, law.c1, law.c2])


def _arruda(law: cm.ArrudaBoyceLaw):
    return _decoupled(PSI_ARRUDA, [law.k0, 0.0] + list(law.coef))  # P[2..6] = a_1..a_5


def _ogden(law: cm.OgdenLaw):
    return LAW_OGDEN, [law.c, law.q, law.r, law.alpha, law.k0], _NO_TENSOR


def _costa(law: cm.CostaLaw):
    return LAW_COSTA, [law.a, law.k0], np.ascontiguousarray(law.T, dtype=float)


_LOWER: Dict[type, Callable] = {cm.StVenantKirchhoffLaw: _svk, cm.NeoHookeanLaw: _neo, cm.MooneyRivlinLaw: _mooney,
                                cm.VerondaWestmannLaw: _veronda, cm.ArrudaBoyceLaw: _arruda, cm.OgdenLaw: _ogden,
                                cm.CostaLaw: _costa}


def lower_law(law: cm.ClassicalLaw) -> Tuple[int, np.ndarray, np.ndarray]:
    """(code, parameters (k,), Costa tensor (1 or m, 6, 6)) of a classical law, by its type."""
    fn = _LOWER.get(type(law))
    if fn is None:
        raise NotImplementedError(f"no compiled classical kernel for the law {type(law).__name__}; "
                                  f"supported: {', '.join(c.__name__ for c in _LOWER)}")
    code, P, T = fn(law)
    return code, np.ascontiguousarray(P, dtype=float), T


class CompiledClassicalGalerkin:
    """Energy, forces and tangent stiffness by the classical Total Lagrangian FEM, compiled.

    Same arguments and methods as :class:`reference_fem.classical.ClassicalGalerkin`
    (points may be an mjed.TetMesh with cells=None). ``backend`` is "numba".
    Raises mjed.compiled.BackendUnavailable without Numba, InvertedElementError for J <= 0.
    """

    backend = "numba"

    def __init__(self, points, cells, material, *, fix_orientation: bool = False):
        if isinstance(points, TetMesh):
            if cells is not None:
                raise ValueError("pass either a TetMesh (with cells=None) or points and cells")
            self.mesh = points
        else:
            self.mesh = TetMesh(points, cells, fix_orientation=fix_orientation)
        require_numba()
        from mjed.compiled.specialise import generated_module
        from reference_fem import classical_kernels as k

        self.material = material
        frame = getattr(material, "frame", None)
        if frame is not None and np.ndim(frame) == 3 and len(frame) != self.mesh.n_cells:
            raise ValueError(f"Costa frame has {len(frame)} rotations for {self.mesh.n_cells} cells")
        self.law = cm.classical_law(material)
        self.code, self.params, self.tensor = lower_law(self.law)
        # the isochoric part of a decoupled law (P[8]): part of what the kernel is compiled for
        self.psi = int(self.params[8]) if self.code == LAW_DECOUPLED else 0
        self._kernel = generated_module(k.kernel_source(self.code, self.psi), "classical_kernel",
                                        helpers=[Path(k.__file__)]).classical_cells
        self.pattern = CSRPattern(self.mesh.cells, self.mesh.n_nodes)
        self._cells = np.ascontiguousarray(self.mesh.cells, dtype=np.int64)
        self._D = np.ascontiguousarray(self.mesh.D, dtype=np.float64)
        self._V0 = np.ascontiguousarray(self.mesh.volumes, dtype=np.float64)
        from mjed.compiled import kernels

        self._assembly = CompiledAssembly(self.pattern, kernels)
        self._J = np.empty(self.mesh.n_cells)

    def energy(self, x) -> float:
        return self._run(x, False, False)[0]

    def force(self, x) -> np.ndarray:
        return self._run(x, True, False)[1]

    def stiffness(self, x) -> sp.csr_matrix:
        return self._run(x, False, True)[2]

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        _, f, K = self._run(x, True, True)
        return f, K

    def _run(self, x, force: bool, stiffness: bool):
        x = checked_positions(x, self.mesh.n_nodes)
        f = np.zeros((self.mesh.n_nodes, 3)) if force else np.zeros((0, 3))
        data = np.zeros(self.pattern.nnz) if stiffness else np.zeros(0)
        energy = self._kernel(x, self._cells, self._D, self._V0, self.params, self.tensor,
                                         force, stiffness, *self._assembly.arguments(), f, data, self._J)
        refuse_inverted(self._J)
        return float(energy), (f if force else None), (self._assembly.matrix(data) if stiffness else None)
