"""The classical "standard FEM" MJED is compared against: Total Lagrangian P1 tetrahedra.

Per element (Zienkiewicz & Taylor vol. 2, Bonet & Wood), with F = sum_a x_a (x) D_a, C = F^T F::

    S = 2 dW/dC, CC = 2 dS/dC (6x6 Voigt)        from reference_fem.classical_materials
    B_a (6x3): engineering Green-Lagrange strain rate per node velocity,
               dE_eng = sum_a B_a dx_a, rows (xx, yy, zz, 2xy, 2yz, 2xz):
               B_a[(i, j), k] = D_a,j F_ki + D_a,i F_kj (halved for i = j)
    f_a  = -V0 F S D_a  (= -V0 B_a^T S_v)
    K_ab = V0 [ B_a^T CC B_b + (D_a . S D_b) Id ]   (material + geometric stiffness)

This is the structure of SOFA's StandardTetrahedralFEMForceField, vectorised
over elements: CC as (m, 6, 6), B as (m, 6, 12), K_e = B^T (CC B) by batched matmul. Only the
geometry (mjed.mesh.TetMesh: D, V0) and the CSR scatter (mjed.sparse.CSRPattern) are shared
with mjed; no MJED term code is used.

Conventions (docs/conventions.md): f = -dW/dx (n, 3); K = d2W/dx2, CSR (3n, 3n), dof = 3 node +
comp.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np
import scipy.sparse as sp

from mjed.errors import InvertedElementError
from mjed.mesh import TetMesh
from mjed.sparse import CSRPattern
from reference_fem.classical_materials import VI, VJ, ClassicalLaw, classical_law

__all__ = ["ClassicalGalerkin", "strain_displacement"]


def strain_displacement(
    F: np.ndarray, D: np.ndarray, out: "np.ndarray | None" = None
) -> np.ndarray:
    """The Total Lagrangian B matrices of all nodes, stacked as (m, 6, 12).

    Column 3 a + k of cell m is B_a[:, k]: dE_eng = B @ dx_e with dx_e the (12,) element
    displacement increment (node-major) and E_eng = (Exx, Eyy, Ezz, 2Exy, 2Eyz, 2Exz).
    out: optional (m, 6, 12) array to write into.
    """
    m = len(F)
    # F[:, :, VI] is (m, 3, 6) with [k, I] = F_k,i(I); D[:, :, VJ] is (m, 4, 6) with [a, I] =
    # D_a,j(I).
    Fi, Fj = np.swapaxes(F[:, :, VI], 1, 2), np.swapaxes(F[:, :, VJ], 1, 2)  # (m, 6, 3)
    Di, Dj = np.swapaxes(D[:, :, VI], 1, 2), np.swapaxes(D[:, :, VJ], 1, 2)  # (m, 6, 4)
    B = (np.empty((m, 6, 12)) if out is None else out).reshape(m, 6, 4, 3)
    np.multiply(Dj[:, :, :, None], Fi[:, :, None, :], out=B)
    B += Di[:, :, :, None] * Fj[:, :, None, :]
    B[:, :3] *= 0.5
    return B.reshape(m, 6, 12)


class ClassicalGalerkin:
    """Energy, nodal forces and tangent stiffness by the classical Total Lagrangian FEM.

    Args:
        points: (n, 3) rest positions.
        cells: (m, 4) positively oriented P1 tetrahedra.
        material: a declared mjed material (mjed.materials); its law is the form its declaration
            gives (classical_law). Ogden's ``tangent`` option is ignored (always exact).
        fix_orientation: passed to mjed.TetMesh.

    ``points`` may also be an mjed.TetMesh, with ``cells=None``, to share one validated mesh.

    Raises InvertedElementError (mjed.errors) for states with J <= 0 in some cell.
    """

    def __init__(self, points, cells, material, *, fix_orientation: bool = False):
        if isinstance(points, TetMesh):  # an already validated mesh (cells must then be None)
            if cells is not None:
                raise ValueError("pass either a TetMesh (with cells=None) or points and cells")
            self.mesh = points
        else:
            self.mesh = TetMesh(points, cells, fix_orientation=fix_orientation)
        self.material = material
        frame = getattr(material, "frame", None)
        if frame is not None and np.ndim(frame) == 3 and len(frame) != self.mesh.n_cells:
            raise ValueError(
                f"Costa frame has {len(frame)} rotations for {self.mesh.n_cells} cells"
            )
        self.law: ClassicalLaw = classical_law(material)
        self._pattern: "CSRPattern | None" = None
        # Work arrays of force_and_stiffness / stiffness, kept between calls: the same memory
        # reuse as mjed's engine, so that neither pays page faults for fresh temporaries.
        self._work: dict = {}

    @property
    def pattern(self) -> CSRPattern:
        if self._pattern is None:
            self._pattern = CSRPattern(self.mesh.cells, self.mesh.n_nodes)
        return self._pattern

    # ---------------------------------------------------------------- public API
    def energy(self, x) -> float:
        """Total strain energy sum_cells V0 W."""
        F, J = self._kinematics(x)
        C = np.swapaxes(F, 1, 2) @ F
        return float(self.mesh.volumes @ self.law.energy(C, J))

    def second_piola_kirchhoff(self, x) -> np.ndarray:
        """Per-cell S, (m, 3, 3)."""
        F, J = self._kinematics(x)
        return self.law.stress(np.swapaxes(F, 1, 2) @ F, J)

    def element_forces(self, x) -> np.ndarray:
        """Per-cell nodal forces -V0 F S D_a, (m, 4, 3)."""
        F, J = self._kinematics(x)
        S = self.law.stress(np.swapaxes(F, 1, 2) @ F, J)
        return self._element_forces(F, S)

    def force(self, x) -> np.ndarray:
        """Nodal forces -dW/dx, (n, 3)."""
        return self.pattern.assemble_vector(self.element_forces(x))

    def element_stiffness(self, x) -> np.ndarray:
        """Element stiffness matrices (m, 12, 12), dof order (node 0: x, y, z, node 1: ...)."""
        return self._element_force_and_stiffness(x)[1]

    def stiffness(self, x) -> sp.csr_matrix:
        """Tangent stiffness d2W/dx2, CSR (3n, 3n)."""
        return self.pattern.assemble_matrix(self._element_force_and_stiffness(x, reuse=True)[1])

    def force_and_stiffness(self, x) -> Tuple[np.ndarray, sp.csr_matrix]:
        """Both from one evaluation of the kinematics and the material."""
        fe, Ke = self._element_force_and_stiffness(x, reuse=True)
        return self.pattern.assemble_vector(fe), self.pattern.assemble_matrix(Ke)

    # ---------------------------------------------------------------- internals
    def _kinematics(self, x):
        x = np.asarray(x, dtype=np.float64)
        n = self.mesh.n_nodes
        if x.shape != (n, 3):
            raise ValueError(f"positions must have shape ({n}, 3), got {x.shape}")
        if not np.isfinite(x).all():
            raise ValueError("positions must be finite")
        F = np.swapaxes(x[self.mesh.cells], 1, 2) @ self.mesh.D  # F_ki = sum_a x_a,k D_a,i
        J = (
            F[:, 0, 0] * (F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1])
            - F[:, 0, 1] * (F[:, 1, 0] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 0])
            + F[:, 0, 2] * (F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0])
        )
        bad = np.flatnonzero(~(J > 0))
        if len(bad):
            raise InvertedElementError(bad, J[bad], context="at the given positions")
        return F, J

    def _element_forces(self, F, S):
        # f_a,k = -V0 sum_ij F_ki S_ij D_a,j: rows of D (F S)^T.
        return -self.mesh.volumes[:, None, None] * (self.mesh.D @ np.swapaxes(F @ S, 1, 2))

    def _buffer(self, name: str, shape: tuple, reuse: bool):
        if not reuse:
            return None
        a = self._work.get(name)
        if a is None or a.shape != shape:
            a = self._work[name] = np.empty(shape)
        return a

    def _element_force_and_stiffness(self, x, reuse: bool = False):
        """reuse: write B, CC B and K_e into kept work arrays (K_e is then only valid until
        the next call: for callers that assemble it at once).
        """
        F, J = self._kinematics(x)
        S, CC = self.law.stress_and_tangent(np.swapaxes(F, 1, 2) @ F, J)
        D, V0 = self.mesh.D, self.mesh.volumes
        m = len(F)
        B = strain_displacement(F, D, out=self._buffer("B", (m, 6, 12), reuse))  # (m, 6, 12)
        CB = np.matmul(CC, B, out=self._buffer("CB", (m, 6, 12), reuse))
        K = np.matmul(
            np.swapaxes(B, 1, 2), CB, out=self._buffer("K", (m, 12, 12), reuse)
        )  # material part
        G = D @ S @ np.swapaxes(D, 1, 2)  # (m, 4, 4): D_a . S D_b
        K4 = K.reshape(m, 4, 3, 4, 3)
        for k in range(3):
            K4[:, :, k, :, k] += G
        K *= V0[:, None, None]
        return self._element_forces(F, S), K
