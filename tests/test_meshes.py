"""Tests of the meshes package: built-ins, generators, file reading and writing."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import meshes
from meshes import catalog
from meshes.tetra import orient_positively, remove_unreferenced, signed_volumes

REFERENCE_TET = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
# Two tetrahedra sharing the face (1, 2, 3), both positively oriented, plus a 6th point.
TWO_TETS_POINTS = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [2, 2, 2]])
TWO_TETS_CELLS = np.array([[0, 1, 2, 3], [1, 4, 2, 3]])


def assert_valid_tet_mesh(points: np.ndarray, cells: np.ndarray, volume: float) -> None:
    """Shapes, dtypes, contiguous numbering, positive orientation and total volume."""
    assert points.dtype == np.float64 and points.ndim == 2 and points.shape[1] == 3
    assert cells.dtype == np.int64 and cells.ndim == 2 and cells.shape[1] == 4
    assert np.array_equal(np.unique(cells), np.arange(len(points)))  # 0-based, all used
    v = signed_volumes(points, cells)
    assert v.min() > 0
    assert abs(v.sum() - volume) <= 1e-12 * volume


# ---------------------------------------------------------------- built-in meshes


def test_names_and_describe():
    assert meshes.names() == (
        "single-tet",
        "cube-small",
        "cube-medium",
        "cube-paper",
        "liver",
        "liver-100k",
        "liver-coarse",
    )
    with pytest.raises(ValueError, match="cube-paper"):
        meshes.describe("cube-huge")


@pytest.mark.parametrize("name", catalog.names())
def test_builtin_is_valid(name):
    points, cells = meshes.load(name)
    assert_valid_tet_mesh(points, cells, catalog.describe(name).domain_volume)
    assert catalog.check_counts(catalog.describe(name), points, cells) == []


def test_builtin_sizes():
    assert 300 <= len(meshes.load("cube-small")[1]) <= 700
    assert abs(len(meshes.load("cube-medium")[1]) / 3000 - 1) <= 0.05


def test_cube_paper_counts():
    points, cells = meshes.load("cube-paper")
    assert abs(len(cells) / 20700 - 1) <= 0.05
    assert abs(len(points) / 4300 - 1) <= 0.05


def test_builtin_files_are_committed():
    for name in catalog.names():
        filename = catalog.describe(name).filename
        assert filename is None or (catalog.DATA_DIR / filename).is_file()


def test_single_tet_is_reference():
    points, cells = meshes.load("single-tet")
    assert np.array_equal(points, REFERENCE_TET)
    assert np.array_equal(cells, [[0, 1, 2, 3]])


def test_resolve_name_path_and_errors(tmp_path):
    points, cells, label = meshes.resolve("cube-small")
    assert label == "cube-small" and len(cells) > 0
    path = tmp_path / "two.vtu"
    meshes.write_mesh(path, TWO_TETS_POINTS[:5], TWO_TETS_CELLS)
    p, c, label = meshes.resolve(str(path))
    assert label == str(path) and np.array_equal(c, TWO_TETS_CELLS)
    with pytest.raises(ValueError, match="single-tet, cube-small, cube-medium, cube-paper"):
        meshes.resolve("cube-huge")
    with pytest.raises(meshes.MeshReadError, match="no such file"):
        meshes.resolve(tmp_path / "missing.msh")


def test_load_regenerates_missing_file(tmp_path, monkeypatch):
    pytest.importorskip("gmsh")
    monkeypatch.setattr(catalog, "DATA_DIR", tmp_path)
    points, cells = meshes.load("cube-small")
    assert_valid_tet_mesh(points, cells, 1.0)


def test_regenerate_writes_loadable_files(tmp_path):
    pytest.importorskip("gmsh")
    pytest.importorskip("meshio")
    (path,) = catalog.regenerate(["cube-small"], data_dir=tmp_path)
    assert path == tmp_path / "cube-small.msh"
    data = meshes.read_mesh(path)
    assert data.dropped == {} and data.unused_nodes.size == 0
    assert_valid_tet_mesh(np.array(data.points), np.array(data.cells), 1.0)


def test_builtins_work_with_mjed_tetmesh():
    mesh_module = pytest.importorskip("mjed.mesh")
    mesh = mesh_module.TetMesh(*meshes.load("cube-small"))
    assert mesh.n_reoriented == 0 and len(mesh.unreferenced_nodes) == 0


# ---------------------------------------------------------------- generators


def test_single_tetrahedron_orientation():
    points, cells = meshes.single_tetrahedron()
    assert np.array_equal(points, REFERENCE_TET) and np.array_equal(cells, [[0, 1, 2, 3]])
    flipped = REFERENCE_TET[[0, 2, 1, 3]]
    points, cells = meshes.single_tetrahedron(flipped)
    assert np.array_equal(points, flipped)  # the points are kept, the cell is reordered
    assert signed_volumes(points, cells)[0] == pytest.approx(1 / 6)
    with pytest.raises(ValueError, match="flat"):
        meshes.single_tetrahedron([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    with pytest.raises(ValueError, match="shape"):
        meshes.single_tetrahedron(REFERENCE_TET[:3])


def test_unit_cube_count_and_validity():
    pytest.importorskip("gmsh")
    points, cells = meshes.unit_cube(1000)
    assert abs(len(cells) / 1000 - 1) <= 0.05
    assert_valid_tet_mesh(points, cells, 1.0)
    assert points.min() == 0.0 and points.max() == 1.0


def test_unit_cube_is_deterministic():
    pytest.importorskip("gmsh")
    p1, c1 = meshes.unit_cube(800)
    p2, c2 = meshes.unit_cube(800)
    assert np.array_equal(p1, p2) and np.array_equal(c1, c2)
    p3, c3 = meshes.unit_cube(800, seed=7)
    assert abs(len(c3) / 800 - 1) <= 0.05
    assert len(p3) != len(p1) or not np.array_equal(p3, p1)


def test_unit_cube_rejects_bad_target():
    for bad in (0, -5, 2.5, True):
        with pytest.raises(ValueError, match="target_cells"):
            meshes.unit_cube(bad)


def test_cylinder():
    pytest.importorskip("gmsh")
    radius, height = 0.02, 0.005
    points, cells = meshes.cylinder(radius, height, 2000)
    assert abs(len(cells) / 2000 - 1) <= 0.05
    v = signed_volumes(points, cells)
    assert v.min() > 0
    # Polygonal curved face: a little less than the exact volume.
    exact = math.pi * radius**2 * height
    assert 0.97 * exact < v.sum() <= exact
    assert points[:, 2].min() == 0.0 and points[:, 2].max() == pytest.approx(height)
    assert np.hypot(points[:, 0], points[:, 1]).max() <= radius * (1 + 1e-12)
    with pytest.raises(ValueError, match="positive"):
        meshes.cylinder(-1.0, 1.0, 100)


def test_generation_respects_an_existing_gmsh_session():
    gmsh = pytest.importorskip("gmsh")
    from meshes import _gmsh

    if _gmsh._is_initialized(gmsh):
        pytest.skip("gmsh already initialised by another test")
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("somebody-else")
        gmsh.option.setNumber("Mesh.Algorithm3D", 10)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.3)
        inside = meshes.unit_cube(400)
        assert _gmsh._is_initialized(gmsh)  # not finalised behind the owner's back
        assert gmsh.model.getCurrent() == "somebody-else"
        assert gmsh.model.list() == ["", "somebody-else"]
        assert gmsh.option.getNumber("Mesh.Algorithm3D") == 10
        assert gmsh.option.getNumber("Mesh.MeshSizeMax") == 0.3
    finally:
        gmsh.finalize()
    outside = meshes.unit_cube(400)
    assert np.array_equal(inside[0], outside[0]) and np.array_equal(inside[1], outside[1])


# ---------------------------------------------------------------- helpers


def test_orient_positively_and_remove_unreferenced():
    flipped = TWO_TETS_CELLS[:, [0, 2, 1, 3]]
    fixed, n = orient_positively(TWO_TETS_POINTS, flipped)
    assert n == 2 and (signed_volumes(TWO_TETS_POINTS, fixed) > 0).all()
    assert np.array_equal(flipped, TWO_TETS_CELLS[:, [0, 2, 1, 3]])  # input untouched
    cells = np.array([[5, 1, 2, 3]])
    points, renumbered, removed = remove_unreferenced(TWO_TETS_POINTS, cells)
    assert removed == 2
    assert np.array_equal(points, TWO_TETS_POINTS[[1, 2, 3, 5]])
    assert np.array_equal(renumbered, [[3, 0, 1, 2]])


# ---------------------------------------------------------------- reading and writing


@pytest.mark.parametrize(
    ("suffix", "kwargs"),
    [
        (".msh", {"msh_version": "4.1"}),
        (".msh", {"msh_version": "4.1", "binary": True}),
        (".msh", {"msh_version": "2.2"}),
        (".msh", {"msh_version": "2.2", "binary": True}),
        (".vtk", {}),
        (".vtu", {}),
    ],
)
def test_write_read_round_trip(tmp_path, suffix, kwargs):
    pytest.importorskip("meshio")
    points, cells = meshes.load("cube-small")
    path = meshes.write_mesh(tmp_path / f"mesh{suffix}", points, cells, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a clean file reads without any warning
        data = meshes.read_mesh(path)
    assert np.array_equal(data.points, points) and np.array_equal(data.cells, cells)
    assert data.dropped == {} and data.unused_nodes.size == 0 and data.source == str(path)


@pytest.mark.parametrize("file_format", ["gmsh22", "gmsh", "vtk", "vtu"])
def test_read_files_written_by_meshio(tmp_path, file_format):
    meshio = pytest.importorskip("meshio")
    suffix = {"gmsh22": ".msh", "gmsh": ".msh", "vtk": ".vtk", "vtu": ".vtu"}[file_format]
    path = tmp_path / f"m{suffix}"
    meshio.write(
        str(path),
        meshio.Mesh(TWO_TETS_POINTS[:5], [("tetra", TWO_TETS_CELLS)]),
        file_format=file_format,
    )
    data = meshes.read_mesh(path)
    assert np.array_equal(data.points, TWO_TETS_POINTS[:5]) and np.array_equal(
        data.cells, TWO_TETS_CELLS
    )


def test_read_keeps_negative_orientation(tmp_path):
    pytest.importorskip("meshio")
    flipped = TWO_TETS_CELLS[:, [0, 2, 1, 3]]
    path = meshes.write_mesh(tmp_path / "flipped.vtu", TWO_TETS_POINTS[:5], flipped)
    data = meshes.read_mesh(path)
    assert np.array_equal(data.cells, flipped)  # the consumer decides about orientation


def test_read_gmsh_native_file(tmp_path):
    gmsh = pytest.importorskip("gmsh")
    pytest.importorskip("meshio")
    from meshes import _gmsh

    path = tmp_path / "native.msh"
    with _gmsh.session({"Mesh.MeshSizeMin": 0.25, "Mesh.MeshSizeMax": 0.25}):
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        gmsh.model.mesh.generate(3)
        n_tets = len(gmsh.model.mesh.getElementsByType(4)[0])
        gmsh.option.setNumber("Mesh.SaveAll", 1)  # points, lines, triangles too
        gmsh.write(str(path))
        gmsh.option.setNumber("Mesh.SaveAll", 0)
    with pytest.warns(meshes.MeshReadWarning, match="triangle"):
        data = meshes.read_mesh(path)
    assert len(data.cells) == n_tets
    assert {"vertex", "line", "triangle"} <= set(data.dropped)
    assert_valid_tet_mesh(np.array(data.points), np.array(data.cells), 1.0)


def test_mixed_triangles_and_tets(tmp_path):
    meshio = pytest.importorskip("meshio")
    path = tmp_path / "mixed.msh"
    triangles = np.array([[0, 1, 2], [1, 2, 5], [2, 3, 5]])  # node 5 is in no tetrahedron
    meshio.write(
        str(path),
        meshio.Mesh(TWO_TETS_POINTS, [("triangle", triangles), ("tetra", TWO_TETS_CELLS)]),
        file_format="gmsh22",
        binary=False,
    )
    with pytest.warns(meshes.MeshReadWarning) as caught:
        data = meshes.read_mesh(path)
    messages = [str(w.message) for w in caught]
    assert any("3 triangle" in m for m in messages) and any(
        "1 node(s) no tetrahedron uses are kept" in m for m in messages
    )
    assert data.dropped == {"triangle": 3}
    # Node 5 is kept with its number: nothing is renumbered.
    assert data.unused_nodes.tolist() == [5] and data.node_ids.tolist() == [1, 2, 3, 4, 5, 6]
    assert np.array_equal(data.points, TWO_TETS_POINTS) and np.array_equal(
        data.cells, TWO_TETS_CELLS
    )


def test_only_triangles_is_an_error(tmp_path):
    meshio = pytest.importorskip("meshio")
    path = tmp_path / "surface.vtu"
    meshio.write(
        str(path), meshio.Mesh(REFERENCE_TET, [("triangle", np.array([[0, 1, 2], [0, 1, 3]]))])
    )
    with pytest.raises(
        meshes.MeshReadError, match=r"surface\.vtu.*no linear tetrahedra.*2 triangle"
    ):
        meshes.read_mesh(path)


def test_missing_file(tmp_path):
    with pytest.raises(meshes.MeshReadError, match=r"nothere\.msh: no such file"):
        meshes.read_mesh(tmp_path / "nothere.msh")


def test_unknown_extension(tmp_path):
    path = tmp_path / "mesh.xyz"
    path.write_text("0 0 0\n")
    with pytest.raises(meshes.MeshReadError, match=r"mesh\.xyz.*unknown mesh file type '\.xyz'"):
        meshes.read_mesh(path)
    with pytest.raises(ValueError, match="suffix"):
        meshes.write_mesh(tmp_path / "mesh.stl", REFERENCE_TET, [[0, 1, 2, 3]])


@pytest.mark.parametrize("suffix", [".msh", ".vtk", ".vtu"])
def test_unreadable_file(tmp_path, suffix):
    pytest.importorskip("meshio")
    path = tmp_path / f"garbage{suffix}"
    path.write_text("this is not a mesh\n")
    with pytest.raises(meshes.MeshReadError, match=f"garbage\\{suffix}: cannot be read"):
        meshes.read_mesh(path)


def test_tetra10_refused(tmp_path):
    meshio = pytest.importorskip("meshio")
    path = tmp_path / "quadratic.msh"
    points = np.vstack(
        [REFERENCE_TET, (REFERENCE_TET[[0, 1, 2, 0, 0, 1]] + REFERENCE_TET[[1, 2, 0, 3, 2, 3]]) / 2]
    )
    meshio.write(
        str(path),
        meshio.Mesh(points, [("tetra10", np.arange(10)[None])]),
        file_format="gmsh22",
        binary=False,
    )
    with pytest.raises(meshes.MeshReadError, match=r"quadratic\.msh.*higher-order.*tetra10"):
        meshes.read_mesh(path)


def test_two_dimensional_points_refused():
    meshio = pytest.importorskip("meshio")
    from meshes.io import tet_mesh_from_meshio

    flat = meshio.Mesh(REFERENCE_TET[:, :2], [("tetra", np.array([[0, 1, 2, 3]]))])
    with pytest.raises(meshes.MeshReadError, match="flat.vtu: points have 2 coordinates"):
        tet_mesh_from_meshio(flat, source="flat.vtu")


def test_tet_mesh_data_is_frozen(tmp_path):
    pytest.importorskip("meshio")
    path = meshes.write_mesh(tmp_path / "t.vtu", REFERENCE_TET, [[0, 1, 2, 3]])
    data = meshes.read_mesh(path)
    with pytest.raises(AttributeError):
        data.points = None
    with pytest.raises(ValueError):
        data.cells[0, 0] = 1
