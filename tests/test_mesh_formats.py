"""Mesh formats organs come in: every supported format reads back identically (points, cells,
node numbering); surfaces are refused with the gmsh commands; the reader rules (unused nodes
kept, repeated nodes and undefined ids named, one-line warnings).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import meshes
from meshes.formats.gmsh_ascii import write_gmsh_legacy
from meshes.io import one_line_warnings, read_mesh, surface_advice, write_mesh

pytest.importorskip("meshio")

# (file name, write_mesh options, first node id of the format's numbering)
FORMATS = [
    ("organ_v1.msh", dict(msh_version="1.0"), 1),
    ("organ_v22.msh", dict(msh_version="2.2"), 1),
    ("organ_v41.msh", dict(msh_version="4.1"), 1),
    ("organ.vtk", {}, 0),
    ("organ.vtu", {}, 0),
    ("organ.mesh", {}, 1),
    ("organ.inp", {}, 1),
]


@pytest.fixture(scope="module")
def organ():
    points, cells = meshes.load("liver-coarse")
    return points, cells


@pytest.mark.parametrize("name, options, first", FORMATS, ids=[f[0] for f in FORMATS])
def test_a_generated_organ_reads_back_identically_in_every_format(
    tmp_path, organ, name, options, first
):
    points, cells = organ
    path = write_mesh(tmp_path / name, points, cells, **options)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing to warn about in a clean file
        data = read_mesh(path)
    np.testing.assert_array_equal(data.points, points)
    np.testing.assert_array_equal(data.cells, cells)
    np.testing.assert_array_equal(data.node_ids, first + np.arange(len(points)))
    assert data.unused_nodes.size == 0 and str(path) in data.source


def test_legacy_gmsh_keeps_sparse_node_numbers_and_unused_nodes(tmp_path, organ):
    """SOFA-style legacy file: node numbers with gaps, boundary triangles, an unused node."""
    points, cells = organ
    extra = np.vstack([points, [[1.0, 2.0, 3.0]]])
    ids = 10 + 3 * np.arange(len(extra))[::-1]  # decreasing, with gaps
    triangles = cells[:5, :3]
    path = write_gmsh_legacy(
        tmp_path / "liver.msh", extra, cells, node_ids=ids, triangles=triangles
    )
    assert path.read_text().startswith("$NOD\n")
    with pytest.warns(meshes.MeshReadWarning) as caught:
        data = read_mesh(path)
    messages = [str(w.message) for w in caught]
    assert any("dropped 5 triangle" in m for m in messages)
    assert any(
        f"1 node(s) no tetrahedron uses are kept with their numbers (ids [{ids[-1]}])" in m
        for m in messages
    )
    np.testing.assert_array_equal(data.points, extra)
    np.testing.assert_array_equal(data.cells, cells)
    np.testing.assert_array_equal(data.node_ids, ids)
    assert data.unused_nodes.tolist() == [len(points)]
    np.testing.assert_array_equal(data.positions_of(ids[[4, 0, 7]]), [4, 0, 7])
    with pytest.raises(ValueError, match="11 is not a node"):
        data.positions_of([11])


def test_a_cell_that_repeats_a_node_is_named(tmp_path):
    path = tmp_path / "bad.msh"
    path.write_text(
        "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n$ELM\n2\n1 4 1 1 4 1 2 3 4\n2 4 1 1 "
        "4 1 2 2 4\n$ENDELM\n"
    )
    with pytest.raises(
        meshes.MeshReadError,
        match=r"bad\.msh: tetrahedron 1 repeats a node: its node ids are \[1, 2, 2, 4\]",
    ):
        read_mesh(path)


def test_an_undefined_node_id_is_named(tmp_path):
    path = tmp_path / "bad.msh"
    path.write_text(
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 "
        "1\n$EndNodes\n$Elements\n1\n1 4 2 1 1 1 2 3 9\n$EndElements\n"
    )
    with pytest.raises(
        meshes.MeshReadError, match=r"bad\.msh: tetrahedron 0 uses node id\(s\) \[9\] that the file"
    ):
        read_mesh(path)


V22 = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n"
V41 = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"
FOUR_NODES = "1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n"


@pytest.mark.parametrize(
    "text, words",
    [
        (  # a node number past int64, which numpy would wrap or refuse with OverflowError
            f"{V22}$Nodes\n4\n123456789012345678901234 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n"
            "$EndNodes\n$Elements\n1\n1 4 0 123456789012345678901234 2 3 4\n$EndElements\n",
            "a node id of \\$NODES is too large",
        ),
        (
            f"$NOD\n4\n{FOUR_NODES}$ENDNOD\n$ELM\n1\n1 4 0 0 4 1 2 3 99999999999999999999\n"
            "$ENDELM\n",
            "number 99999999999999999999 in the \\$ELM section is too large",
        ),
        (  # a negative count in a 4.1 node block
            f"{V41}$Nodes\n1 4 1 4\n3 1 0 -5\n1\n0 0 0\n$EndNodes\n$Elements\n1 1 1 1\n"
            "3 1 4 1\n1 1 2 3 4\n$EndElements\n",
            "malformed gmsh 4.1",
        ),
        (
            f"{V22}$Nodes\n-4\n$EndNodes\n$Elements\n0\n$EndElements\n",
            "announces a negative count",
        ),
        (  # tetrahedra, and no node at all
            f"{V41}$Nodes\n0 0 0 0\n$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 4\n"
            "$EndElements\n",
            "1 tetrahedra but no nodes",
        ),
    ],
    ids=["huge node id", "huge element node", "negative 4.1 count", "negative count", "no nodes"],
)
def test_hostile_gmsh_files_are_refused_by_name(tmp_path, text, words):
    path = tmp_path / "hostile.msh"
    path.write_text(text)
    with pytest.raises(meshes.MeshReadError, match=words) as info:
        read_mesh(path)
    assert "hostile.msh" in str(info.value)


@pytest.mark.parametrize("suffix", [".stl", ".obj"])
def test_surface_files_are_refused_with_the_gmsh_commands(tmp_path, suffix):
    path = tmp_path / f"organ{suffix}"
    path.write_text("solid organ\nendsolid organ\n")
    with pytest.raises(meshes.MeshReadError) as info:
        read_mesh(path)
    text = str(info.value)
    assert text.startswith(str(path)) and "a surface mesh holds no volume" in text
    assert f'Merge "organ{suffix}"; Surface Loop(1) = {{1}}; Volume(1) = {{1}};' in text
    assert "gmsh organ.geo -3 -o organ.msh" in text


def test_a_file_with_only_triangles_is_refused_as_a_surface(tmp_path):
    path = tmp_path / "skin.msh"
    path.write_text(
        "$NOD\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$ENDNOD\n$ELM\n1\n1 2 1 1 3 1 2 3\n$ENDELM\n"
    )
    with pytest.raises(
        meshes.MeshReadError,
        match=r"skin\.msh: no linear tetrahedra; found 1 triangle; a surface mesh",
    ):
        read_mesh(path)


def test_the_surface_advice_meshes_a_closed_surface(tmp_path, organ):
    """The commands the refusal gives do produce a volume mesh (gmsh's Python API runs the same
    .geo).
    """
    gmsh = pytest.importorskip("gmsh")
    meshio = pytest.importorskip("meshio")
    from comparisons.liver.figures import boundary_faces

    points, cells = organ
    tri = boundary_faces(cells)
    used = np.unique(tri)
    index = np.full(len(points), -1)
    index[used] = np.arange(len(used))
    stl = tmp_path / "organ.stl"
    meshio.write(str(stl), meshio.Mesh(points[used], [("triangle", index[tri])]))
    advice = surface_advice(stl)
    geo_text = advice.split("containing  ")[1].split("  then run")[0]
    (tmp_path / "organ.geo").write_text(geo_text.replace("; ", ";\n"))
    assert advice.endswith("gmsh organ.geo -3 -o organ.msh")
    gmsh.initialize(["", "-3"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(tmp_path / "organ.geo"))
        gmsh.model.mesh.generate(3)
        gmsh.write(str(tmp_path / "organ.msh"))
    finally:
        gmsh.finalize()
    with pytest.warns(meshes.MeshReadWarning):
        data = read_mesh(tmp_path / "organ.msh")
    assert data.n_cells > 100


def test_mesh_warnings_print_as_one_line():
    """No file name, line number or source line under our mesh warnings; others unchanged."""
    import mjed

    with one_line_warnings():
        ours = warnings.formatwarning(
            "organ.msh: 1 node(s) kept", meshes.MeshReadWarning, "/x/io.py", 12, "warn(...)"
        )
        engine = warnings.formatwarning(
            "reoriented 3 cell(s)", mjed.MeshWarning, "/x/mesh.py", 7, "warn(...)"
        )
        other = warnings.formatwarning("something else", UserWarning, "/x/y.py", 3, "src line")
    assert ours == "MeshReadWarning: organ.msh: 1 node(s) kept\n"
    assert engine == "MeshWarning: reoriented 3 cell(s)\n"
    assert "/x/y.py:3" in other and "src line" in other
    assert "/x/y.py" in warnings.formatwarning(
        "m", meshes.MeshReadWarning, "/x/y.py", 3, ""
    )  # restored after
