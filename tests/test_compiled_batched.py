"""The cell-batched compiled kernel (CompiledForceField(batch=B), mjed.compiled.batched)
against the kernel that runs one cell at a time and the NumPy engine, serial and parallel.

The batched kernel runs the same generated cell body, the same operations in the same order
(no fastmath), and adds into the sums in cell order: its results must equal the one-cell
kernel's bit for bit, and the NumPy engine's to round-off. The meshes' cell counts (162) are
not multiples of the batches, so the last batch of every range is a padded one.

What compiles: the batch size is a compile-time constant of a batched kernel (the vectoriser
proves from the constant distances between its rows that results never overwrite inputs; see
BatchTarget._one_buffer), so each material, batch size and serial or parallel form is a kernel
of its own (25 to 110 s to compile on the 2-core test machine). The tests therefore use the
batch size the project runs, DEFAULT_BATCH, wherever the batch size is not what they check
(one kernel per material shared by every test), and the default run checks every material
serially, the parallel form and each batch-size regime once; the tests marked ``sweep`` (run
by ``make test-sweep``) repeat the parallel form on two more materials and add one more batch
size, with the same tolerances.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS, deformed_cube, relative_difference

import mjed
from mjed.compiled import CompiledForceField, numba_available
from mjed.compiled.batched import DEFAULT_BATCH

pytestmark = pytest.mark.skipif(
    not numba_available(),
    reason="the compiled backend needs Numba (Debian: python3-numba; PyPI: numba)",
)


@pytest.fixture(scope="module")
def cube():
    return deformed_cube()


def _same(field, one_cell, ref, x):
    """The batched field equals one_cell exactly and ref (NumPy) to round-off, every output."""
    f, K, S = field.force_stiffness_and_stress(x)
    f1, K1, S1 = one_cell.force_stiffness_and_stress(x)
    assert np.array_equal(f, f1) and np.array_equal(S, S1)
    assert np.array_equal(K.indptr, K1.indptr) and np.array_equal(K.indices, K1.indices)
    assert np.array_equal(K.data, K1.data)
    assert field.energy(x) == one_cell.energy(x)
    f_r, K_r = ref.force_and_stiffness(x)
    assert relative_difference(f, f_r) < 1e-13
    assert abs(K - K_r).max() <= 1e-13 * abs(K_r).max()
    assert field.energy(x) == pytest.approx(ref.energy(x), rel=1e-13)
    assert relative_difference(S, ref.stress(x)) < 1e-13
    # the single-purpose entry points (other lanes functions) agree with the combined one
    assert np.array_equal(field.force(x), f) and np.array_equal(field.stress(x), S)
    assert abs(field.stiffness(x) - K).max() == 0.0


@pytest.mark.parametrize("regularize", [False, True])
def test_batched_equals_one_cell_kernel_and_numpy(material, regularize, cube):
    mesh, x = cube
    opts = dict(regularize=regularize)
    field = CompiledForceField(mesh, material, batch=DEFAULT_BATCH, **opts)
    assert field.batch == DEFAULT_BATCH
    _same(
        field,
        CompiledForceField(mesh, material, **opts),
        mjed.make_force_field(mesh, material, **opts),
        x,
    )


def _parallel_case(name, regularize, cube):
    # slabs=5: four colours, slabs of 33 and 32 cells (some a whole number of batches, some
    # ending in a padded batch)
    mesh, x = cube
    material = MATERIALS[name]
    opts = dict(regularize=regularize, parallel=True, slabs=5)
    field = CompiledForceField(mesh, material, batch=DEFAULT_BATCH, **opts)
    assert field.parallel and field.schedule.n_colours >= 2
    _same(
        field,
        CompiledForceField(mesh, material, **opts),
        mjed.make_force_field(mesh, material, regularize=regularize),
        x,
    )


@pytest.mark.parametrize("regularize", [False, True])
def test_batched_parallel_equals_parallel_kernel_and_numpy(regularize, cube):
    """The parallel batched kernel (Neo-Hookean): its schedule, slabs and padded batches."""
    _parallel_case("NeoHookean", regularize, cube)


@pytest.mark.sweep
@pytest.mark.parametrize("regularize", [False, True])
@pytest.mark.parametrize("name", ("Ogden", "Costa"))
def test_batched_parallel_sweep(name, regularize, cube):
    """Full sweep (make test-sweep): the parallel batched kernel of two more materials. The
    parallel form differs from the serial one only in its driver and cell order, which do not
    depend on the material (checked on Neo-Hookean above); Ogden's hoisted eigen pass and
    Costa's fibre frame are checked in the batched kernel serially (every material above).
    """
    _parallel_case(name, regularize, cube)


def _any_batch_size(batch, cube):
    mesh, x = cube
    mat = MATERIALS["NeoHookean"]
    _same(
        CompiledForceField(mesh, mat, batch=batch, regularize=True),
        CompiledForceField(mesh, mat, regularize=True),
        mjed.make_force_field(mesh, mat, regularize=True),
        x,
    )


@pytest.mark.parametrize("batch", [1, DEFAULT_BATCH, 256])
def test_any_batch_size(batch, cube):
    """One lane (no vector loop); the default (its last batch padded); a batch larger than
    the mesh (one padded batch).
    """
    _any_batch_size(batch, cube)


@pytest.mark.sweep
def test_any_batch_size_sweep(cube):
    """Full sweep (make test-sweep): a batch size that divides nothing and is no multiple of
    a vector's width (its last batch padded, as the default's above).
    """
    _any_batch_size(5, cube)


def test_batched_per_cell_frame(cube):
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
    _same(
        CompiledForceField(mesh, mat, batch=DEFAULT_BATCH),
        CompiledForceField(mesh, mat),
        mjed.make_force_field(mesh, mat),
        x,
    )


def test_batched_refuses_inverted_cells_naming_them(cube):
    mesh, _ = cube
    y = mesh.points.copy()
    y[mesh.cells[5, 0]] = y[mesh.cells[5, 1:]].mean(axis=0) * 2 - y[mesh.cells[5, 0]]  # flip cell 5
    for parallel in (False, True):
        field = mjed.make_force_field(
            mesh, MATERIALS["NeoHookean"], backend="numba", batch=DEFAULT_BATCH, parallel=parallel
        )
        with pytest.raises(mjed.InvertedElementError, match="cell 5 "):
            field.force(y)


def test_batch_must_not_be_negative(cube):
    mesh, _ = cube
    with pytest.raises(ValueError, match="batch"):
        CompiledForceField(mesh, MATERIALS["NeoHookean"], batch=-1)


def test_batched_ogden_with_sofas_coaxial_tangent(cube):
    # the other eigen tangent: its powers of the eigenvalues stay in the lanes (one libm call
    # per lane), the exact one's divided differences are computed in the gather pass
    mesh, x = cube
    mat = mjed.materials.Ogden(mu=1.0, alpha=3.0, k0=5.0, tangent="sofa")
    _same(
        CompiledForceField(mesh, mat, batch=DEFAULT_BATCH, regularize=True),
        CompiledForceField(mesh, mat, regularize=True),
        mjed.make_force_field(mesh, mat, regularize=True),
        x,
    )
