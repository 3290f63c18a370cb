"""Per-cell kinematics of P1 tetrahedra, as pure functions over arrays.

Shapes: m cells, 4 nodes per cell. F, C are (m, 3, 3); J, I1, I2 are (m,).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

__all__ = ["deformation_gradient", "cofactor", "Kinematics"]


def deformation_gradient(x_cells: np.ndarray, D: np.ndarray) -> np.ndarray:
    """F = sum_a x_a (x) D_a.

    Args:
        x_cells: (m, 4, 3) current positions of each cell's nodes.
        D: (m, 4, 3) rest shape vectors.

    Returns:
        (m, 3, 3) deformation gradients.
    """
    return np.swapaxes(x_cells, 1, 2) @ D


def cofactor(F: np.ndarray) -> np.ndarray:
    """cof F = dJ/dF = J F^-T, built from cross products so it stays finite at J <= 0.

    Args:
        F: (m, 3, 3).

    Returns:
        (m, 3, 3); column k is the cross product of the two other columns of F.
    """
    c0, c1, c2 = F[:, :, 0], F[:, :, 1], F[:, :, 2]
    return np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=2)


class Kinematics:
    """Strain measures of every cell at one state, each computed on first use.

    Invariant functions of the materials read what they need from here, so a quantity used
    by several terms (C, I1, I2, ...) is computed once per evaluation.
    """

    def __init__(self, F: np.ndarray):
        self.F = F

    @cached_property
    def cof(self) -> np.ndarray:
        """(m, 3, 3) cofactor matrix J F^-T."""
        return cofactor(self.F)

    @cached_property
    def J(self) -> np.ndarray:
        """(m,) det F."""
        return np.einsum("mi,mi->m", self.F[:, :, 0], self.cof[:, :, 0])

    @cached_property
    def C(self) -> np.ndarray:
        """(m, 3, 3) right Cauchy-Green tensor F^T F."""
        return np.swapaxes(self.F, 1, 2) @ self.F

    @cached_property
    def I1(self) -> np.ndarray:
        """(m,) tr C."""
        return np.einsum("mii->m", self.C)

    @cached_property
    def I2(self) -> np.ndarray:
        """(m,) (I1^2 - tr C^2) / 2."""
        return 0.5 * (self.I1**2 - np.einsum("mij,mij->m", self.C, self.C))

    @cached_property
    def E(self) -> np.ndarray:
        """(m, 3, 3) Green-Lagrange strain (C - I) / 2."""
        E = 0.5 * self.C
        E[:, [0, 1, 2], [0, 1, 2]] -= 0.5
        return E

    @cached_property
    def eig(self) -> "tuple[np.ndarray, np.ndarray]":
        """Eigenvalues (m, 3), ascending, and eigenvectors (m, 3, 3) (columns) of C."""
        return np.linalg.eigh(self.C)
