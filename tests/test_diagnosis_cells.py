"""Per-cell data misassigned: a cell skipped or counted twice in the assembly is named with the
cell (conformance.diagnosis.cells), and per-cell fibre frames read one cell off are named as
shifted (conformance.diagnosis.frames). The engines are MJED's element forces and matrices,
assembled here with their own mistake.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from conformance.diagnosis.cells import fit_cell_contributions
from conformance.judge.compare import Scales
from reference_fem import dolfinx_available


def _element_engine(weights):
    """MJED per cell, assembled with weight weights(m)[e] on cell e (1: right)."""
    import mjed

    def engine(case):
        field = mjed.make_force_field(mjed.TetMesh(case.points, case.cells), case.model)
        fe = np.asarray(field.element_forces(case.positions))
        Ke = np.asarray(field.element_stiffness(case.positions))
        m, n = case.cells.shape[0], case.points.shape[0]
        w = weights(m)
        dof = (3 * case.cells[:, :, None] + np.arange(3)).reshape(m, 12)
        f = np.zeros(3 * n)
        np.add.at(f, dof.ravel(), (w[:, None, None] * fe).reshape(-1))
        K = sp.coo_matrix(
            (
                (w[:, None, None] * Ke).ravel(),
                (np.repeat(dof, 12, 1).ravel(), np.tile(dof, 12).ravel()),
            ),
            shape=(3 * n, 3 * n),
        ).tocsr()
        return f.reshape(n, 3), K

    return engine


def _weights(cell, weight):
    """Weights of an engine giving ``cell`` (negative: from the end) the weight ``weight``."""

    def weights(m):
        w = np.ones(m)
        w[cell] = weight
        return w

    return weights


def test_the_fit_reads_a_missing_cell_and_nothing_from_other_cells():
    rng = np.random.default_rng(1)
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    fe = rng.normal(size=(2, 4, 3))
    Ke = rng.normal(size=(2, 12, 12))
    from conformance.diagnosis.elements import assemble

    df, dK = assemble(cells[[1]], 5, -fe[[1]], -Ke[[1]])
    fit = fit_cell_contributions(cells, 5, fe, Ke, df, dK, np.array([0, 1]), Scales(1, 1, 1))
    assert fit is not None and np.allclose(fit.alpha, [0.0, -1.0]) and fit.stiffness < 1e-12


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
@pytest.mark.parametrize(
    "cell, weight, words", [(-1, 0.0, "contribution missing"), (3, 2.0, "counted twice")]
)
def test_a_cell_skipped_or_counted_twice_is_named(cell, weight, words):
    from conformance.protocol import check_implementation

    seen: list = []

    def weights(m):
        seen.append(m)
        return _weights(cell, weight)(m)

    run = check_implementation(
        _element_engine(weights),
        material="MooneyRivlin",
        mesh="cube-small",
        states=("random",),
        probes=False,
    )
    (outcome,) = run.outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed" and len(d.causes) == 1, d.text()
    assert d.causes[0].code == "cell-contribution" and words in d.causes[0].title, d.text()
    named = cell % seen[0]
    assert f"cell {named}" in d.causes[0].title, d.text()
    assert d.causes[0].title.count("cell ") == 1, d.text()  # that cell alone
    assert any(f.code == "localised" for f in d.findings)  # the localisation stays, observed


def test_the_fit_over_all_cells_finds_cells_missing_anywhere():
    from conformance.diagnosis.cells import fit_all_cells
    from conformance.diagnosis.elements import assemble
    from meshes import unit_cube

    points, cells = unit_cube(75)[:2]
    m, n = cells.shape[0], points.shape[0]
    rng = np.random.default_rng(2)
    fe = rng.normal(size=(m, 4, 3))
    A = rng.normal(size=(m, 12, 12))
    Ke = A + np.swapaxes(A, 1, 2)
    w = np.zeros(m)
    w[[5, 40, m - 1]] = [-1.0, -1.0, 1.0]
    df, dK = assemble(cells, n, w[:, None, None] * fe, w[:, None, None] * Ke)
    fit = fit_all_cells(cells, n, fe, Ke, df, dK, Scales(1, 1, 1))
    assert fit is not None and np.allclose(fit.alpha, w, atol=1e-9)
    assert max(fit.force, fit.stiffness) < 1e-10


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_last_cells_skipped_all_over_the_mesh_are_named():
    from conformance.protocol import check_implementation

    seen: list = []

    def weights(m):  # the assembly loop stops 6 cells short
        seen.append(m)
        w = np.ones(m)
        w[-6:] = 0.0
        return w

    run = check_implementation(
        _element_engine(weights),
        material="NeoHookean",
        mesh="cube-small",
        states=("random",),
        probes=False,
    )
    (outcome,) = run.outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed" and len(d.causes) == 1, d.text()
    cause = d.causes[0]
    assert cause.code == "cell-contribution", d.text()
    assert cause.figures["cells"] == list(range(seen[0] - 6, seen[0])), d.text()
    assert np.allclose(cause.figures["coefficients"], -1.0)


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
@pytest.mark.parametrize("shift", [1, -1])
def test_per_cell_frames_shifted_by_one_cell_are_named(shift):
    from frame_support import check_with_frames

    outcome = check_with_frames(lambda R, cells: np.roll(R, shift, axis=0), "fibre-shear")
    d = outcome.diagnosis
    assert outcome.status == "failed" and len(d.causes) == 1, d.text()
    assert d.causes[0].code == "frame-shifted", d.text()
    assert ("previous" if shift == 1 else "next") in d.causes[0].title


def test_a_place_that_is_the_stiffest_cells_is_an_observation_not_a_cause():
    """A Demiray mesh whose exponential makes a few cells far stiffer than the rest: an error
    on the stiffest cell's nodes (where a step's truncation or a rounded exponential shows) is
    kept as an observation under "unexplained"; the same error on another cell stays a place.
    """
    from types import SimpleNamespace

    from conftest import box_mesh, mjed_split

    from conformance.diagnosis.cells import stiffest_cells
    from conformance.diagnosis.diagnose import diagnose
    from conformance.run import _graded_localisation
    from mjed import materials as M

    points, cells = box_mesh(3, jitter=0.2, seed=4)
    rng = np.random.default_rng(4)
    x = points @ np.diag([1.25, 0.9, 0.9]).T + 0.05 * rng.standard_normal(points.shape)
    model = M.Demiray(a=300.0, b=8.0, k0=2e4)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    (top,) = stiffest_cells(split, 1)
    c = SimpleNamespace(
        ci=SimpleNamespace(model=model, points=points, cells=cells, positions=x),
        ref=SimpleNamespace(force=f_o, stiffness=K_o),
        s=s,
        read_causes=True,
    )
    for cell, demoted in ((top, True), ((top + 7) % len(cells), False)):
        f = f_o.copy()
        f[cells[cell]] += 1e-6 * np.abs(f_o).max()
        d = diagnose(
            "c", f=f, K=K_o, W=None, f_o=f_o, K_o=K_o, W_o=0.0, s=s, points=points,
            cells=cells, x=x,
        )  # fmt: skip
        assert [x.code for x in d.causes] == ["localised"], d.text()
        out = _graded_localisation(d, c)
        if demoted:
            assert not out.causes and out.findings[0].code == "unexplained"
            assert "stiffest cells" in out.findings[1].title
        else:
            assert out is d
