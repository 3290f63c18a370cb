"""The dolfinx compatibility layer (reference_fem.compat) and the MPI helpers, in one process.

The pure parts (version parsing, the gathers' stacking, collective errors) run everywhere;
the accessors are checked against the installed dolfinx, whichever release it is.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from reference_fem import compat, dolfinx_available
from reference_fem.distributed import RankError, collective, gather_csr, gather_rows, on_root

REPO = Path(__file__).resolve().parents[1]
needs_dolfinx = pytest.mark.skipif(
    not dolfinx_available(), reason="dolfinx is not installed (Debian: python3-dolfinx)"
)


@pytest.mark.parametrize(
    "text, expected",
    [
        ("0.5.2", (0, 5, 2)),
        ("0.11.0.post0", (0, 11, 0)),
        ("0.10", (0, 10, 0)),
        ("0.9.0rc1", (0, 9, 0)),
        ("1.0.0.dev0", (1, 0, 0)),
    ],
)
def test_parse_version(text, expected):
    assert compat.parse_version(text) == expected


@pytest.mark.parametrize("text", ["", "abc", "0", "main"])
def test_parse_version_refuses_garbage(text):
    with pytest.raises(ValueError, match="dolfinx version"):
        compat.parse_version(text)


# Spellings that differ between releases; outside compat.py they mean a version branch or
# a call that breaks on one of the releases.
_RELEASE_SPECIFIC = [
    r"__version__",
    r"dolfinx_version\(",
    r"VectorFunctionSpace",
    r"TensorFunctionSpace",
    r"fem\.functionspace",
    r"VectorElement",
    r"basix\.ufl",
    r"geometry\.dofmap",
    r"dofmap\.list",
    r"\.input_global_indices\b(?!\()",
    r"\.original_cell_index\b(?!\()",
    r"create_mesh\(",
    r"fem\.petsc",
    r"import dolfinx",
    r"from dolfinx",
]
# Every module of reference_fem but the layer itself.
_LAYERED = sorted(p.name for p in (REPO / "reference_fem").glob("*.py") if p.name != "compat.py")


@pytest.mark.parametrize("name", _LAYERED)
def test_no_release_specific_calls_outside_compat(name):
    text = (REPO / "reference_fem" / name).read_text()
    code = "\n".join(line.split("#")[0] for line in text.splitlines())  # comments may name them
    code = re.sub(r'""".*?"""', "", code, flags=re.S)  # and so may docstrings
    found = [
        p
        for p in _RELEASE_SPECIFIC
        if re.search(r"(?<!compat)" + p if p.startswith("\\.") else r"(?<!compat\.)" + p, code)
    ]
    assert not found, f"reference_fem/{name} uses {found}; go through reference_fem.compat"


# -- MPI helpers without MPI: a stand-in communicator -------------------------------------
class _FakeComm:
    """Rank 0 of a 2-rank communicator whose gathers return prepared parts."""

    size, rank = 2, 0

    def __init__(self, parts):
        self.parts = parts

    def gather(self, value, root=0):
        return [value] + self.parts


def test_gather_csr_stacks_rows_in_rank_order():
    A = sp.random(7, 7, density=0.5, format="csr", random_state=3)
    top, bottom = A[:4], A[4:]
    comm = _FakeComm([(bottom.indptr, bottom.indices, bottom.data)])
    indptr, indices, data = gather_csr(comm, top.indptr, top.indices, top.data)
    B = sp.csr_matrix((data, indices, indptr), shape=(7, 7))
    assert (abs(B - A)).nnz == 0 and B.nnz == A.nnz


def test_gather_rows_concatenates_in_rank_order():
    comm = _FakeComm([np.array([3.0, 4.0])])
    assert np.array_equal(gather_rows(comm, np.array([1.0, 2.0])), [1.0, 2.0, 3.0, 4.0])


def test_collective_helpers_in_serial():
    class Serial:
        size, rank = 1, 0

    def bad():
        raise ValueError("points must have shape (n, 3)")

    assert on_root(Serial(), lambda a: a + 1, 1) == 2
    assert collective(Serial(), lambda: 5) == 5
    with pytest.raises(ValueError, match="shape"):
        on_root(Serial(), bad)
    with pytest.raises(ValueError, match="shape"):
        collective(Serial(), bad)
    assert issubclass(RankError, RuntimeError)


# -- accessors on the installed release --------------------------------------------------
@needs_dolfinx
@pytest.mark.oracle
def test_accessors_on_the_installed_release():
    from conftest import box_mesh

    dolfinx = compat.import_dolfinx()
    assert compat.dolfinx_version() == compat.parse_version(dolfinx.__version__)
    points, cells = box_mesh(2)
    m, n = cells.shape[0], points.shape[0]
    mesh = compat.create_tet_mesh(compat.comm_self(), cells, points)
    V = compat.vector_p1_space(mesh)
    geo, dofs = compat.geometry_dofmap(mesh), compat.cell_dofs(V, 4)
    assert geo.shape == dofs.shape == (m, 4)
    assert compat.num_owned_cells(mesh) == m
    # input indices are permutations of the input, and geometry follows them exactly
    igi = compat.input_global_indices(mesh)
    assert np.array_equal(np.sort(igi), np.arange(n))
    assert np.array_equal(mesh.geometry.x[:, :3], points[igi])
    oci = compat.original_cell_index(mesh)
    assert np.array_equal(np.sort(oci), np.arange(m))
    assert np.array_equal(np.sort(igi[geo], axis=1), np.sort(cells[oci], axis=1))
    assert (
        compat.owned_range(V.dofmap.index_map) == (0, n)
        and compat.num_ghosts(V.dofmap.index_map) == 0
    )
    assert compat.dof_coordinates(V).shape == (n, 3)
    S = compat.scalar_p1_space(mesh)
    assert S.dofmap.index_map_bs == S.dofmap.bs == 1 and compat.cell_dofs(S, 4).shape == (m, 4)
    Q = compat.tensor_dg0_space(mesh)
    assert Q.dofmap.index_map_bs * Q.dofmap.bs in (9, 81)  # 9 values per cell, blocked either way
    assert compat.cell_dofs(Q, 1).shape == (m, 1)
    c = compat.constant(mesh, np.eye(3))
    assert np.array_equal(c.value, np.eye(3))


@needs_dolfinx
@pytest.mark.oracle
def test_assembly_wrappers_give_the_volume_and_a_zero_sum_residual():
    import ufl
    from conftest import box_mesh

    points, cells = box_mesh(2, jitter=0.2)
    mesh = compat.create_tet_mesh(compat.comm_self(), cells, points)
    V = compat.vector_p1_space(mesh)
    u = compat.function(V, "u")
    one = compat.constant(mesh, 1.0)
    dx = ufl.dx(domain=mesh)
    assert np.isclose(compat.assemble_scalar_local(compat.compile_form(one * dx)), 1.0, rtol=1e-13)
    # R = d/du int |I + grad u|^2 dx at u = 0 is 2 int div v dx: its entries sum to zero per
    # component.
    F = ufl.Identity(3) + ufl.grad(u)
    R = compat.compile_form(ufl.derivative(ufl.inner(F, F) * dx, u, ufl.TestFunction(V)))
    b = compat.create_vector(R)
    u.x.array[:] = 0.3  # assembling twice into the same vector must not accumulate
    compat.scatter_forward(u)
    compat.assemble_vector_into(b, R)
    first = b.array_r.copy()
    compat.assemble_vector_into(b, R)
    compat.accumulate_ghosts(b)
    assert np.array_equal(first, b.array_r)
    assert np.allclose(first.reshape(-1, 3).sum(axis=0), 0.0, atol=1e-12)
    K = compat.compile_form(
        ufl.derivative(
            ufl.derivative(ufl.inner(F, F) * dx, u, ufl.TestFunction(V)), u, ufl.TrialFunction(V)
        )
    )
    A = compat.create_matrix(K)
    compat.assemble_matrix_into(A, K)
    compat.assemble_matrix_into(A, K)
    indptr, indices, data = A.getValuesCSR()
    S = sp.csr_matrix((data, indices, indptr))
    assert abs(S - S.T).max() < 1e-14 and np.allclose(S.sum(axis=1), 0.0, atol=1e-12)


@needs_dolfinx
def test_stack_versions_are_printable_text():
    """Every version is one printable line (the MPI library's string ends with a NUL byte,
    which used to reach the cross-release JSON).
    """
    versions = compat.stack_versions()
    assert {"python", "dolfinx", "ufl", "petsc", "numpy", "mpi"} <= set(versions)
    for name, text in versions.items():
        assert isinstance(text, str) and text.isprintable() and text, (name, text)


def test_a_form_compiled_elsewhere_is_waited_for():
    """Two checks side by side compile the same form; the second waits for the first instead of
    failing after FFCx's default 10 s (it did, on the loaded 2-core machine).
    """
    from reference_fem import compat

    (options,) = compat.jit_wait_options().values()
    assert options["timeout"] == compat.JIT_TIMEOUT_S >= 300


def test_unoptimised_compilation_is_asked_for_only_when_optimise_is_false():
    (fast,) = compat.jit_wait_options(optimise=False).values()
    (full,) = compat.jit_wait_options(optimise=True).values()
    assert fast["cffi_extra_compile_args"][0] == "-O0" and fast["timeout"] == full["timeout"]
    assert full["cffi_extra_compile_args"][:2] == ["-O2", "-g0"]  # FFCx's own defaults
    # gcc's slow warning analyses off in both, including those -Wall (in Python's CFLAGS, which
    # cffi puts first) turns on: they change no instruction, only compile time
    for options in (fast, full):
        assert "-Wno-free-nonheap-object" in options["cffi_extra_compile_args"]
        assert "-Wno-all" in options["cffi_extra_compile_args"]


@needs_dolfinx
@pytest.mark.oracle
def test_small_meshes_compile_without_optimisation_and_agree_with_optimised_forms(monkeypatch):
    # The size rule reads the form's mesh (cells over all ranks); both compilations give the
    # same residual to round-off, and the timed dolfinx method always asks for -O2.
    import ufl
    from conftest import box_mesh

    points, cells = box_mesh(2, jitter=0.2)
    mesh = compat.create_tet_mesh(compat.comm_self(), cells, points)
    V = compat.vector_p1_space(mesh)
    u = compat.function(V, "u")
    u.x.array[:] = np.random.default_rng(3).uniform(-0.05, 0.05, u.x.array.shape)
    F = ufl.Identity(3) + ufl.grad(u)
    J = ufl.det(F)
    W = ufl.tr(F.T * F) * J ** (-2.0 / 3.0) + (J - 1) ** 2
    R_ufl = ufl.derivative(W * ufl.dx(domain=mesh), u, ufl.TestFunction(V))
    assert compat._form_cells(R_ufl) == len(cells) <= compat.FAST_COMPILE_MAX_CELLS

    asked = []
    original = compat.jit_wait_options

    def spy(*, optimise=True):
        asked.append(optimise)
        return original(optimise=optimise)

    monkeypatch.setattr(compat, "jit_wait_options", spy)
    residuals = []
    for optimise in (None, True):
        R = compat.compile_form(R_ufl, optimise=optimise)
        b = compat.create_vector(R)
        compat.assemble_vector_into(b, R)
        residuals.append(b.array_r.copy())
    assert asked == [False, True]
    scale = np.abs(residuals[1]).max()
    assert scale > 0 and np.abs(residuals[0] - residuals[1]).max() <= 1e-14 * scale
    monkeypatch.setattr(compat, "FAST_COMPILE_MAX_CELLS", len(cells) - 1)
    compat.compile_form(R_ufl)
    assert asked[-1] is True  # a mesh above the limit gets FFCx's optimisation
