"""The compiled kernel run in parallel over cells (CompiledForceField(parallel=True)) against
the serial kernel and the NumPy engine, and the colouring that makes it race-free.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS, deformed_cube, relative_difference

import mjed
from mjed.compiled import numba_available

pytestmark = pytest.mark.skipif(
    not numba_available(),
    reason="the compiled backend needs Numba (Debian: python3-numba; PyPI: numba)",
)


@pytest.fixture(scope="module")
def cube():
    return deformed_cube()


# The cell body is the serial kernel's (tests/test_compiled.py runs it on every material);
# what the parallel kernel adds is the schedule, the per-cell arrays in its order and the
# threads. Three materials cover what that can touch: scalar terms (NeoHookean), the
# per-cell eigen-decomposition and divided differences (Ogden), fibre frames and several
# tangent slots (Costa). Each parallel kernel compiles in about 30 s.
PARALLEL_MATERIALS = ("NeoHookean", "Ogden", "Costa")


@pytest.mark.parametrize("regularize", [False, True])
@pytest.mark.parametrize("name", PARALLEL_MATERIALS)
def test_parallel_equals_numpy_engine(name, regularize, cube):
    # slabs=5: thin slabs on a 3x3x3 box, so several colours and slabs of unequal sizes
    mesh, x = cube
    material = MATERIALS[name]
    ref = mjed.make_force_field(mesh, material, regularize=regularize)
    par = mjed.make_force_field(
        mesh, material, backend="numba", regularize=regularize, parallel=True, slabs=5
    )
    assert par.parallel and par.schedule.n_colours >= 2
    f_r, K_r = ref.force_and_stiffness(x)
    f_p, K_p = par.force_and_stiffness(x)
    assert relative_difference(f_p, f_r) < 1e-13
    assert abs(K_p - K_r).max() <= 1e-13 * abs(K_r).max()
    assert np.array_equal(K_p.indptr, K_r.indptr) and np.array_equal(K_p.indices, K_r.indices)
    assert par.energy(x) == pytest.approx(ref.energy(x), rel=1e-13)
    # per-cell outputs back in the caller's order
    assert relative_difference(par.stress(x), ref.stress(x)) < 1e-13
    assert np.array_equal(par.force(x), f_p) and abs(par.stiffness(x) - K_p).max() == 0.0


def test_parallel_per_cell_frame_and_inverted_cells(cube):
    from scipy.spatial.transform import Rotation

    mesh, x = cube
    R = Rotation.random(mesh.n_cells, random_state=3).as_matrix()
    base = MATERIALS["Costa"]
    mat = type(base)(
        **{
            k: getattr(base, k) for k in ("a", "k0", "b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")
        },
        frame=R,
    )
    f_r, K_r = mjed.make_force_field(mesh, mat).force_and_stiffness(x)
    f_p, K_p = mjed.make_force_field(
        mesh, mat, backend="numba", parallel=True, slabs=3
    ).force_and_stiffness(x)
    assert relative_difference(f_p, f_r) < 1e-13 and abs(K_p - K_r).max() <= 1e-13 * abs(K_r).max()
    y = mesh.points.copy()
    y[mesh.cells[5, 0]] = y[mesh.cells[5, 1:]].mean(axis=0) * 2 - y[mesh.cells[5, 0]]  # flip cell 5
    with pytest.raises(mjed.InvertedElementError, match="cell 5 "):
        mjed.make_force_field(mesh, MATERIALS["NeoHookean"], backend="numba", parallel=True).force(
            y
        )


@pytest.mark.parametrize("slabs", [1, 2, 4, 7, 40])
def test_schedule_is_a_colouring_of_a_permutation(cube, slabs):
    from mjed.compiled.schedule import cell_schedule

    mesh, _ = cube
    sch = cell_schedule(mesh.points, mesh.cells, slabs)
    assert np.array_equal(np.sort(sch.cell_id), np.arange(mesh.n_cells))
    assert (
        sch.chunk_ptr[0] == 0
        and sch.chunk_ptr[-1] == mesh.n_cells
        and np.all(np.diff(sch.chunk_ptr) > 0)
    )
    cells = mesh.cells[sch.cell_id]
    for c in range(sch.n_colours):  # no node in two chunks of one colour
        owner = {}
        for k in range(sch.colour_ptr[c], sch.colour_ptr[c + 1]):
            for node in np.unique(cells[sch.chunk_ptr[k] : sch.chunk_ptr[k + 1]]):
                assert owner.setdefault(node, k) == k
    if slabs <= 4:
        assert sch.n_colours <= 3  # slabs thicker than a cell: few synchronisations


def test_parallel_field_on_the_liver_matches_serial():
    # an irregular mesh, several threads' worth of slabs
    from meshes import catalog

    points, cells = catalog.load("liver-coarse")
    mesh = mjed.TetMesh(points, cells)
    x = points * [1.02, 0.99, 1.0]
    mat = MATERIALS["NeoHookean"]
    f_s, K_s = mjed.make_force_field(mesh, mat, backend="numba").force_and_stiffness(x)
    f_p, K_p = mjed.make_force_field(
        mesh, mat, backend="numba", parallel=True, slabs=8
    ).force_and_stiffness(x)
    assert relative_difference(f_p, f_s) < 1e-13 and abs(K_p - K_s).max() <= 1e-13 * abs(K_s).max()
