"""The timing study runs end to end on a tiny mesh (no timing assertions), the structured
mesh generator, and the edge-block CSR assembly it relies on.
"""

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
    faces = np.sort(
        np.concatenate(
            [cells[:, [1, 2, 3]], cells[:, [0, 2, 3]], cells[:, [0, 1, 3]], cells[:, [0, 1, 2]]]
        ),
        axis=1,
    )
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
FAST = ["mjed", "classical"]


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    pytest.importorskip("matplotlib")
    from comparisons.timing.study import timing_study

    out = tmp_path_factory.mktemp("timing")
    result = timing_study(
        "StVenantKirchhoff,NeoHookean",
        "single-tet",
        quick=True,
        out_dir=str(out),
        methods=FAST,
        memory=False,
    )
    return result, out


def test_study_result_statuses_checks_and_protocol(tiny_study):
    from common.result import Status

    result, out = tiny_study
    assert result.key == "timing"
    assert result.status in (Status.PASSED, Status.TARGET_MISSED)
    assert result.partial and any(
        "quick" in n for n in result.not_covered
    )  # a quick run is never complete
    assert result.protocol.startswith("quick:")
    assert all(r["protocol"] == "quick" for r in result.data["results"])
    # every verification passed and is a tolerance; the speed comparisons are targets
    tol = [c for c in result.checks if c.kind == "tolerance"]
    assert tol and all(c.passed for c in tol) and all("classical" in c.name for c in tol)
    targets = [c for c in result.checks if c.kind == "target"]
    assert any("classical FEM (NumPy pair)" in c.name for c in targets)
    assert any(
        "paper's claim" in c.name and c.measured is None for c in targets
    )  # compiled pair not timed here
    assert result.command.startswith(
        "mjed-verify timing --material StVenantKirchhoff,NeoHookean --mesh single-tet"
    )
    assert "--quick" in result.command and "--no-memory" in result.command
    json.dumps(result.to_dict())  # JSON-serialisable as it stands


def test_study_data_schema_and_ratios_per_round(tiny_study):
    result, _ = tiny_study
    data = result.data
    assert data["mesh"]["name"] == "single-tet" and data["mesh"]["n_cells"] == 1
    combos = {(r["material"], r["method"], r["what"]) for r in data["results"]}
    assert combos == {
        (m, meth, w)
        for m in ("StVenantKirchhoff", "NeoHookean")
        for meth in FAST
        for w in ("force+stiffness", "force", "stiffness")
    }
    for r in data["results"]:
        assert 0 < r["min_s"] <= r["median_s"] <= r["max_s"] and r["calls_per_repeat"] >= 1
        assert r["stopped_by"] in ("spread", "budget", "rounds")
    for r in data["ratios"]:
        per = np.asarray(r["per_repeat"])
        assert (
            r["median"] == pytest.approx(np.median(per))
            and r["min"] == per.min()
            and r["max"] == per.max()
        )
        num, den = r["ratio"].split("/")
        t = {
            x["method"]: x
            for x in data["results"]
            if x["material"] == r["material"] and x["what"] == r["what"]
        }
        assert t[num]["min_s"] / t[den]["max_s"] <= per.min() * (1 + 1e-12)
        assert per.max() <= t[num]["max_s"] / t[den]["min_s"] * (1 + 1e-12)
    assert {r["ratio"] for r in data["ratios"]} == {"classical/mjed"}
    assert data["floor"]["seconds"] > 0 and data["bandwidth"]["GB_per_s"] > 0
    assert set(data["opcount"]) == {"StVenantKirchhoff", "NeoHookean"}


def test_study_blocks_and_figure(tiny_study):
    from common.blocks import Figure, Table

    result, out = tiny_study
    figs = [b for b in result.blocks if isinstance(b, Figure)]
    assert figs and (out / "timing_fig2.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    captions = " ".join(b.caption for b in result.blocks if isinstance(b, Table))
    for words in ("quick protocol", "operation-count model", "bandwidth floor", "Speed targets"):
        assert words in captions


def test_paper_protocol_is_100_calls_by_3_rounds():
    from comparisons.timing.study import timing_study

    result = timing_study(
        "NeoHookean", "single-tet", protocol="paper", methods=FAST, memory=False, out_dir=None
    )
    assert result.protocol.startswith("paper: 100 calls")
    assert not result.not_covered
    for r in result.data["results"]:
        assert r["calls_per_repeat"] == 100 and r["repeats"] == 3 and r["protocol"] == "paper"


def test_a_plugged_in_peer_is_timed_only_when_it_matches():
    import mjed as mj
    from comparisons.timing import methods as tm
    from comparisons.timing.study import timing_study

    class Wrong:
        def __init__(self, points, cells, material):
            self.field = mj.HyperelasticForceField(mj.TetMesh(points, cells), material)

        def force_and_stiffness(self, x):
            f, K = self.field.force_and_stiffness(x)
            return 1.001 * f, K

    good = tm.register(
        tm.TimedMethod(
            "test-good",
            "good peer",
            "peer",
            False,
            lambda p, c, m: mj.HyperelasticForceField(mj.TetMesh(p, c), m),
        )
    )
    bad = tm.register(tm.TimedMethod("test-wrong", "wrong peer", "peer", False, Wrong))
    try:
        result = timing_study(
            "NeoHookean",
            "single-tet",
            quick=True,
            methods=["mjed", good.name, bad.name],
            memory=False,
            out_dir=None,
        )
    finally:
        del tm.METHODS[good.name], tm.METHODS[bad.name]
    timed = {r["method"] for r in result.data["results"]}
    assert good.name in timed and bad.name not in timed
    skipped = {k["method"]: k["reason"] for k in result.data["skipped"]}
    assert "differs from NumPy MJED" in skipped[bad.name]
    # a peer that only has force_and_stiffness is timed on that alone
    assert {r["what"] for r in result.data["results"] if r["method"] == good.name} == {
        "force+stiffness",
        "force",
        "stiffness",
    }


def test_bad_study_input_is_refused():
    from comparisons.timing.study import timing_study

    with pytest.raises(ValueError, match="unknown method 'abaqus'"):
        timing_study(
            "NeoHookean", "single-tet", methods=["mjed", "abaqus"], out_dir=None, memory=False
        )
    with pytest.raises(ValueError, match="must include 'mjed'"):
        timing_study("NeoHookean", "single-tet", methods=["classical"], out_dir=None, memory=False)
    with pytest.raises(ValueError, match="unknown protocol"):
        timing_study("NeoHookean", "single-tet", protocol="fast", out_dir=None, memory=False)


# ------------------------------------------------------------------ protocol and bandwidth
def test_protocol_stopping_rules():
    from comparisons.timing.protocol import PROTOCOLS, calls_for, relative_spread

    budget = PROTOCOLS["budget"]
    assert budget.should_stop(1, [0.0], 0.0) is None  # fewer than min_rounds
    assert budget.should_stop(3, [0.01, 0.04], 0.0) == "spread"
    assert budget.should_stop(3, [0.2], 0.0) is None
    assert budget.should_stop(3, [0.2], budget.budget_s + 1) == "budget"
    assert budget.should_stop(budget.max_rounds, [0.2], 0.0) == "rounds"
    assert (
        PROTOCOLS["paper"].should_stop(2, [0.0], 1e9) is None
        and PROTOCOLS["paper"].should_stop(3, [1.0], 0) == "rounds"
    )
    assert (
        calls_for(PROTOCOLS["paper"], 1.0) == 100
        and calls_for(budget, 0.001) == 20
        and calls_for(budget, 5.0) == 1
    )
    assert relative_spread([1.0, 2.0, 1.0, 1.1, 1.0]) == pytest.approx(0.1)
    assert relative_spread([1.0]) == float("inf")


def test_bandwidth_and_floor_sanity():
    from comparisons.timing.bandwidth import floor_bytes, measure_bandwidth

    bw = measure_bandwidth(8 * 2**20, repeats=2)
    assert 1e8 < bw.bytes_per_s < 1e13 and bw.array_bytes == 8 * 2**20
    # the floor counts every byte once: CSR values + force written, positions + cells + geometry
    # read
    assert floor_bytes(4, 1, 144) == 8 * 144 + 8 * 12 + 8 * 12 + 4 * 4 + 8 * 13
    assert floor_bytes(8, 2, 144) > floor_bytes(4, 1, 144)
    with pytest.raises(ValueError):
        measure_bandwidth(0)


# ------------------------------------------------------------------ scaling and the command line
@pytest.mark.skipif(
    not os.path.exists("/proc/self/clear_refs"), reason="peak memory needs Linux /proc"
)
def test_scaling_quick_runs_in_subprocesses(tmp_path):
    pytest.importorskip("matplotlib")
    from comparisons.timing.study import scaling_study

    result = scaling_study(
        quick=True, sizes=[60, 400], methods=["mjed", "classical"], repeats=1, out_dir=str(tmp_path)
    )
    rows = result.data["rows"]
    assert {(r["method"], r["n_cells"]) for r in rows} == {
        (m, n) for m in ("mjed", "classical") for n in (48, 384)
    }
    for r in rows:
        assert r["seconds"] > 0 and r["peak_bytes"] >= 0
    assert set(result.data["stopped"]) == {"mjed", "classical"}
    assert (tmp_path / "timing_scaling.png").exists()
    assert result.partial and result.title.endswith("from 48 to 384 cells")  # says what ran
    flat = [c for c in result.checks if "flat" in c.name]
    assert flat and flat[0].measured is None  # 48 and 384 cells do not span 1e4 to 1e6
    assert result.command.startswith("mjed-verify timing --scaling")


def test_timing_cli_json_exit_code_and_reproduce_line(tmp_path):
    from comparisons.cli import main

    path = tmp_path / "t.json"
    code = main(
        [
            "timing",
            "--quick",
            "--material",
            "NeoHookean",
            "--mesh",
            "single-tet",
            "--methods",
            "mjed,classical",
            "--no-memory",
            "--out",
            str(tmp_path / "out"),
            "--json",
            str(path),
        ]
    )
    payload = json.loads(path.read_text())
    assert code == 3  # a quick run is partial: never exit 0
    assert payload["key"] == "timing" and payload["partial"] is True
    assert payload["command"] == (
        "mjed-verify timing --material NeoHookean --mesh single-tet --methods mjed,classical "
        f"--protocol budget --quick --no-memory --out {tmp_path / 'out'} --json {path}"
    )
    assert main(["timing", "--methods", "mjed,abaqus", "--mesh", "single-tet"]) == 2
    assert main(["timing", "--methods", "classical", "--mesh", "single-tet"]) == 2
