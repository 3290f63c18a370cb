"""Both compiled kernels (MJED and the classical Galerkin) against the UFL oracle, to the
equivalence study's tolerances (1e-10), for every material: per element on random single
tetrahedra and assembled on the small cube in every state.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx (Debian: python3-dolfinx)")
pytestmark = pytest.mark.oracle

from conftest import perturbed, random_tetrahedron  # noqa: E402

import mjed  # noqa: E402
from common.tolerances import FORCE_TOL, STIFFNESS_TOL  # noqa: E402
from comparisons.equivalence.study import compare_arrays  # noqa: E402
from mjed.compiled import numba_available  # noqa: E402
from reference_fem import UFLOracle  # noqa: E402

if not numba_available():
    pytest.skip(
        "the compiled backend needs Numba (Debian: python3-numba; PyPI: numba)",
        allow_module_level=True,
    )


def _compiled(kind, mesh, material):
    if kind == "mjed":
        return mjed.make_force_field(mesh, material, backend="numba")
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    return CompiledClassicalGalerkin(mesh, None, material)


@pytest.mark.parametrize("kind", ["mjed", "classical"])
@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_per_element_against_oracle(material, kind, seed):
    rng = np.random.default_rng(seed)
    P, cells = random_tetrahedron(rng)
    x = perturbed(P, rng, 0.1)
    oracle = UFLOracle(P, cells, material)
    field = _compiled(kind, mjed.TetMesh(P, cells), material)
    f, K = field.force_and_stiffness(x)
    fe, ke, se = compare_arrays(f, K, oracle.force(x), oracle.stiffness(x), 0.1)
    assert fe <= FORCE_TOL and ke <= STIFFNESS_TOL and se <= 1e-12, (fe, ke, se)
    assert np.isclose(
        field.energy(x), oracle.energy(x), rtol=1e-12, atol=1e-14 * abs(oracle.energy(x))
    )


@pytest.mark.parametrize("kind", ["mjed", "classical"])
def test_compiled_assembled_against_oracle_on_the_small_cube_in_every_state(kind):
    pytest.importorskip("meshio", reason="cube-small is stored as a gmsh file")
    import meshes
    from common.cases import DEFAULT_MATERIALS
    from common.states import apply_state, state_names

    points, cells = meshes.load("cube-small")
    mesh = mjed.TetMesh(points, cells)
    edge = float(np.mean(np.linalg.norm(points[cells[:, 1]] - points[cells[:, 0]], axis=1)))
    worst = []
    for name, material in DEFAULT_MATERIALS.items():
        field = _compiled(kind, mesh, material)
        oracle = UFLOracle(points, cells, material)
        for state in state_names():
            x = apply_state(state, points, cells)
            f, K = field.force_and_stiffness(x)
            fe, ke, _ = compare_arrays(f, K, oracle.force(x), oracle.stiffness(x), edge)
            worst.append((max(fe, ke), name, state))
    bad = [w for w in worst if not w[0] <= max(FORCE_TOL, STIFFNESS_TOL)]
    assert not bad, bad
    assert len(worst) == len(DEFAULT_MATERIALS) * len(state_names())
