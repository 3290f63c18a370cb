"""The one place that knows which dolfinx release is installed.

The oracle runs on Debian 12's dolfinx 0.5.2 (UFL 2022.2, petsc4py 3.18) and on current
releases (tested: the PyPI wheel ``dolfinx-solver-real`` 0.11, UFL 2026.1). Their Python APIs
differ in small ways that matter here: how a P1 vector space and a coordinate element are
made, the argument order of ``create_mesh``, whether cell-wise maps are AdjacencyLists or
(m, k) arrays, and what ``create_vector`` takes. Every such difference is settled in this
module, so the rest of ``reference_fem`` reads the same on every release; nothing else
branches on the version.

Only 0.5.2 and 0.11 were installed and tested. Where the release notes date a change, the
branch is on :func:`dolfinx_version`; where they were not checked (0.6 to 0.10 were never
installed here), the branch looks at the object itself (a signature, an attribute) and the
comment says so.

All functions import dolfinx lazily, so this module can be imported (and its pure helpers
tested) without it.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from functools import lru_cache
from typing import Any, Dict, Optional, Tuple

import numpy as np

__all__ = [
    "parse_version",
    "dolfinx_version",
    "import_dolfinx",
    "stack_versions",
    "comm_world",
    "comm_self",
    "create_tet_mesh",
    "vector_p1_space",
    "scalar_p1_space",
    "tensor_dg0_space",
    "function",
    "constant",
    "compile_form",
    "geometry_dofmap",
    "cell_dofs",
    "input_global_indices",
    "original_cell_index",
    "num_owned_cells",
    "owned_range",
    "num_ghosts",
    "dof_coordinates",
    "create_vector",
    "create_matrix",
    "assemble_scalar_local",
    "assemble_vector_into",
    "assemble_matrix_into",
    "scatter_forward",
    "accumulate_ghosts",
]

# The first release whose elements are basix.ufl elements and whose function spaces come
# from fem.functionspace (0.7; VectorFunctionSpace and ufl.VectorElement went away after).
# Only 0.5.2 and 0.11 were installed and tested here; the 0.7 threshold is the release
# notes' and the intermediate releases are untested.
_BASIX_ELEMENTS = (0, 7, 0)
# Releases before this one return cell-wise maps (V.dofmap.list, geometry.dofmap) as
# AdjacencyLists; from it on they are (m, k) NumPy arrays (release notes; untested here).
_ARRAY_DOFMAPS = (0, 7, 0)


def parse_version(text: str) -> Tuple[int, int, int]:
    """(major, minor, patch) of a version string such as '0.5.2' or '0.11.0.post0'.

    Raises:
        ValueError: if the string does not start with three dot-separated integers (a
            missing patch number counts as 0).
    """
    parts = str(text).split(".")
    numbers = []
    for p in parts[:3]:
        digits = ""
        for ch in p:
            if not ch.isdigit():
                break
            digits += ch
        if not digits:
            break
        numbers.append(int(digits))
    if len(numbers) < 2:
        raise ValueError(f"cannot read a dolfinx version from {text!r}")
    while len(numbers) < 3:
        numbers.append(0)
    return tuple(numbers)  # type: ignore[return-value]


@lru_cache(maxsize=None)
def import_dolfinx():
    """Import and return the ``dolfinx`` module, loading its MPI runtime first if needed.

    The PyPI wheel ``dolfinx-solver-real`` vendors PETSc and links the MPICH of the PyPI
    ``mpich`` wheel; its compiled modules only find ``libmpi`` once ``dolfinx_solver`` (which
    imports ``mpi4py.MPI`` in the right order) has been imported. Debian's build needs no
    such step.
    """
    if importlib.util.find_spec("dolfinx_solver") is not None:
        importlib.import_module("dolfinx_solver")
    import dolfinx
    import dolfinx.fem.petsc  # noqa: F401  (checks that the PETSc layer loads too)

    return dolfinx


def dolfinx_version() -> Tuple[int, int, int]:
    """The installed dolfinx release as (major, minor, patch)."""
    return parse_version(import_dolfinx().__version__)


def _at_least(release: Tuple[int, int, int]) -> bool:
    return dolfinx_version() >= release


def stack_versions() -> Dict[str, Any]:
    """Versions of everything the oracle's numbers depend on, for provenance records."""
    dolfinx = import_dolfinx()
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    out: Dict[str, Any] = {
        "python": sys.version.split()[0],
        "dolfinx": dolfinx.__version__,
        "ufl": getattr(ufl, "__version__", "unknown"),
        "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()),
        "numpy": np.__version__,
        # MPI libraries end the version string with a NUL byte, which JSON would keep.
        "mpi": MPI.Get_library_version().replace("\x00", "").splitlines()[0].strip(),
    }
    for name in ("ffcx", "basix", "dolfinx_solver"):
        try:
            out[name] = importlib.import_module(name).__version__
        except Exception:  # not part of this stack
            pass
    return out


# -- communicators ------------------------------------------------------------------------
def comm_world():
    """MPI.COMM_WORLD (after dolfinx has set up MPI in the right order)."""
    import_dolfinx()
    from mpi4py import MPI

    return MPI.COMM_WORLD


def comm_self():
    """MPI.COMM_SELF."""
    import_dolfinx()
    from mpi4py import MPI

    return MPI.COMM_SELF


# -- mesh and spaces ----------------------------------------------------------------------
def _vector_p1_element():
    """The UFL element of a P1 vector field on tetrahedra in 3-D."""
    import ufl

    if _at_least(_BASIX_ELEMENTS):
        import basix.ufl

        return basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,))
    # Equispaced from the start: FFCx 0.5 gives a coordinate element without a variant this
    # one, in place, when it compiles a form (ffcx.analysis), which changes the mesh's UFL hash.
    # A form built on that mesh before the change and one built after then number the mesh
    # twice, their signatures (FFCx's cache keys) differ from the same form's on a fresh mesh,
    # and every first run compiled each form again under several keys. For P1 the points,
    # hence the generated code and every result, are the same.
    return ufl.VectorElement(
        ufl.FiniteElement("Lagrange", ufl.tetrahedron, 1, variant="equispaced")
    )


def create_tet_mesh(comm, cells: np.ndarray, points: np.ndarray):
    """A dolfinx mesh of P1 tetrahedra with an affine vector coordinate element.

    Args:
        comm: MPI communicator. Each rank passes its share of the input: the oracle gives
            everything on rank 0 and empty arrays elsewhere, and dolfinx's default
            partitioner (ghost mode none) then distributes the cells.
        cells: (m_rank, 4) int64 input node indices (global input numbering).
        points: (n_rank, 3) float64 input points; input index = offset of this rank's
            block in the concatenation over ranks.
    """
    import_dolfinx()
    import ufl
    from dolfinx.mesh import create_mesh

    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 4)
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    domain = ufl.Mesh(_vector_p1_element())
    # (comm, cells, x, domain) up to 0.9, (comm, cells, e, x) from 0.10: read from the
    # signature, which names the arguments in both.
    names = list(inspect.signature(create_mesh).parameters)
    if names.index("x") < 3:
        return create_mesh(comm, cells, points, domain)
    return create_mesh(comm, cells, domain, points)


def vector_p1_space(mesh):
    """The continuous P1 vector function space (block size 3) on ``mesh``."""
    from dolfinx import fem

    install_jit_memo()

    if _at_least(_BASIX_ELEMENTS):
        return fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    return fem.VectorFunctionSpace(mesh, ("Lagrange", 1))


def scalar_p1_space(mesh):
    """The continuous scalar P1 function space on ``mesh``."""
    from dolfinx import fem

    if _at_least(_BASIX_ELEMENTS):
        return fem.functionspace(mesh, ("Lagrange", 1))
    return fem.FunctionSpace(mesh, ("Lagrange", 1))


def tensor_dg0_space(mesh):
    """Cell-wise constant 3x3 tensors (row-major blocks of 9 per cell)."""
    from dolfinx import fem

    if _at_least(_BASIX_ELEMENTS):
        return fem.functionspace(mesh, ("DG", 0, (3, 3)))
    return fem.TensorFunctionSpace(mesh, ("DG", 0))


def function(V, name: str):
    """A zero dolfinx Function on ``V``."""
    from dolfinx import fem

    return fem.Function(V, name=name)


def constant(mesh, value):
    """A dolfinx Constant holding ``value`` (a float or an array) as float64."""
    from dolfinx import fem

    return fem.Constant(mesh, np.asarray(value, dtype=np.float64))


#: A form whose compilation takes longer than this is announced on a terminal (stderr).
COMPILE_NOTICE_AFTER_S = 1.0


def _compile_notice() -> None:
    """One line while FFCx compiles a form (a cache hit never gets here: it takes ms)."""
    from dolfinx.jit import get_parameters

    try:
        where = get_parameters()["cache_dir"]
    except Exception:  # noqa: BLE001 - the notice must never fail the compilation
        where = "dolfinx's JIT cache"
    print(
        f"mjed: FFCx is compiling a form (first use on this machine, a few seconds; "
        f"kept in {where})",
        file=sys.stderr,
        flush=True,
    )


#: Forms on meshes of at most this many cells are compiled without C optimisation (``-O0``).
#: On such meshes an assembly takes milliseconds, while gcc's -O2 is most of a form's compile
#: time (a hyperelastic stiffness form: 3.0 s at -O2, 0.9 s at -O0; a conformance test module
#: compiling 126 forms from empty caches: 180 s against 119 s); -O0 code assembles about 3x
#: slower (48,000 cells: 2.2 s against 0.73 s), which pays for the compile only past roughly
#: 10^5 cell-assemblies of one form. The results differ at round-off only (4e-16 relative
#: there: -O2 folds some constants at compile time). The kits, the tests and the diagnosis'
#: variants are on small meshes; the timed dolfinx method always gets FFCx's -O2.
FAST_COMPILE_MAX_CELLS = 20_000
#: gcc 12's -Wfree-nonheap-object analysis (the "access analysis" pass, run at every -O level)
#: grows far faster than the function it reads: an FFCx stiffness kernel of 38,000 temporaries
#: (2 MB of C, a frame-dependent variant energy of the diagnosis) took 54 s at -O0 with it and
#: 4 s without, 145 s and 88 s at -O2. A warning about freeing non-heap memory can never fire
#: on FFCx's kernels, which free nothing; turning it off changes no generated instruction.
#: The 72 forms of one diagnosis test and one held-out corpus at -O0: 85.8 s of gcc with the
#: analysis, 27.2 s without (2-core VM, 27 November 2026).
#: cffi compiles with Python's own CFLAGS first, and they hold -Wall, whose warnings in gcc 12
#: run that same pass again (and more analyses) whatever -Wfree-nonheap-object says: the 2 MB
#: kernel above, compiled with Python's flags and then ours, took 57 s at -O0, and 3.1 s with
#: -Wno-all after them; a 400 kB stiffness kernel 2.1 s against 0.6 s (28 November 2026). The
#: objects are byte-identical with and without it (at -O0 and -O2): warnings change no code, and
#: nobody reads gcc's warnings on generated kernels.
_NO_SLOW_WARNINGS = ["-Wno-free-nonheap-object", "-Wno-all"]
_C_OPTIMISATION = ["-O2", "-g0", *_NO_SLOW_WARNINGS]  # FFCx's and dolfinx's default, plus that
_NO_C_OPTIMISATION = ["-O0", "-g0", *_NO_SLOW_WARNINGS]


#: What dolfinx's JIT returned in this process, by FFCx's own cache key (see _jit_key).
_JIT_MEMO: Dict[tuple, Any] = {}


def _jit_key(ufl_object, args: tuple, kwargs: dict) -> Optional[tuple]:
    """FFCx's cache key of a form or element: its UFL signature (a form's) or repr (an
    element's) and the options; None for anything else (not memoised).
    """
    import ufl

    options = (repr(args), repr(sorted(kwargs.items())))
    if isinstance(ufl_object, ufl.Form):
        return ("form", ufl_object.signature(), *options)
    element_base = getattr(ufl, "FiniteElementBase", None)
    if element_base is not None and isinstance(ufl_object, element_base):
        return ("element", repr(ufl_object), *options)
    return None


def install_jit_memo() -> None:
    """Have dolfinx's JIT answer a form or element it already answered in this process from
    memory.

    dolfinx asks FFCx's JIT for every form it builds, even one compiled a moment ago: FFCx
    then finds the module in its disk cache by listing the cache folder (about 2,000 files
    after a first test run) and loads it again, 10 to 20 ms each. The diagnosis builds
    hundreds of oracles on the same few forms, so that lookup cost more than the assembly. The
    memo keys on what FFCx's cache keys on (the form's signature and the options) and returns
    the same compiled object FFCx would load; in parallel runs (more than one rank) dolfinx's
    own path is kept. Installed once, by the oracle's first compilation.
    """
    from dolfinx import jit

    if getattr(jit.ffcx_jit, "memoised", False):
        return

    def ffcx_jit(comm, ufl_object, *args, **kwargs):
        inner = ffcx_jit.__wrapped__  # dolfinx's own
        key = _jit_key(ufl_object, args, kwargs) if comm.size == 1 else None
        if key is None:
            return inner(comm, ufl_object, *args, **kwargs)
        if key not in _JIT_MEMO:
            _JIT_MEMO[key] = inner(comm, ufl_object, *args, **kwargs)
        return _JIT_MEMO[key]

    ffcx_jit.memoised = True
    ffcx_jit.__wrapped__ = jit.ffcx_jit
    jit.ffcx_jit = ffcx_jit


def compile_form(ufl_form, *, optimise: Optional[bool] = None):
    """The dolfinx Form compiled (JIT, cached by FFCx) from a UFL form.

    optimise: compile the C with FFCx's default flags (-O2) when True, without optimisation
    when False; None (default) decides by the size of the form's mesh
    (:data:`FAST_COMPILE_MAX_CELLS`). The two are separate entries of FFCx's cache.

    A compilation that lasts longer than :data:`COMPILE_NOTICE_AFTER_S` says so on stderr
    when stderr is a terminal (a first run on a new machine compiles hundreds of forms), so
    that a long first run never waits silently.
    """
    from dolfinx import fem

    install_jit_memo()
    if optimise is None:
        optimise = _form_cells(ufl_form) > FAST_COMPILE_MAX_CELLS
    timer = None
    if sys.stderr.isatty() and comm_world().rank == 0:
        import threading

        timer = threading.Timer(COMPILE_NOTICE_AFTER_S, _compile_notice)
        timer.daemon = True
        timer.start()
    try:
        return fem.form(ufl_form, **jit_wait_options(optimise=optimise))
    finally:
        if timer is not None:
            timer.cancel()


def _form_cells(ufl_form) -> int:
    """Cells of the form's mesh, summed over the ranks (0 where it cannot be told)."""
    domains = ufl_form.ufl_domains()
    mesh = domains[0].ufl_cargo() if domains else None
    if mesh is None:
        return 0
    index_map = mesh.topology.index_map(mesh.topology.dim)
    return int(index_map.size_global)


#: How long a process waits for another one that is compiling the same form (FFCx's default,
#: 10 s, is shorter than one compilation on a loaded 2-core machine: two checks running side by
#: side then failed with "JIT compilation timed out"). Not part of FFCx's cache key.
JIT_TIMEOUT_S = 600


def jit_wait_options(*, optimise: bool = True) -> dict:
    """The dolfinx JIT options that make a process wait JIT_TIMEOUT_S for a form that another
    process is compiling (the keyword is jit_params before dolfinx 0.6, jit_options since),
    and compile its C at -O2, or without optimisation with ``optimise=False`` (see
    compile_form), without gcc's slow warning analyses (-Wall's, -Wfree-nonheap-object's)
    either way.
    """
    key = "jit_params" if dolfinx_version() < (0, 6, 0) else "jit_options"
    flags = _C_OPTIMISATION if optimise else _NO_C_OPTIMISATION
    options: Dict[str, Any] = {"timeout": JIT_TIMEOUT_S, "cffi_extra_compile_args": list(flags)}
    return {key: options}


# -- cell-wise maps and index maps --------------------------------------------------------
def _as_cell_array(adjacency_or_array, nodes_per_cell: int) -> np.ndarray:
    if dolfinx_version() < _ARRAY_DOFMAPS:
        return np.asarray(adjacency_or_array.array).reshape(-1, nodes_per_cell)
    return np.asarray(adjacency_or_array).reshape(-1, nodes_per_cell)


def geometry_dofmap(mesh) -> np.ndarray:
    """(cells on this rank, 4) geometry node indices of each cell (local numbering)."""
    geometry = mesh.geometry
    # Newer releases hold one dofmap per cell type (geometry.dofmaps) and deprecate
    # geometry.dofmap (0.11 warns); which release added dofmaps was not checked, so ask the
    # object.
    if hasattr(geometry, "dofmaps"):
        return _as_cell_array(geometry.dofmaps[0], 4)
    return _as_cell_array(geometry.dofmap, 4)


def cell_dofs(V, nodes_per_cell: int) -> np.ndarray:
    """(cells on this rank, nodes_per_cell) dof blocks of each cell of space ``V``."""
    return _as_cell_array(V.dofmap.list, nodes_per_cell)


def input_global_indices(mesh) -> np.ndarray:
    """(geometry nodes on this rank,) input index of each geometry node, int64."""
    return np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)


def original_cell_index(mesh) -> np.ndarray:
    """(cells on this rank,) input index of each local cell, int64.

    Some releases (0.9, 0.10) hold one array per cell type; a tetrahedral mesh has one type.
    This is recognised from the object, since those releases were not installed here.
    """
    raw = mesh.topology.original_cell_index
    if isinstance(raw, (list, tuple)):
        raw = raw[0]
    return np.asarray(raw, dtype=np.int64)


def num_owned_cells(mesh) -> int:
    """Number of cells owned by this rank (the first ones in local numbering)."""
    tdim = mesh.topology.dim
    return int(mesh.topology.index_map(tdim).size_local)


def owned_range(index_map) -> Tuple[int, int]:
    """[start, stop) of the global indices owned by this rank (in blocks)."""
    start, stop = index_map.local_range
    return int(start), int(stop)


def num_ghosts(index_map) -> int:
    return int(index_map.num_ghosts)


def dof_coordinates(V) -> np.ndarray:
    """(dof nodes on this rank incl. ghosts, 3) coordinates of V's dof nodes."""
    return np.asarray(V.tabulate_dof_coordinates())[:, :3]


# -- assembly -----------------------------------------------------------------------------
def create_vector(form):
    """A ghosted PETSc vector for the linear form ``form``.

    Up to 0.10 ``fem.petsc.create_vector`` takes the form; 0.11 takes the function space.
    Read from its signature, since the 0.10 signature was not checked against an install.
    """
    import dolfinx.fem.petsc as fem_petsc

    first = next(iter(inspect.signature(fem_petsc.create_vector).parameters))
    if first == "V":
        return fem_petsc.create_vector(form.function_spaces[0])
    return fem_petsc.create_vector(form)


def create_matrix(form):
    """A PETSc matrix with the sparsity pattern of the bilinear form ``form``."""
    import dolfinx.fem.petsc as fem_petsc

    return fem_petsc.create_matrix(form)


def assemble_scalar_local(form) -> float:
    """This rank's contribution to a scalar form (sum over ranks for the total)."""
    from dolfinx import fem

    return float(fem.assemble_scalar(form))


def assemble_vector_into(b, form) -> None:
    """Zero ``b`` and assemble the linear form into it (owned and ghost entries)."""
    import dolfinx.fem.petsc as fem_petsc

    with b.localForm() as local:
        local.set(0.0)
    fem_petsc.assemble_vector(b, form)


def assemble_matrix_into(A, form) -> None:
    """Zero ``A``, assemble the bilinear form into it and finalise it (MatAssembly)."""
    import dolfinx.fem.petsc as fem_petsc

    A.zeroEntries()
    fem_petsc.assemble_matrix(A, form)
    A.assemble()


def accumulate_ghosts(b) -> None:
    """Add the ghost entries of ``b`` into their owners' entries (reverse scatter)."""
    from petsc4py import PETSc

    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)


def scatter_forward(function) -> None:
    """Copy owned values of a dolfinx Function to the ranks that hold them as ghosts."""
    function.x.scatter_forward()
