"""The compiled (Numba) backend against the NumPy engine, for every material and both
regularisation settings, plus its interface: backend choice, errors, no Numba at import.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import MATERIALS, deformed_cube, relative_difference

import mjed
from mjed.compiled import numba_available
from mjed.compiled.batched import DEFAULT_BATCH

needs_numba = pytest.mark.skipif(
    not numba_available(),
    reason="the compiled backend needs Numba (Debian: python3-numba; PyPI: numba)",
)


@pytest.fixture(scope="module")
def cube():
    return deformed_cube()


@needs_numba
@pytest.mark.parametrize("regularize", [False, True])
def test_compiled_equals_numpy_engine(material, regularize, cube):
    mesh, x = cube
    ref = mjed.make_force_field(mesh, material, regularize=regularize)
    comp = mjed.make_force_field(mesh, material, backend="numba", regularize=regularize)
    assert ref.backend == "numpy" and comp.backend == "numba"
    f_r, K_r = ref.force_and_stiffness(x)
    f_c, K_c = comp.force_and_stiffness(x)
    assert relative_difference(f_c, f_r) < 1e-13
    assert abs(K_c - K_r).max() <= 1e-13 * abs(K_r).max()
    assert np.array_equal(K_c.indptr, K_r.indptr) and np.array_equal(K_c.indices, K_r.indices)
    assert comp.energy(x) == pytest.approx(ref.energy(x), rel=1e-13)
    # the single-purpose entry points agree with the combined one
    assert np.array_equal(comp.force(x), f_c)
    assert abs(comp.stiffness(x) - K_c).max() == 0.0


@needs_numba
def test_compiled_sees_a_compressed_state_and_regularisation_changes_it(cube):
    # Not vacuous: the state has compressed cells, where the regularised tangent differs.
    mesh, x = cube
    mat = MATERIALS["NeoHookean"]
    x = mesh.points + 0.7 * (x - mesh.points)
    x[:, 2] *= 0.8
    K0 = mjed.make_force_field(mesh, mat, backend="numba").stiffness(x)
    K1 = mjed.make_force_field(mesh, mat, backend="numba", regularize=True).stiffness(x)
    assert abs(K1 - K0).max() > 1e-6 * abs(K0).max()


@needs_numba
def test_compiled_per_cell_costa_frame(cube, rng):
    mesh, x = cube
    from scipy.spatial.transform import Rotation

    R = Rotation.random(mesh.n_cells, random_state=3).as_matrix()
    base = MATERIALS["Costa"]
    mat = type(base)(
        **{
            k: getattr(base, k) for k in ("a", "k0", "b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")
        },
        frame=R,
    )
    f_r, K_r = mjed.make_force_field(mesh, mat).force_and_stiffness(x)
    f_c, K_c = mjed.make_force_field(mesh, mat, backend="numba").force_and_stiffness(x)
    assert relative_difference(f_c, f_r) < 1e-13 and abs(K_c - K_r).max() <= 1e-13 * abs(K_r).max()


@needs_numba
def test_compiled_refuses_inverted_cells_like_the_engine(cube):
    mesh, _ = cube
    x = mesh.points.copy()
    x[mesh.cells[0, 0]] = x[mesh.cells[0, 1:]].mean(axis=0) * 2 - x[mesh.cells[0, 0]]  # flip cell 0
    field = mjed.make_force_field(mesh, MATERIALS["NeoHookean"], backend="numba")
    with pytest.raises(mjed.InvertedElementError):
        field.force_and_stiffness(x)
    loose = mjed.make_force_field(
        mesh, MATERIALS["NeoHookean"], backend="numba", allow_inverted=True
    )
    f = loose.force(x)  # NaN where ln J appears, as documented
    assert not np.isfinite(f).all()


@needs_numba
def test_serial_kernels_run_the_cells_in_morton_order_and_answer_in_the_callers(cube):
    # The serial compiled fields (one cell at a time, batched, and the classical element) visit
    # the cells in the Morton order of their centroids (locality of the assembly sums); the
    # cells named by a refusal, J and S per cell stay in the caller's order. On a shuffled
    # mesh that order is far from the caller's.
    from mjed.darcy import cell_jacobians
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    mesh0, x = cube
    cells = mesh0.cells[np.random.default_rng(1).permutation(mesh0.n_cells)]
    mesh = mjed.TetMesh(mesh0.points, cells)
    mat = MATERIALS["NeoHookean"]
    ref = mjed.make_force_field(mesh, mat)
    y = mesh.points.copy()
    y[cells[5, 0]] = y[cells[5, 1:]].mean(axis=0) * 2 - y[cells[5, 0]]  # flip cell 5
    bad = np.flatnonzero(cell_jacobians(mesh, y) <= 0)
    assert 5 in bad
    fields = [
        mjed.make_force_field(mesh, mat, backend="numba"),
        mjed.make_force_field(mesh, mat, backend="numba", batch=DEFAULT_BATCH),
        CompiledClassicalGalerkin(mesh, None, mat),
    ]
    for field in fields:
        order = (field.schedule if hasattr(field, "schedule") else field._order).cell_id
        assert np.array_equal(np.sort(order), np.arange(mesh.n_cells))
        assert not np.array_equal(order, np.arange(mesh.n_cells))
        with pytest.raises(mjed.InvertedElementError) as err:
            field.force(y)
        assert np.array_equal(err.value.cells, bad)
    for field in fields[:2]:
        assert relative_difference(field.stress(x), ref.stress(x)) < 1e-13
        f, K = field.force_and_stiffness(x)
        f_r, K_r = ref.force_and_stiffness(x)
        assert relative_difference(f, f_r) < 1e-13 and abs(K - K_r).max() <= 1e-13 * abs(K_r).max()


@needs_numba
def test_compiled_refuses_a_term_kind_it_has_no_kernel_for(cube):
    mesh, _ = cube
    porous = mjed.with_porous_volume(
        MATERIALS["NeoHookean"], mjed.PorousVolume(f_w=0.8, K0=1.0, K_lim=40.0)
    )
    with pytest.raises(NotImplementedError, match="PorousVolume.*backend='numpy'"):
        mjed.make_force_field(mesh, porous, backend="numba")


def test_unknown_backend_and_bad_positions(cube):
    mesh, x = cube
    with pytest.raises(ValueError, match="unknown backend 'fortran'"):
        mjed.make_force_field(mesh, MATERIALS["NeoHookean"], backend="fortran")
    if numba_available():
        field = mjed.make_force_field(mesh, MATERIALS["NeoHookean"], backend="numba")
        with pytest.raises(ValueError, match="shape"):
            field.force(x[:-1])


def test_importing_mjed_does_not_import_numba():
    code = "import sys, mjed, mjed.compiled; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_missing_numba_gives_a_clear_error(cube, monkeypatch):
    import mjed.compiled.availability as availability

    monkeypatch.setattr(availability, "numba_available", lambda: False)
    mesh, _ = cube
    with pytest.raises(availability.BackendUnavailable, match="needs Numba.*python3-numba"):
        mjed.make_force_field(mesh, MATERIALS["NeoHookean"], backend="numba")


@needs_numba
def test_jacobi_eigen_decomposition_matches_lapack(rng):
    from mjed.compiled.kernels import eigh3

    for A in [np.eye(3), np.diag([2.0, 2.0, 5.0])] + [
        rng.standard_normal((3, 3)) for _ in range(50)
    ]:
        A = A + A.T if not np.allclose(A, np.diag(np.diag(A))) else A
        lam, V, scratch = np.empty(3), np.empty((3, 3)), np.empty((3, 3))
        eigh3(A, lam, V, scratch)
        assert np.allclose(
            np.sort(lam), np.linalg.eigvalsh(A), rtol=0, atol=1e-14 * np.abs(A).max()
        )
        assert np.abs(V.T @ V - np.eye(3)).max() < 1e-14
        assert np.abs(A @ V - V * lam).max() < 1e-14 * np.abs(A).max()


@needs_numba
def test_compiled_stress_equals_numpy_engine(material, cube):
    # S per cell is what the viscous history integrates; one pass gives it with f and K.
    mesh, x = cube
    ref = mjed.make_force_field(mesh, material)
    comp = mjed.make_force_field(mesh, material, backend="numba")
    S_r = ref.stress(x)
    assert S_r.shape == (mesh.n_cells, 3, 3) and np.abs(S_r).max() > 0
    assert relative_difference(comp.stress(x), S_r) < 1e-13
    f, K, S = comp.force_stiffness_and_stress(x)
    f_n, K_n, S_n = ref.force_stiffness_and_stress(x)
    assert np.array_equal(S, comp.stress(x)) and np.array_equal(f, comp.force(x))
    assert abs(K - comp.stiffness(x)).max() == 0.0
    assert relative_difference(S_n, S_r) == 0.0 and relative_difference(f_n, ref.force(x)) == 0.0


@needs_numba
def test_viscous_field_on_the_compiled_backend_equals_numpy(cube):
    # Same history, same forces and tangent, over accepted steps (the liver's visco model).
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    mesh, x = cube
    mat = MATERIALS["ArrudaBoyce"]
    prony = Prony((0.235, 0.333), (0.27, 0.03))
    fields = [
        ViscoHyperelasticForceField(
            mjed.make_force_field(mesh, mat, backend=b), prony=prony, dt=0.02
        )
        for b in ("numpy", "numba")
    ]
    rng = np.random.default_rng(3)
    for step in range(3):
        xs = mesh.points + (step + 1) / 3 * (x - mesh.points) + 0.01 * rng.standard_normal(x.shape)
        (f_r, K_r), (f_c, K_c) = (v.force_and_stiffness(xs) for v in fields)
        assert relative_difference(f_c, f_r) < 1e-12
        assert abs(K_c - K_r).max() <= 1e-12 * abs(K_r).max()
        for v in fields:
            v.accept_step(xs)
    assert np.abs(fields[0].gammas).max() > 0
    assert relative_difference(fields[1].gammas, fields[0].gammas) < 1e-12
    assert relative_difference(fields[1].stress(x), fields[0].stress(x)) < 1e-12


@needs_numba
def test_a_view_or_read_only_positions_reuse_the_compiled_kernel(cube):
    # Numba would compile a new specialisation (seconds) for an F-ordered or read-only array;
    # both compiled fields hand their kernel a C copy instead: same result, no new signature.
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    mesh, x = cube
    mat = MATERIALS["NeoHookean"]
    for field in (
        mjed.make_force_field(mesh, mat, backend="numba"),
        CompiledClassicalGalerkin(mesh.points, mesh.cells, mat),
    ):
        f, K = field.force_and_stiffness(x)
        n_signatures = len(field._kernel.signatures)
        view = np.asfortranarray(x)
        view.setflags(write=False)
        f2, K2 = field.force_and_stiffness(view)
        assert np.array_equal(f2, f) and abs(K2 - K).max() == 0.0
        assert len(field._kernel.signatures) == n_signatures
