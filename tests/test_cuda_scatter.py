"""The element and edge assemblies of the cuda backend (mjed.cuda.codegen.Assembly): each cell
stores its 144 stiffness entries (or its six edge blocks, 54), a gather kernel sums them into
the CSR values through a per-mesh incidence built on the host. The incidences against a dense
assembly (no Numba's CUDA), damaged ones caught; the option at generation (the atomic kernel
unchanged, the others without atomic adds into the stiffness, the option in the cache name);
the three assemblies on Numba's CUDA simulator
against each other and the NumPy engine, FP64 and FP32, for NeoHookean and Ogden.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import box_mesh
from cuda_support import run_on_simulator

import mjed
from mjed.compiled import numba_available
from mjed.compiled.codegen import EDGES
from mjed.cuda.codegen import (
    BLOCK_ENTRIES,
    EDGE_ENTRIES,
    Assembly,
    CudaTarget,
    block_map,
    edge_incidence,
    element_incidence,
)
from mjed.sparse import CSRPattern

ROOT = Path(__file__).resolve().parents[1]


def _dense(cells: np.ndarray, n: int, ke: np.ndarray) -> np.ndarray:
    """The stiffness assembled entry by entry from per-cell entries ke (144, m): the reference."""
    K = np.zeros((3 * n, 3 * n))
    for e, nodes in enumerate(cells):
        for a in range(4):
            for b in range(4):
                for r in range(3):
                    for c in range(3):
                        K[3 * nodes[a] + r, 3 * nodes[b] + c] += ke[9 * (4 * a + b) + 3 * r + c, e]
    return K


def _layout(n: int = 2):
    points, cells = box_mesh(n, jitter=0.1)
    pattern = CSRPattern(cells, len(points))
    blk, _ = block_map(cells, pattern.indptr, pattern.indices, len(points))
    return cells, len(points), pattern, element_incidence(blk, pattern.indptr, len(points))


def test_incidence_sums_to_the_dense_assembly():
    cells, n, pattern, inc = _layout()
    ke = np.random.default_rng(1).standard_normal((BLOCK_ENTRIES, len(cells)))
    data = inc.gather(ke, pattern.nnz)
    K = np.zeros((3 * n, 3 * n))
    rows = np.repeat(np.arange(3 * n), np.diff(pattern.indptr))
    K[rows, pattern.indices] = data
    np.testing.assert_allclose(K, _dense(cells, n, ke), rtol=0, atol=1e-13)
    # every block written, each cell block counted once, offsets consistent
    assert inc.blocks * 9 == pattern.nnz and inc.offsets[-1] == 16 * len(cells)
    assert np.all(np.diff(inc.offsets) >= 1)
    assert np.array_equal(
        np.sort(inc.contributions % len(cells)), np.repeat(np.arange(len(cells)), 16)
    )


def test_a_damaged_incidence_is_caught_by_the_dense_check():
    cells, n, pattern, inc = _layout(1)
    ke = np.random.default_rng(2).standard_normal((BLOCK_ENTRIES, len(cells)))
    good = inc.gather(ke, pattern.nnz)
    contributions = inc.contributions.copy()
    contributions[[0, 1]] = contributions[[1, 0]] + np.array([0, len(cells)])  # misplaced
    bad = type(inc)(inc.first, inc.rowlen, inc.offsets, contributions, inc.cells)
    assert np.abs(bad.gather(ke, pattern.nnz) - good).max() > 1e-3


def _element_of_edges(edges: np.ndarray) -> np.ndarray:
    """The 144 per-cell entries (144, m) of six stored edge blocks (54, m), by the rules the
    edge assembly relies on: block (a, b) = K_ab, (b, a) = K_ab^T, (a, a) = -sum_b K_ab.
    """
    m = edges.shape[1]
    blocks = np.zeros((4, 4, 3, 3, m))
    for k, (a, b) in enumerate(EDGES):
        K = edges[9 * k : 9 * k + 9].reshape(3, 3, m)
        blocks[a, b] = K
        blocks[b, a] = K.transpose(1, 0, 2)
        blocks[a, a] -= K
        blocks[b, b] -= K.transpose(1, 0, 2)
    return blocks.reshape(BLOCK_ENTRIES, m)


def _edge_layout(n: int = 2):
    cells, nodes, pattern, inc = _layout(n)
    return cells, nodes, pattern, edge_incidence(inc)


def _csr_dense(pattern, data: np.ndarray) -> np.ndarray:
    n3 = pattern.shape[0]
    K = np.zeros((n3, n3))
    K[np.repeat(np.arange(n3), np.diff(pattern.indptr)), pattern.indices] = data
    return K


def test_edge_incidence_sums_to_the_dense_assembly():
    cells, n, pattern, inc = _edge_layout()
    m = len(cells)
    edges = np.random.default_rng(4).standard_normal((EDGE_ENTRIES, m))  # not symmetric
    K = _csr_dense(pattern, inc.gather(edges, pattern.nnz))
    np.testing.assert_allclose(K, _dense(cells, n, _element_of_edges(edges)), rtol=0, atol=1e-12)
    # each cell edge in four blocks: (a, b), (b, a), (a, a) and (b, b)
    assert inc.offsets[-1] == 24 * m and inc.blocks * 9 == pattern.nnz
    assert np.array_equal(np.sort((inc.contributions >> 1) % m), np.repeat(np.arange(m), 24))
    assert int(inc.diagonal.sum()) == n and np.all(np.diff(inc.offsets) >= 1)
    # FP32 stays FP32
    assert inc.gather(edges.astype(np.float32), pattern.nnz).dtype == np.float32


@pytest.mark.parametrize("damage", ["transpose flag", "diagonal flag", "edge"])
def test_a_damaged_edge_incidence_is_caught_by_the_dense_check(damage):
    cells, n, pattern, inc = _edge_layout(1)
    m = len(cells)
    edges = np.random.default_rng(5).standard_normal((EDGE_ENTRIES, m))
    reference = _dense(cells, n, _element_of_edges(edges))
    contributions, diagonal = inc.contributions.copy(), inc.diagonal.copy()
    off = np.flatnonzero(np.repeat(diagonal == 0, np.diff(inc.offsets)))[0]
    if damage == "transpose flag":
        contributions[off] ^= 1
    elif damage == "diagonal flag":
        diagonal[0] ^= 1
    else:  # the next cell's edge block
        contributions[off] += 2 if (contributions[off] >> 1) % m < m - 1 else -2
    bad = type(inc)(inc.first, inc.rowlen, inc.offsets, contributions, m, diagonal)
    assert np.abs(_csr_dense(pattern, bad.gather(edges, pattern.nnz)) - reference).max() > 1e-3


def test_incidence_refuses_another_pattern():
    cells, n, pattern, _ = _layout(1)
    blk, _ = block_map(cells, pattern.indptr, pattern.indices, n)
    with pytest.raises(ValueError, match="not of this pattern"):
        element_incidence(blk + 1, pattern.indptr, n)


def test_assembly_option_is_validated_and_default_atomic():
    assert (
        Assembly.of("element") is Assembly.ELEMENT
        and Assembly.of(Assembly.ATOMIC) is Assembly.ATOMIC
    )
    assert CudaTarget().assembly is Assembly.ATOMIC
    with pytest.raises(ValueError, match="atomic, element, edge"):
        CudaTarget(np.float64, "shared")
    assert Assembly.of("edge").entries == EDGE_ENTRIES == 54
    assert Assembly.ELEMENT.entries == BLOCK_ENTRIES and Assembly.ATOMIC.entries == 0


def test_element_kernel_stores_every_entry_once_and_adds_only_the_force():
    from common.cases import default_material
    from mjed.compiled.codegen import kernel_source
    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape

    points, cells = box_mesh(1)
    mesh = mjed.TetMesh(points, cells)
    material = default_material("NeoHookean")
    shape = kernel_shape(lower_groups(material.decomposition(), mesh.D))
    atomic = kernel_source(shape, CudaTarget(np.float64))
    element = kernel_source(shape, CudaTarget(np.float64, Assembly.ELEMENT))
    # both kernels (force+K and force alone) hold the stiffness code, the second with
    # want_stiffness = False so that the compiler removes it
    assert atomic.count("cuda.atomic.add(data") == 2 * BLOCK_ENTRIES
    assert "cuda.atomic.add(data" not in element and "rowlen[" not in element
    stores = [f"data[{j}, e] = " for j in range(BLOCK_ENTRIES)]
    assert all(element.count(s) == 2 for s in stores)  # once in each of the two kernels
    assert element.count("cuda.atomic.add(force") == atomic.count("cuda.atomic.add(force") == 24
    assert "element stiffness" in element and "element" not in atomic


def _mjed_source(material_name: str, assembly) -> str:
    from common.cases import default_material
    from mjed.compiled.codegen import kernel_source
    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape

    points, cells = box_mesh(1)
    mesh = mjed.TetMesh(points, cells)
    material = default_material(material_name)
    shape = kernel_shape(lower_groups(material.decomposition(), mesh.D))
    return kernel_source(shape, CudaTarget(np.float64, assembly))


@pytest.mark.parametrize("material", ["NeoHookean", "Ogden"])
def test_edge_kernel_stores_the_six_edge_blocks_and_adds_only_the_force(material):
    source = _mjed_source(material, "edge")
    assert "cuda.atomic.add(data" not in source and "rowlen[" not in source
    assert source.count("data[") == 2 * EDGE_ENTRIES  # 54 stores in each of the two kernels
    for k in range(len(EDGES)):  # edge k's block as the atomic path sends it to (a, b)
        for r in range(3):
            for c in range(3):
                assert source.count(f"data[{9 * k + 3 * r + c}, e] = K{k}_{r}{c}\n") == 2
    assert source.count("cuda.atomic.add(force") == 24 and "edge stiffness" in source


def test_atomic_path_sends_the_stored_edge_block_to_a_b():
    # the block the edge kernel stores for edge k is what the atomic kernel adds at (a, b)
    source = _mjed_source("NeoHookean", "atomic").splitlines()
    for k, (a, b) in enumerate(EDGES):
        at = source.index(
            next(line for line in source if line.strip() == f"p = blk[e, {4 * a + b}]")
        )
        assert source[at + 1].strip() == f"cuda.atomic.add(data, p + 0 * L{a} + 0, K{k}_00)"
        assert source[at + 2].strip() == f"cuda.atomic.add(data, p + 0 * L{a} + 1, K{k}_01)"


def test_classical_element_kernel_follows_the_option():
    from common.cases import default_material
    from reference_fem import classical_materials as cm
    from reference_fem.classical_codegen import ClassicalCudaTarget, classical_source
    from reference_fem.classical_compiled import lower_law

    shape = lower_law(cm.classical_law(default_material("NeoHookean")))[0]
    source = classical_source(shape, ClassicalCudaTarget(np.float32, "element"))
    assert "cuda.atomic.add(data" not in source and source.count("data[143, e] = ") == 2
    with pytest.raises(NotImplementedError, match="no edge assembly"):
        ClassicalCudaTarget(np.float64, "edge")


@pytest.fixture(scope="module")
def simulated():
    script = str(ROOT / "tests" / "cuda_scatter_simulated.py")
    return run_on_simulator([script, "NeoHookean", "Ogden"], timeout=600)


@pytest.mark.skipif(not numba_available(), reason="needs Numba's CUDA target")
@pytest.mark.parametrize("dtype,tol", [("float64", 1e-13), ("float32", 5e-5)])
@pytest.mark.parametrize("assembly", ["element", "edge"])
def test_gathered_assembly_equals_atomic_and_numpy_on_the_simulator(
    simulated, assembly, dtype, tol
):
    assert simulated["simulated"]
    cases = [c for c in simulated["cases"] if c["dtype"] == dtype]
    assert {c["material"] for c in cases} == {"NeoHookean", "Ogden"}
    for c in cases:
        assert c[f"{assembly}_same_pattern"], c
        for key in ("vs_atomic_K", "vs_atomic_f", "device_out_K", "device_out_f"):
            value = c[f"{assembly}_{key}"]
            assert value <= tol, (c["material"], assembly, key, value)
        assert c[f"{assembly}_vs_numpy_K"] <= tol and c[f"{assembly}_vs_numpy_f"] <= tol, c
        assert c[f"{assembly}_force_alone"] <= tol, c


@pytest.mark.skipif(not numba_available(), reason="needs Numba's CUDA target")
def test_scatter_benchmark_code_path_runs_on_the_simulator():
    # comparisons.timing.gpu_scatter only times a device; its code path on one tiny cube here
    from comparisons.timing.gpu_scatter import VARIANTS

    code = (
        "import json; from comparisons.timing.gpu_scatter import measure, print_figures; "
        "fig = measure(sizes=(48, 200), min_time=0.0, budget=0.0); lines = []; "
        "print_figures(fig, lines.append); print(json.dumps({'fig': fig, 'text': lines}))"
    )
    run = run_on_simulator(["-c", code], timeout=600)
    fig, text = run["fig"], run["text"]
    assert fig["simulated"] and fig["not_started"] == [200]  # past the budget
    (row,) = fig["sizes"]
    assert row["cells"] == 48 and row["blocks"] * 9 == row["nnz"] and not row["skipped"]
    assert row["edge_incidence_s"] >= 0
    for dtype in ("float64", "float32"):
        p = row["precisions"][dtype]
        assert p["check"]["agrees"] and p["check"]["K"] <= p["check"]["tol"]
        assert p["check"]["edge"]["agrees"] and p["check"]["edge"]["K"] <= p["check"]["tol"]
        assert set(p["timings"]) == set(VARIANTS) and len(VARIANTS) == 8
        assert all(t["tets_per_s"] > 0 and t["repeats"] >= 3 for t in p["timings"].values())
        assert p["ratios"]["atomic f+K / element f+K"] > 0
        assert p["ratios"]["atomic f+K / edge f+K"] > 0
        assert p["ratios"]["element f+K / edge f+K"] > 0
        for name in ("gather", "edge gather", "edge f+K"):
            assert any(line.strip().startswith(f"{dtype} {name} ") for line in text), name
        assert any(f"{dtype} edge vs atomic" in line and "agrees" in line for line in text)
    assert "simulator: figures meaningless" in text[0]


def test_scatter_benchmark_refuses_the_simulator(monkeypatch, capsys):
    from comparisons.timing import gpu_scatter

    monkeypatch.setenv("NUMBA_ENABLE_CUDASIM", "1")
    assert gpu_scatter.main(["--sizes", "48"]) == 2
    assert "needs a real NVIDIA GPU" in capsys.readouterr().err


def test_element_extra_bytes():
    from comparisons.timing.gpu_scatter import extra_bytes

    # 1e6 tets in FP64: the per-cell entries alone are 1.15 GB, the edge blocks 0.43 GB
    element = 144 * 8 * 10**6 + 4 * (16 * 10**6 + 1)
    assert extra_bytes(1_000_000, 0, "float64") == element + 54 * 8 * 10**6 + 4 * (24 * 10**6 + 1)
    assert extra_bytes(20_000_000, 0, "float32") % 8 == 0  # int64 indices past 2**31 entries
