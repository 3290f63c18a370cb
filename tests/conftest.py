"""Shared fixtures: small NumPy-built meshes (no gmsh needed) and the material set."""

from __future__ import annotations

import os

# One OpenBLAS thread per test process. The suite already runs one pytest-xdist worker per core
# (and each corpus test two engine subprocesses); OpenBLAS' own threads on top of them
# oversubscribe the cores, and its waiting threads then slow the many small LAPACK calls (the
# stacked 3x3 inverses and determinants of every mesh, the least-squares fits of the diagnosis)
# several times over: the mutation catalogue took 303 s with the default and 180 s with one
# thread, beside another worker (docs/tests.md). Set before NumPy first loads OpenBLAS;
# subprocesses inherit it. An explicit OPENBLAS_NUM_THREADS is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import mjed  # noqa: E402
from mjed import materials as M  # noqa: E402

# The parameter sets of every declared material, read from its declaration (``examples``:
# chosen so that every term of the energy matters, and a second set where the sign of a
# parameter changes the kernel or the split); a declaration without examples gives its default.
MATERIALS = {
    label: example
    for d in M.declarations()
    for label, example in (dict(d.examples) or {d.name: d.default}).items()
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


def stretched_state(seed=0, uniaxial=False):
    """(points, cells, x): a jittered 2 x 2 x 2 cube stretched along its axes (uniaxial, F
    diagonal) or deformed, rotated and its nodes moved randomly (U != V in F's SVD).
    """
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    if uniaxial:
        return points, cells, points @ np.diag([1.2, 0.95, 0.95])
    rng = np.random.default_rng(seed)
    c, s_ = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    x = points @ (R @ np.array([[1.15, 0.1, 0.0], [0.0, 0.95, 0.05], [0.05, 0.0, 0.9]])).T
    return points, cells, x + 0.03 * rng.standard_normal(points.shape)


def mjed_split(model, points, cells, x):
    """(split, f_o, K_o, s): MJED's force and stiffness as the oracle of a diagnosis test, their
    split into cells (conformance.diagnosis.elements.element_split) and the case's scales.
    """
    import scipy.sparse as sp

    from conformance.diagnosis.elements import element_split
    from conformance.judge.compare import DOUBLE, scales

    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f_o, K_o = field.force_and_stiffness(x)
    K_o = sp.csr_matrix(K_o)
    s = scales(0.5, 1.0, f_o, K_o)
    split = element_split(model, points, cells, x, f_o, K_o, s, DOUBLE)
    assert split is not None and split.residual < 1e-12
    return split, f_o, K_o, s


def checked_random(engine, material):
    """The diagnosis of ``engine`` checked as ``material`` on cube-small's random state without
    probes (conformance.protocol.check_implementation), asserted to have failed.
    """
    import logging

    from conformance.protocol import check_implementation

    logging.disable(logging.INFO)
    run = check_implementation(
        engine, material=material, mesh="cube-small", states=("random",), probes=False
    )
    (outcome,) = run.outcomes
    assert outcome.status == "failed", outcome.diagnosis.text()
    return outcome.diagnosis


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


def pytest_report_header(config):
    """One loud line when SOFA's engine program is missing: its checks are then skipped."""
    from conformance.adapters.sofa import find_program, how_to_build

    if find_program() is None:
        return f"SOFA checks SKIPPED: {how_to_build()}"
    return f"SOFA checks: engine program {find_program()}"


#: the environment variable naming the tutorial cache that a session's worker processes share
#: (tests/docs_support.py reads it)
TUTORIAL_CACHE_VARIABLE = "MJED_TESTS_TUTORIAL_CACHE"


def pytest_configure(config):
    """In the controlling process only: one tutorial cache for the session's workers
    (tests/docs_support.py), made before they start so that they inherit its name.
    """
    if hasattr(config, "workerinput") or TUTORIAL_CACHE_VARIABLE in os.environ:
        return
    import shutil
    import tempfile

    path = tempfile.mkdtemp(prefix="mjed-tutorials-")
    os.environ[TUTORIAL_CACHE_VARIABLE] = path
    config.add_cleanup(lambda: shutil.rmtree(path, ignore_errors=True))
    config.add_cleanup(lambda: os.environ.pop(TUTORIAL_CACHE_VARIABLE, None))


# ---- the full sweeps: cross products kept out of the default run (make test-sweep)


def pytest_addoption(parser):
    parser.addoption(
        "--sweep",
        action="store_true",
        help="also run the tests marked 'sweep' (full cross products; make test-sweep)",
    )


def pytest_collection_modifyitems(config, items):
    """A test marked ``sweep`` repeats, on more cases, a code path the default run already
    checks (each one's docstring says which); it is skipped, saying so, unless --sweep.
    """
    if config.getoption("--sweep"):
        return
    skip = pytest.mark.skip(reason="full sweep: run with --sweep (make test-sweep)")
    for item in items:
        if "sweep" in item.keywords:
            item.add_marker(skip)
