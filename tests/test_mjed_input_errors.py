"""Every bad input gets a clear error that names the problem (mesh, parameters, positions)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from conftest import box_mesh

import mjed
from mjed import materials as M

TET = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
CELL = np.array([[0, 1, 2, 3]])


@pytest.mark.parametrize(
    "points, cells, message",
    [
        (TET[:, :2], CELL, r"points must have shape \(n, 3\)"),
        (TET, CELL[:, :3], r"cells must have shape \(m, 4\)"),
        (TET, np.zeros((0, 4), dtype=int), "no cells"),
        (TET[:3], np.array([[0, 1, 2, 2]]), "at least 4 points"),
        (
            np.where(np.arange(12).reshape(4, 3) == 7, np.nan, TET),
            CELL,
            "non-finite coordinates; first is node 2",
        ),
        (np.where(np.arange(12).reshape(4, 3) == 3, np.inf, TET), CELL, "node 1"),
        (TET, np.array([[0, 1, 2, 4]]), r"cell 0 has node indices out of range \[0, 4\)"),
        (TET, np.array([[0, 1, 2, -1]]), "out of range"),
        (TET, np.array([[0, 1, 2, 2]]), "cell 0 repeats a node"),
        (TET, np.array([[0, 1, 2, 3.5]]), "integer node indices"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], CELL, "degenerate.*cell 0"),
        (TET, np.array([[0, 2, 1, 3]]), "negatively oriented.*cell 0"),
        ("not a mesh", CELL, "points"),
    ],
)
def test_mesh_errors_name_the_problem(points, cells, message):
    with pytest.raises(mjed.MeshError, match=message):
        mjed.TetMesh(points, cells)


def test_mesh_error_names_the_right_cell():
    points, cells = box_mesh(2)
    cells = cells.copy()
    cells[17, [2, 3]] = cells[17, [3, 2]]
    with pytest.raises(mjed.MeshError, match="1 negatively oriented cell.*cell 17"):
        mjed.TetMesh(points, cells)


def test_nearly_flat_cell_is_degenerate():
    points = TET.copy()
    points[3] = [0.3, 0.3, 1e-12]
    with pytest.raises(mjed.MeshError, match="degenerate"):
        mjed.TetMesh(points, CELL)


def test_fix_orientation_swaps_and_reports():
    points, cells = box_mesh(2)
    flipped = cells.copy()
    flipped[::3, [1, 2]] = flipped[::3, [2, 1]]
    with pytest.warns(mjed.MeshWarning, match=f"reoriented {len(cells[::3])} cell"):
        mesh = mjed.TetMesh(points, flipped, fix_orientation=True)
    assert mesh.n_reoriented == len(cells[::3])
    assert np.all(mesh.volumes > 0)
    assert np.isclose(mesh.volumes.sum(), 1.0)
    ref = mjed.TetMesh(points, cells)
    mat = M.NeoHookean(1.0, 1.0)
    x = points * 1.1
    assert np.allclose(
        mjed.HyperelasticForceField(mesh, mat).force(x),
        mjed.HyperelasticForceField(ref, mat).force(x),
        atol=1e-14,
    )


def test_unreferenced_nodes_are_reported():
    points = np.vstack([TET, [[5.0, 5.0, 5.0]]])
    with pytest.warns(mjed.MeshWarning, match=r"1 node\(s\) belong to no cell \(first: \[4\]\)"):
        mesh = mjed.TetMesh(points, CELL)
    assert mesh.unreferenced_nodes.tolist() == [4]


def test_clean_mesh_is_silent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh = mjed.TetMesh(*box_mesh(2))
    assert mesh.n_reoriented == 0 and len(mesh.unreferenced_nodes) == 0
    assert mesh.D.shape == (48, 4, 3) and np.allclose(mesh.D.sum(axis=1), 0)


@pytest.mark.parametrize(
    "factory, name",
    [
        (lambda: M.StVenantKirchhoff(mu=-1.0, lam=1.0), "mu"),
        (lambda: M.StVenantKirchhoff(mu=1.0, lam=math.nan), "lam"),
        (lambda: M.StVenantKirchhoff(mu=1.0, lam=-1.0), "lam"),
        (lambda: M.NeoHookean(mu=0.0, lam=1.0), "mu"),
        (lambda: M.NeoHookean(mu=1.0, lam=math.inf), "lam"),
        (lambda: M.NeoHookean(mu=True, lam=1.0), "mu"),
        (lambda: M.MooneyRivlin(c1="1", c2=1.0, k0=1.0), "c1"),
        (lambda: M.MooneyRivlin(c1=1.0, c2=-2.0, k0=1.0), "s? c1 \\+ c2"),
        (lambda: M.MooneyRivlin(c1=1.0, c2=1.0, k0=0.0), "k0"),
        (lambda: M.VerondaWestmann(c1=1.0, c2=-1.0, k0=1.0), "c2"),
        (lambda: M.ArrudaBoyce(mu=1.0, k0=1.0, N=0.0), "N"),
        (lambda: M.ArrudaBoyce(mu=math.nan, k0=1.0), "mu"),
        (lambda: M.Yeoh(c10=0.0, c20=0.1, c30=0.1, k0=1.0), "c10"),
        (lambda: M.Yeoh(c10=1.0, c20=math.inf, c30=0.1, k0=1.0), "c20"),
        (lambda: M.Yeoh(c10=1.0, c20=-0.1, c30=0.1, k0=-1.0), "k0"),
        (lambda: M.Gent(mu=1.0, Jm=0.0, k0=1.0), "Jm"),
        (lambda: M.Gent(mu=-1.0, Jm=5.0, k0=1.0), "mu"),
    ],
)
def test_invalid_parameters_name_the_parameter(factory, name):
    with pytest.raises(
        ValueError, match=f"parameter{name}" if name.startswith("s?") else f"parameter {name}"
    ):
        factory()


def test_materials_are_frozen():
    mat = M.NeoHookean(1.0, 2.0)
    with pytest.raises(AttributeError):
        mat.mu = 3.0


def test_inverted_state_is_refused_with_the_cells_named():
    points, cells = box_mesh(2)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), M.NeoHookean(1.0, 1.0))
    x = points.copy()
    x[:, 2] *= -1.0  # mirror: every cell inverted
    with pytest.raises(
        mjed.InvertedElementError, match="48 inverted or flattened cell.*cell 0 \\(J=-1\\)"
    ) as info:
        field.force(x)
    assert len(info.value.cells) == 48
    for method in (
        field.energy,
        field.stiffness,
        field.element_stiffness,
        field.force_and_stiffness,
    ):
        with pytest.raises(mjed.InvertedElementError):
            method(x)


def test_allow_inverted_evaluates():
    points, cells = box_mesh(1)
    mesh = mjed.TetMesh(points, cells)
    x = points.copy()
    x[:, 2] *= -1.0
    f = mjed.HyperelasticForceField(mesh, M.StVenantKirchhoff(1.0, 1.0), allow_inverted=True).force(
        x
    )
    assert np.isfinite(f).all()  # StVK has no ln J: finite through inversion


@pytest.mark.parametrize(
    "bad, message",
    [(np.zeros((5, 3)), r"shape \(8, 3\)"), ("nan", "non-finite positions; first is node 3")],
)
def test_bad_positions(bad, message):
    points, cells = box_mesh(1)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), M.NeoHookean(1.0, 1.0))
    if isinstance(bad, str):
        bad = points.copy()
        bad[3, 1] = np.nan
    with pytest.raises(ValueError, match=message):
        field.force(bad)


def test_field_rejects_wrong_types():
    mesh = mjed.TetMesh(TET, CELL)
    with pytest.raises(TypeError, match="material"):
        mjed.HyperelasticForceField(mesh, {"mu": 1.0})
    with pytest.raises(TypeError, match="TetMesh"):
        mjed.HyperelasticForceField((TET, CELL), M.NeoHookean(1.0, 1.0))
