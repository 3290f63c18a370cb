"""A spatial tangent built by Miehe's perturbation of F, with one-sided differences.

An updated-Lagrangian engine that computes its spatial tangent column by column as

    c e_kl = (tau(F + eps E_kl F) - tau(F)) / (J eps) - (the Jaumann rate's terms),

E_kl = sym(e_k e_l) (Miehe 1996; the usual way to a UMAT's DDSDDE), has in column kl the error
(eps / 2) tau''_kl / J + O(eps^2), tau''_kl the second derivative of the Kirchhoff stress along
the path F(t) = (I + t E_kl) F. This is another error than that of differences of S in the
strain (:mod:`conformance.diagnosis.strain_differences`), so it is tested on its own: tau''
per cell by second differences of the oracle's stress (MJED's element forces on the mesh with
its cells pulled apart, each cell's F moved along the path), the stiffness v B^T c_lead B of
the leading error assembled (B from grad N = D F^-1, v = J V0), and eps fitted with one
unknown (forward: eps > 0, backward: eps < 0) by
:func:`conformance.diagnosis.strain_differences.strain_difference_reading`, beside the strain
scheme: named, as partly explaining, when the fit accounts for nearly all of the stiffness error
(99 %), as the other difference readings are; both fitting are said as ambiguous.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np
import scipy.sparse as sp

from conformance.diagnosis.elements import ElementSplit, assemble, cell_piola
from conformance.diagnosis.spatial_variants import FEBIO, from_voigt

__all__ = ["STEP", "kirchhoff_curvatures", "perturbation_basis"]

#: Step of the second differences of tau along the path (dimensionless, like eps).
STEP = 1e-3


def _sym_unit(k: int, l: int) -> np.ndarray:  # noqa: E741 - the index names of the formula
    """(3, 3) E_kl = (e_k e_l^T + e_l e_k^T) / 2."""
    E = np.zeros((3, 3))
    E[k, l] += 0.5
    E[l, k] += 0.5
    return E


def kirchhoff_curvatures(
    model: Any, split: ElementSplit, points: np.ndarray
) -> Optional[np.ndarray]:
    """(m, 6, 6) per cell tau''_kl / J in Voigt form: row I the pair I of tau'', column the
    perturbation kl (both in FEBio order); None when MJED cannot evaluate the model there.
    """
    import mjed

    cells, F = split.cells, split.F
    m = cells.shape[0]
    X = points[cells]
    loose = np.arange(4 * m).reshape(m, 4)
    Xc = X - X[:, :1]
    J = np.linalg.det(F)
    rows = np.array(FEBIO)
    out = np.empty((m, 6, 6))
    Dp = np.linalg.pinv(split.D)  # (m, 3, 4): P from the element forces, f_a = -V0 P D_a

    def tau(field, Fs: np.ndarray) -> np.ndarray:
        """(m, 3, 3) the oracle's Kirchhoff stress P F^T at per-cell gradients Fs."""
        xs = (np.einsum("mij,maj->mai", Fs, Xc) + X[:, :1]).reshape(-1, 3)
        fe = np.asarray(field.element_forces(xs), dtype=np.float64)
        P = -np.einsum("mja,mak->mkj", Dp, fe) / split.V0[:, None, None]
        return P @ Fs.swapaxes(1, 2)

    try:
        field = mjed.make_force_field(mjed.TetMesh(X.reshape(-1, 3), loose), model)
        t0 = cell_piola(split)[0] @ F.swapaxes(1, 2)
        for col, (k, l) in enumerate(FEBIO):  # noqa: E741
            step = STEP * _sym_unit(k, l)
            tp = tau(field, (np.eye(3) + step) @ F)
            tm = tau(field, (np.eye(3) - step) @ F)
            d2 = (tp + tm - 2.0 * t0) / STEP**2
            out[:, :, col] = d2[:, rows[:, 0], rows[:, 1]] / J[:, None]
    except Exception:  # noqa: BLE001 - not an MJED material, or an inverted moved cell
        return None
    return out


def perturbation_basis(split: ElementSplit, curv: np.ndarray) -> sp.csr_matrix:
    """(3n, 3n) the assembled v B^T c_lead B of the leading error per unit step, c_lead the
    tensor of (1/2) curv (m, 6, 6) from :func:`kirchhoff_curvatures`.
    """
    gN = split.D @ np.linalg.inv(split.F)
    v = np.linalg.det(split.F) * split.V0
    lead = from_voigt(0.5 * curv)  # column kl's error per unit step
    Ke = np.einsum("m,maj,mijkl,mbl->maibk", v, gN, lead, gN, optimize=True)
    m = split.cells.shape[0]
    return assemble(split.cells, split.n, np.zeros((m, 4, 3)), Ke.reshape(m, 12, 12))[1]
