"""mjed.cuda.threads: one block size for every kernel, smaller on the simulator, and kernels
whose results cannot depend on it.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from mjed.cuda.threads import (
    DEVICE_THREADS,
    REDUCTION_BLOCKS,
    SIMULATED_BLOCKS,
    SIMULATED_THREADS,
    ZEROING_BLOCKS,
    block_cap,
    blocks_for,
    threads_per_block,
)

CUDA = Path(__file__).resolve().parents[1] / "mjed" / "cuda"


def test_the_simulator_runs_small_blocks_and_a_device_four_warps():
    assert threads_per_block({}) == DEVICE_THREADS == 128
    assert threads_per_block({"NUMBA_ENABLE_CUDASIM": "0"}) == DEVICE_THREADS
    assert threads_per_block({"NUMBA_ENABLE_CUDASIM": "1"}) == SIMULATED_THREADS == 8


def test_the_variable_sets_the_size_for_either():
    assert threads_per_block({"NUMBA_ENABLE_CUDASIM": "1", "MJED_CUDA_THREADS": "128"}) == 128
    assert threads_per_block({"MJED_CUDA_THREADS": " 32 "}) == 32


@pytest.mark.parametrize("raw", ["0", "-8", "2048", "many", "8.5"])
def test_a_size_no_block_can_have_is_refused_naming_the_variable(raw):
    with pytest.raises(ValueError, match=f"MJED_CUDA_THREADS='{re.escape(raw)}'"):
        threads_per_block({"MJED_CUDA_THREADS": raw})


def test_no_kernel_shares_memory_or_synchronises_a_block():
    """What makes the block size a question of speed alone (mjed.cuda.threads): a kernel that
    used shared memory or __syncthreads could depend on it, and would need tests at the device's
    block size, which the simulator then does not run.
    """
    sources = {p.name: p.read_text() for p in CUDA.glob("*.py") if p.name != "threads.py"}
    assert "step_kernels.py" in sources and "codegen.py" in sources
    for name, text in sources.items():
        for word in ("cuda.shared", "syncthreads", "threadfence_block", "blockDim", "threadIdx"):
            assert word not in text, (name, word)
    # and no block size written in a launch but one thread ([1, 1], a few scalars cleared):
    # every other launch takes THREADS_PER_BLOCK
    for name, text in sources.items():
        assert not re.search(r"\[[^\[\]]*,\s*(?!1\s*\])\d+\s*\]\(", text), name


# ------------------------------------------------------------------ the blocks of a launch
@pytest.mark.parametrize("items", [0, 1, 127, 128, 129, 1000, 10**6])
def test_a_device_launch_runs_one_thread_per_item(items):
    threads, cap = threads_per_block({}), block_cap({})
    assert cap is None
    one_per_item = max(1, -(-items // DEVICE_THREADS))
    assert blocks_for(items, threads=threads, cap=cap) == one_per_item
    assert blocks_for(items, REDUCTION_BLOCKS, threads=threads, cap=cap) == min(one_per_item, 256)
    assert blocks_for(items, ZEROING_BLOCKS, threads=threads, cap=cap) == min(one_per_item, 1024)


def test_the_simulator_caps_every_launch_at_a_few_blocks():
    sim = {"NUMBA_ENABLE_CUDASIM": "1"}
    threads, cap = threads_per_block(sim), block_cap(sim)
    assert cap == SIMULATED_BLOCKS == 2
    assert blocks_for(1000, threads=threads, cap=cap) == 2
    assert blocks_for(1000, REDUCTION_BLOCKS, threads=threads, cap=cap) == 2
    assert blocks_for(9, threads=threads, cap=cap) == 2  # two blocks, the second partly idle
    assert blocks_for(8, threads=threads, cap=cap) == blocks_for(0, threads=threads, cap=cap) == 1


def test_the_blocks_variable_caps_either():
    assert block_cap({"MJED_CUDA_BLOCKS": "4"}) == 4
    assert block_cap({"NUMBA_ENABLE_CUDASIM": "1", "MJED_CUDA_BLOCKS": " 1000 "}) == 1000
    assert blocks_for(10**6, threads=128, cap=4) == 4


@pytest.mark.parametrize("raw", ["0", "-2", "two", "1.5", str(2**31)])
def test_a_cap_no_launch_can_have_is_refused_naming_the_variable(raw):
    with pytest.raises(ValueError, match=f"MJED_CUDA_BLOCKS='{re.escape(raw)}'"):
        block_cap({"MJED_CUDA_BLOCKS": raw})


# ------------------------------------------------------------------ every kernel a stride loop
#: kernels that run on one thread (``if cuda.grid(1) == 0:``): they clear a few scalars
SINGLE_THREAD_KERNELS = {"clear"}


def _is_call(node, dotted: str, *args) -> bool:
    """Whether ``node`` is the call ``dotted(*args)`` (constant arguments)."""
    return (
        isinstance(node, ast.Call)
        and ast.unparse(node.func) == dotted
        and [ast.unparse(a) for a in node.args] == [repr(a) for a in args]
    )


def _kernels(tree: ast.Module):
    """The functions decorated ``@cuda.jit`` that are kernels (not ``device=True``)."""
    for fn in ast.walk(tree):
        if isinstance(fn, ast.FunctionDef):
            jit = [d for d in fn.decorator_list if "cuda.jit" in ast.unparse(d)]
            if jit and not any("device=True" in ast.unparse(d) for d in jit):
                yield fn


def _stride_names(fn: ast.FunctionDef):
    """(start, stride) of each ``start, stride = cuda.grid(1), cuda.gridsize(1)`` in fn."""
    for node in ast.walk(fn):
        if (
            isinstance(node, ast.Assign)
            and isinstance(node.targets[0], ast.Tuple)
            and isinstance(node.value, ast.Tuple)
            and len(node.value.elts) == 2
            and _is_call(node.value.elts[0], "cuda.grid", 1)
            and _is_call(node.value.elts[1], "cuda.gridsize", 1)
        ):
            yield tuple(ast.unparse(t) for t in node.targets[0].elts)


def _stride_loops(fn: ast.FunctionDef, start: str, stride: str):
    """The loops ``for i in range(start, n, stride)`` of fn."""
    for node in ast.walk(fn):
        if isinstance(node, ast.For) and _is_call_of_range(node.iter):
            args = [ast.unparse(a) for a in node.iter.args]
            if len(args) == 3 and args[0] == start and args[2] == stride:
                yield node


def _is_call_of_range(node) -> bool:
    return isinstance(node, ast.Call) and ast.unparse(node.func) == "range"


def stride_faults(fn: ast.FunctionDef) -> list:
    """What keeps kernel ``fn`` from being a grid-stride loop (module docstring of
    mjed.cuda.threads): a thread index used other than as a stride loop's start, no stride
    loop, or a ``return`` inside one (the items after it would be skipped).
    """
    grids = [n for n in ast.walk(fn) if _is_call(n, "cuda.grid", 1)]
    if fn.name in SINGLE_THREAD_KERNELS:
        single = [n for n in ast.walk(fn) if isinstance(n, ast.Compare)]
        ok = len(grids) == 1 and any(ast.unparse(c) == "cuda.grid(1) == 0" for c in single)
        return [] if ok else [f"{fn.name}: not a single-thread kernel"]
    names = list(_stride_names(fn))
    if len(names) != 1 or len(grids) != 1:
        return [f"{fn.name}: cuda.grid(1) not (only) the start of a stride loop"]
    start, stride = names[0]
    loops = list(_stride_loops(fn, start, stride))
    faults = [] if loops else [f"{fn.name}: no loop range({start}, n, {stride})"]
    uses = [n for n in ast.walk(fn) if isinstance(n, ast.Name) and n.id in (start, stride)]
    if len(uses) != 2 + 2 * len(loops):  # the assignment, then each loop's two arguments
        faults.append(f"{fn.name}: {start} or {stride} used outside a stride loop's range")
    for loop in loops:
        if any(isinstance(n, ast.Return) for n in ast.walk(loop)):
            faults.append(f"{fn.name}: a return inside the stride loop skips items")
    return faults


def _generated_sources() -> dict:
    """Fresh sources of the generated cell kernels: two materials, every assembly and dtype,
    MJED and classical.
    """
    import numpy as np
    from conftest import MATERIALS

    from mjed.compiled.codegen import kernel_source
    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape
    from mjed.cuda.codegen import Assembly, CudaTarget
    from reference_fem import classical_materials as cm
    from reference_fem.classical_codegen import ClassicalCudaTarget, classical_source
    from reference_fem.classical_compiled import lower_law

    sources = {}
    for name in ("NeoHookean", "Ogden"):
        shape = kernel_shape(lower_groups(MATERIALS[name].decomposition(), np.zeros((1, 4, 3))))
        law = lower_law(cm.classical_law(MATERIALS[name]))[0]
        for dtype in (np.float64, np.float32):
            for assembly in Assembly:
                target = CudaTarget(dtype, assembly)
                sources[f"{name} {assembly.value} {dtype.__name__}"] = kernel_source(shape, target)
            sources[f"{name} classical {dtype.__name__}"] = classical_source(
                law, ClassicalCudaTarget(np.dtype(dtype))
            )
    return sources


def test_stride_faults_names_a_per_item_kernel_and_a_return_in_the_loop():
    per_item = (
        "@cuda.jit\ndef k(a):\n    i = cuda.grid(1)\n    if i < a.shape[0]:\n        a[i] = 0\n"
    )
    early = (
        "@cuda.jit\ndef k(a):\n    start, stride = cuda.grid(1), cuda.gridsize(1)\n"
        "    for i in range(start, a.shape[0], stride):\n        if a[i] > 0:\n"
        "            return\n        a[i] = 0\n"
    )
    assert stride_faults(next(_kernels(ast.parse(per_item))))
    assert "return" in stride_faults(next(_kernels(ast.parse(early))))[0]


def test_every_kernel_is_a_grid_stride_loop():
    """What lets the simulator cap a launch's blocks (mjed.cuda.threads) without skipping an
    item: every kernel, hand-written or generated, loops over its items by the grid's stride.
    """
    sources = {p.name: p.read_text() for p in CUDA.glob("*.py")}
    sources.update(_generated_sources())
    names, faults = set(), []
    for label, text in sources.items():
        for fn in _kernels(ast.parse(text)):
            names.add(fn.name)
            faults += [f"{label}: {fault}" for fault in stride_faults(fn)]
    assert not faults
    expected = {"mjed_cells", "mjed_force", "classical_cells", "classical_force", "_spmv"}
    assert expected | SINGLE_THREAD_KERNELS <= names and len(names) >= 34


# ------------------------------------------------------------------ every launch through blocks_for
def _launches(tree: ast.Module):
    """(grid, block) expressions of every launch ``kernel[grid, block](...)`` in tree."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Subscript):
            index = node.func.slice
            if isinstance(index, ast.Tuple) and len(index.elts) == 2:
                yield index.elts[0], index.elts[1]


def _last(node) -> str:
    """The name an expression ends in: x for x, self.x and a.b.x; '' for anything else."""
    if isinstance(node, ast.Name):
        return node.id
    return node.attr if isinstance(node, ast.Attribute) else ""


def _derived(trees, roots: set, call: str = "") -> set:
    """The names (last components) assigned, in any of ``trees``, a call of ``call`` or one of
    the names already found (from ``roots``), element by element in tuple assignments.
    """
    found = set(roots)
    pairs = []
    for tree in trees:
        for node in ast.walk(tree):
            if isinstance(node, ast.Assign):
                for target in node.targets:
                    both = isinstance(target, ast.Tuple) and isinstance(node.value, ast.Tuple)
                    if both and len(target.elts) == len(node.value.elts):
                        pairs += zip(target.elts, node.value.elts)
                    else:
                        pairs.append((target, node.value))
    grew = True
    while grew:
        grew = False
        for target, value in pairs:
            from_call = call and isinstance(value, ast.Call) and _last(value.func) == call
            if (
                _last(target)
                and _last(target) not in found
                and (from_call or _last(value) in found)
            ):
                found.add(_last(target))
                grew = True
    return found


def test_every_launch_takes_its_blocks_from_blocks_for():
    """The GPU's launch configuration and the simulator's cap decided in one place
    (mjed.cuda.threads.blocks_for), but for the one-thread launches ``[1, 1]``.
    """
    paths = [p for p in CUDA.glob("*.py") if p.name != "threads.py"]
    paths.append(CUDA.parents[1] / "reference_fem" / "classical_cuda.py")
    trees = {p.name: ast.parse(p.read_text()) for p in paths}
    blocks = _derived(trees.values(), set(), call="blocks_for")
    threads = _derived(trees.values(), {"THREADS_PER_BLOCK"})
    launches = 0
    for name, tree in trees.items():
        for grid, block in _launches(tree):
            launches += 1
            single = ast.unparse(grid) == ast.unparse(block) == "1"
            from_blocks_for = isinstance(grid, ast.Call) and _last(grid.func) == "blocks_for"
            assert single or from_blocks_for or _last(grid) in blocks, (name, ast.unparse(grid))
            assert single or _last(block) in threads, (name, ast.unparse(block))
    assert launches >= 40
