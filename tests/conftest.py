"""Shared fixtures: small NumPy-built meshes (no gmsh needed) and the material set."""

from __future__ import annotations

import numpy as np
import pytest

import mjed
from mjed import materials as M

# One parameter set per material, chosen so that every term of each energy matters (and a
# second one where the sign of a parameter changes the kernel or the split). Every declared
# material must have one: tests/test_material_declarations.py checks it.
MATERIALS = {
    "StVenantKirchhoff": M.StVenantKirchhoff(mu=1.3, lam=2.1),
    "NeoHookean": M.NeoHookean(mu=1.3, lam=2.1),
    "MooneyRivlin": M.MooneyRivlin(c1=0.7, c2=0.4, k0=5.0),
    "VerondaWestmann": M.VerondaWestmann(c1=0.8, c2=1.2, k0=5.0),
    "ArrudaBoyce": M.ArrudaBoyce(mu=1.0, k0=5.0),
    "Costa": M.Costa(a=0.9, k0=3.0, b_ff=1.0, b_fs=0.3, b_ss=0.8, b_fn=0.2, b_sn=0.1, b_nn=0.5),
    "CostaIndefinite": M.Costa(
        a=0.9, k0=3.0, b_ff=1.0, b_fs=0.9, b_ss=0.5, b_fn=0.2, b_sn=0.1, b_nn=0.5
    ),
    "Ogden": M.Ogden(mu=1.0, alpha=3.0, k0=5.0),
    "OgdenNegative": M.Ogden(mu=1.0, alpha=-2.0, k0=5.0),
    "Yeoh": M.Yeoh(c10=0.6, c20=-0.15, c30=0.2, k0=5.0),
    # Jm above the largest I1b - 3 of the test states (about 20, on the perturbed box of
    # test_engine_modules), close enough that the logarithm bends: 1 - (I1b - 3)/Jm falls to 0.3
    "Gent": M.Gent(mu=1.2, Jm=30.0, k0=5.0),
}


def box_mesh(n: int = 2, *, jitter: float = 0.0, seed: int = 0):
    """Unit cube split into n^3 sub-cubes of 6 tetrahedra each, nodes optionally jittered.

    Returns points (n_nodes, 3) and positively oriented cells (m, 4).
    """
    g = np.linspace(0.0, 1.0, n + 1)
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    points = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    if jitter:
        rng = np.random.default_rng(seed)
        interior = np.all((points > 0) & (points < 1), axis=1)
        points[interior] += jitter / n * rng.uniform(-1, 1, size=(interior.sum(), 3))
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    corners = np.stack(
        [
            idx[i : n + i, j : n + j, k : n + k].ravel()
            for i, j, k in [
                (0, 0, 0),
                (1, 0, 0),
                (1, 1, 0),
                (0, 1, 0),
                (0, 0, 1),
                (1, 0, 1),
                (1, 1, 1),
                (0, 1, 1),
            ]
        ],
        axis=1,
    )
    split = [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6)]
    cells = np.concatenate([corners[:, list(t)] for t in split])
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    neg = np.einsum("mi,mi->m", e[:, 0], np.cross(e[:, 1], e[:, 2])) < 0
    cells[neg, 2], cells[neg, 3] = cells[neg, 3], cells[neg, 2].copy()
    return points, cells


def random_tetrahedron(rng):
    """A random, reasonably shaped, positively oriented single tetrahedron."""
    while True:
        P = rng.uniform(-1, 1, size=(4, 3))
        e = P[1:] - P[0]
        vol = np.linalg.det(e.T) / 6
        if abs(vol) > 0.05:
            cells = np.array([[0, 1, 2, 3]]) if vol > 0 else np.array([[0, 2, 1, 3]])
            return P, cells


def perturbed(points, rng, scale=0.08):
    return points + scale * rng.standard_normal(points.shape)


def deformed_cube(n: int = 3, *, seed: int = 7, scale: float = 0.06):
    """A jittered n x n x n box (a TetMesh) and positions perturbed from its rest points: the
    compiled kernels' tests' mesh.
    """
    points, cells = box_mesh(n, jitter=0.3)
    return mjed.TetMesh(points, cells), perturbed(points, np.random.default_rng(seed), scale)


def relative_difference(a, b) -> float:
    """||a - b|| / ||b||, Frobenius, of two arrays."""
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(np.asarray(b))


@pytest.fixture(params=sorted(MATERIALS))
def material(request):
    return MATERIALS[request.param]


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def parse_reproduce(line: str) -> dict:
    """The options a result's reproduce line sets, parsed back by the real mjed-verify parser."""
    import shlex

    from comparisons.cli import build_parser

    words = shlex.split(line, comments=True)
    assert words[0] == "mjed-verify", line
    return vars(build_parser().parse_args(words[1:]))
