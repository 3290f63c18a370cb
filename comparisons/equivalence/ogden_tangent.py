"""How far SOFA's coaxial Ogden tangent is from the exact Hessian (teaching material).

SOFA's MJED Ogden approximates d(C^p)/dC : H by p C^((p-1)/2) H C^((p-1)/2), which is exact only
when H commutes with C. Forces are unaffected; the stiffness is not the Hessian.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Dict, Sequence

from scipy.sparse.linalg import norm as sparse_norm

import mjed
from common.states import apply_state

__all__ = ["sofa_tangent_errors"]


def sofa_tangent_errors(
    mesh: mjed.TetMesh, material: mjed.materials.Ogden, states: Sequence[str]
) -> Dict[str, float]:
    """||K_sofa - K_exact||_F / ||K_exact||_F for each state."""
    exact = mjed.HyperelasticForceField(mesh, replace(material, tangent="exact"))
    approx = mjed.HyperelasticForceField(mesh, replace(material, tangent="sofa"))
    out = {}
    for s in states:
        x = apply_state(s, mesh.points, mesh.cells)
        K = exact.stiffness(x)
        out[s] = float(sparse_norm(approx.stiffness(x) - K) / sparse_norm(K))
    return out
