"""The timing study runs end to end on a tiny mesh (no timing assertions), the structured
mesh generator, and the edge-block CSR assembly it relies on."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import scipy.sparse as sp

import mjed
from meshes.structured import cube_with_cells, structured_box
from meshes.tetra import signed_volumes
from mjed.engine import edge_blocks_to_element_matrices
from mjed.sparse import CSRPattern, element_dofs

RESULT_KEYS = {"material", "method", "what", "median_s", "min_s", "max_s", "repeats"}


# ------------------------------------------------------------------ structured meshes
@pytest.mark.parametrize("divisions", [1, 2, (2, 3, 4)])
def test_structured_box_counts_and_positive_volumes(divisions):
    n = np.broadcast_to(divisions, (3,))
    lengths = (1.0, 2.0, 0.5)
    points, cells = structured_box(divisions, lengths)
    assert points.shape == (int(np.prod(n + 1)), 3)
    assert cells.shape == (6 * int(np.prod(n)), 4)
    vol = signed_volumes(points, cells)
    assert vol.min() > 0
    assert vol.sum() == pytest.approx(np.prod(lengths), rel=1e-12)
    mjed.TetMesh(points, cells)  # validates (no unused nodes, no flat cells)


def test_structured_box_is_conforming():
    # Every interior face is shared by exactly two cells, every boundary face by one,
    # and the boundary faces cover the box surface (2 triangles per boundary square).
    points, cells = structured_box(3)
    faces = np.sort(np.concatenate([cells[:, [1, 2, 3]], cells[:, [0, 2, 3]], cells[:, [0, 1, 3]], cells[:, [0, 1, 2]]]), axis=1)
    _, counts = np.unique(faces, axis=0, return_counts=True)
    assert set(counts.tolist()) == {1, 2}
    assert (counts == 1).sum() == 6 * 2 * 3 * 3


def test_cube_with_cells_and_bad_input():
    _, cells = cube_with_cells(6000)
    assert len(cells) == 6 * 10**3
    with pytest.raises(ValueError, match="divisions"):
        structured_box(0)
    with pytest.raises(ValueError, match="lengths"):
        structured_box(2, (1.0, -1.0, 1.0))
    with pytest.raises(ValueError, match="target_cells"):
        cube_with_cells(3)


# ------------------------------------------------------------------ the CSR routes
def _coo_reference(cells, n, Ke):
    d = element_dofs(cells)
    rows, cols = np.repeat(d, 12, axis=1).ravel(), np.tile(d, (1, 12)).ravel()
    return sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=(3 * n, 3 * n)).tocsr()


@pytest.mark.parametrize("layout", ["merc", "rcem", "emrc"])
def test_edge_block_assembly_equals_full_element_assembly(layout, rng):
    points, cells = structured_box((2, 2, 1))
    rng.shuffle(cells)  # arbitrary cell order and edge orientations
    blocks = rng.standard_normal((len(cells), 6, 3, 3))
    ref = _coo_reference(cells, len(points), edge_blocks_to_element_matrices(blocks))
    pattern = CSRPattern(cells, len(points))
    b = np.ascontiguousarray(np.transpose(blocks, ["merc".index(a) for a in layout]))
    K = pattern.assemble_edge_blocks(b, layout)
    assert K.has_sorted_indices
    assert abs(K - ref).max() <= 1e-13 * abs(ref).max()
    assert np.array_equal(K.indptr, ref.indptr) and np.array_equal(K.indices, ref.indices)
    # The general route gives the same matrix for arbitrary (not translation-invariant) input.
    Ke = rng.standard_normal((len(cells), 12, 12))
    assert abs(pattern.assemble_matrix(Ke) - _coo_reference(cells, len(points), Ke)).max() < 1e-12


def test_assembled_matrices_do_not_share_data(rng):
    points, cells = structured_box(1)
    pattern = CSRPattern(cells, len(points))
    K1 = pattern.assemble_edge_blocks(rng.standard_normal((len(cells), 6, 3, 3)))
    K2 = pattern.assemble_edge_blocks(rng.standard_normal((len(cells), 6, 3, 3)))
    assert not np.shares_memory(K1.data, K2.data)
    K1.indices[0] = 1  # a caller may edit its matrix in place without touching the pattern
    assert not np.shares_memory(K1.indices, pattern.indices)
    assert pattern.indices[0] != 1 and np.array_equal(K2.indices, pattern.indices)


def test_edge_block_map_refuses_bad_layout():
    points, cells = structured_box(1)
    with pytest.raises(ValueError, match="layout"):
        CSRPattern(cells, len(points)).edge_block_map("mxrc")


# ------------------------------------------------------------------ the study
@pytest.fixture(scope="module")
def tiny_timing(tmp_path_factory):
    pytest.importorskip("matplotlib")
    from comparisons.timing import run_timing

    out = tmp_path_factory.mktemp("timing")
    methods = ["mjed", "classical"]
    from reference_fem import dolfinx_available

    if dolfinx_available():
        methods.append("dolfinx")
    result = run_timing("StVenantKirchhoff,NeoHookean", "single-tet", iterations=2, repeats=3, methods=methods,
                        out_dir=str(out), json_path=str(out / "t.json"), memory=False)
    return result, out, methods


def test_timing_json_schema(tiny_timing):
    result, out, methods = tiny_timing
    on_disk = json.loads((out / "t.json").read_text())
    assert on_disk == json.loads(json.dumps(result))
    assert {"mesh", "results", "ratios", "provenance"} <= set(on_disk)
    assert on_disk["mesh"] == {"name": "single-tet", "n_cells": 1, "n_nodes": 4}
    assert all(set(r) == RESULT_KEYS for r in on_disk["results"])
    combos = {(r["material"], r["method"], r["what"]) for r in on_disk["results"]}
    assert combos == {(m, meth, w) for m in ("StVenantKirchhoff", "NeoHookean") for meth in methods
                      for w in ("force+stiffness", "force", "stiffness")}
    for r in on_disk["results"]:
        assert r["repeats"] == 3 and 0 < r["min_s"] <= r["median_s"] <= r["max_s"]
    prov = on_disk["provenance"]
    for key in ("cpu", "logical_cores", "python", "numpy", "scipy", "dolfinx", "petsc4py", "git_commit"):
        assert key in prov


def test_ratios_are_formed_per_repeat(tiny_timing):
    result, _, methods = tiny_timing
    assert len(result["ratios"]) == 2 * 3 * (len(methods) - 1)
    for r in result["ratios"]:
        per = np.asarray(r["per_repeat"])
        assert per.shape == (3,)
        assert r["median"] == pytest.approx(np.median(per)) and r["min"] == min(per) and r["max"] == max(per)
        # The ratio of medians is in general not the median of per-repeat ratios; what
        # must hold is that each ratio lies within the spread the two methods' times allow.
        other = r["ratio"].split("/")[0]
        t = {(x["method"]): x for x in result["results"] if x["material"] == r["material"] and x["what"] == r["what"]}
        assert t[other]["min_s"] / t["mjed"]["max_s"] <= per.min() * (1 + 1e-12)
        assert per.max() <= t[other]["max_s"] / t["mjed"]["min_s"] * (1 + 1e-12)
    targets = {t["target"] for t in result["targets"]}
    assert any("classical" in t for t in targets) and any("5x" in t for t in targets)


def test_markdown_and_png_written(tiny_timing):
    result, out, methods = tiny_timing
    md = (out / "timing.md").read_text()
    assert "| StVenantKirchhoff |" in md and "classical/mjed" in md and "Machine:" in md
    png = out / "timing_fig2.png"
    assert str(png) in result["figures"] and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_study_input_is_refused():
    from comparisons.timing import run_timing

    with pytest.raises(ValueError, match="method"):
        run_timing("NeoHookean", "single-tet", methods=["mjed", "abaqus"], out_dir=None, memory=False)
    with pytest.raises(ValueError, match="iterations"):
        run_timing("NeoHookean", "single-tet", iterations=0, out_dir=None, memory=False)


@pytest.mark.skipif(not os.path.exists("/proc/self/clear_refs"), reason="peak memory needs Linux /proc")
def test_scaling_quick_runs_in_subprocesses(tmp_path):
    pytest.importorskip("matplotlib")
    from comparisons.timing import run_scaling

    result = run_scaling([60, 400], methods=["mjed", "classical"], repeats=1, out_dir=str(tmp_path))
    assert {(r["method"], r["n_cells"]) for r in result["rows"]} == {(m, n) for m in ("mjed", "classical") for n in (48, 384)}
    for r in result["rows"]:
        assert r["seconds"] > 0 and r["peak_bytes"] >= 0
    assert set(result["stopped"]) == {"mjed", "classical"}
    assert (tmp_path / "timing_scaling.png").exists() and (tmp_path / "scaling.md").exists()
