"""The layers of the project, read from the source: no import upward, no cycle between files.

Layers, lowest first: ``mjed`` (the engine), ``meshes``, ``reference_fem`` (the oracles),
``common`` (results, verdicts, tolerances, states, cases, options, rendering), then the two
applications, ``conformance`` (checking other engines) and ``comparisons`` (the studies and the
command line, which also drives the checker). Every import counts, including those inside
functions: an import deferred for start-up time still ties the two files together.
"""

from __future__ import annotations

import ast
import pathlib
from typing import Dict, List, Set

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
LAYERS = ("mjed", "meshes", "reference_fem", "common", "conformance", "comparisons")
#: Third-party packages a layer must never import: mjed stays NumPy/SciPy (plus optional Numba).
FORBIDDEN = {
    "mjed": ("dolfinx", "ufl", "petsc4py", "basix", "ffcx", "mpi4py"),
    "common": ("dolfinx", "ufl", "petsc4py"),
}


def module_files(root: pathlib.Path, packages=LAYERS) -> Dict[str, pathlib.Path]:
    """Dotted module name -> file, for every module of ``packages`` under ``root``."""
    mods = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = path
    return mods


def imported_names(path: pathlib.Path) -> Set[str]:
    """Every absolute dotted name ``path`` imports, at any depth (functions included).

    ``from pkg import name`` gives ``pkg.name``: a submodule when ``name`` is one, otherwise it
    resolves to ``pkg`` itself (see :func:`import_graph`).
    """
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return names


def import_graph(mods: Dict[str, pathlib.Path]) -> Dict[str, Set[str]]:
    """Module -> the project modules it imports (a name resolves to its longest module prefix)."""

    def resolve(name: str):
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for mod, path in mods.items():
        graph[mod] = {resolve(n) for n in imported_names(path)} - {None, mod}
    return graph


def upward_imports(graph: Dict[str, Set[str]], layers=LAYERS) -> List[str]:
    rank = {p: i for i, p in enumerate(layers)}
    bad = []
    for mod, targets in graph.items():
        for t in targets:
            if rank[t.split(".")[0]] > rank[mod.split(".")[0]]:
                bad.append(f"{mod} -> {t}")
    return sorted(bad)


def cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


@pytest.fixture(scope="module")
def graph():
    return import_graph(module_files(ROOT))


def test_no_layer_imports_a_layer_above_it(graph):
    assert upward_imports(graph) == []


def test_no_cycle_between_files(graph):
    assert cycles(graph) == []


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_low_layers_do_not_import_the_oracle_stack(layer):
    for mod, path in module_files(ROOT, (layer,)).items():
        hits = {n for n in imported_names(path) if n.split(".")[0] in FORBIDDEN[layer]}
        assert not hits, f"{mod} imports {sorted(hits)}"


def test_the_checks_find_a_planted_upward_import_and_cycle(tmp_path):
    """The two checks above can fail: a miniature tree with one of each."""
    for pkg, files in {
        "common": {"a": "from conformance.b import x\n"},
        "conformance": {
            "b": "def f():\n    from conformance.c import y\n",
            "c": "import conformance.b\n",
        },
    }.items():
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
        for name, text in files.items():
            (tmp_path / pkg / f"{name}.py").write_text(text)
    g = import_graph(module_files(tmp_path, ("common", "conformance")))
    assert upward_imports(g, ("common", "conformance")) == ["common.a -> conformance.b"]
    assert cycles(g) == [["conformance.b", "conformance.c"]]


#: Inside the applications, one package per study and one per stage of a check. A study uses
#: only itself and what the application shares (``comparisons.provenance``); the report and the
#: command line above them gather the studies.
STUDIES = (
    "equivalence",
    "timing",
    "regularization",
    "rheometer",
    "liver",
    "cross_release",
    "sofa",
)
#: The stages of a check and what each may import of the others. The diagnosis reads the
#: judge's figures and never runs an engine (``conformance.engine``) or the check runner
#: (``conformance.run``); nothing below the top (``run``, ``protocol``, ``report``, ``corpus``,
#: the adapters) imports it.
STAGES = {
    "kit": (),
    "engine": ("kit",),
    "judge": ("kit",),
    "diagnosis": ("kit", "judge"),
}


def inner_package(module: str, app: str):
    """``comparisons.liver.records`` -> ``liver`` (``comparisons.provenance`` -> ``provenance``):
    the package or module of ``app`` that ``module`` is in; None for ``app`` itself.
    """
    parts = module.split(".")
    return parts[1] if parts[0] == app and len(parts) > 1 else None


def crossings(graph: Dict[str, Set[str]], app: str, allowed: Dict[str, tuple]) -> List[str]:
    """'a -> b' for every import from a package of ``app`` listed in ``allowed`` into another
    module of ``app`` that is not in that package, nor in one it may import.
    """
    bad = []
    for mod, targets in graph.items():
        src = inner_package(mod, app)
        if src not in allowed:
            continue
        for t in targets:
            if t.split(".")[0] != app:
                continue
            dst = inner_package(t, app)
            if dst != src and dst not in allowed[src]:
                bad.append(f"{mod} -> {t}")
    return sorted(bad)


def test_a_study_imports_no_other_study(graph):
    shared = ("provenance",)
    assert crossings(graph, "comparisons", {s: shared for s in STUDIES}) == []


def test_every_study_is_a_package():
    for study in STUDIES:
        assert (ROOT / "comparisons" / study / "__init__.py").is_file(), study
        assert (ROOT / "comparisons" / study / "study.py").is_file(), study


def test_a_stage_of_a_check_imports_only_the_stages_below_it(graph):
    assert crossings(graph, "conformance", STAGES) == []


def test_common_imports_neither_application(graph):
    bad = [
        f"{m} -> {t}"
        for m, ts in graph.items()
        if m.split(".")[0] == "common"
        for t in ts
        if t.split(".")[0] in ("comparisons", "conformance")
    ]
    assert bad == []


def test_the_layout_checks_find_a_crossing(tmp_path):
    """A study that imports another study, a diagnosis that imports the engine runner."""
    files = {
        "comparisons/liver/study.py": "from comparisons.timing.records import T\n",
        "comparisons/timing/records.py": "from comparisons.provenance import p\n",
        "comparisons/provenance.py": "",
        "conformance/diagnosis/diagnose.py": "def f():\n    import conformance.engine.process\n",
        "conformance/engine/process.py": "",
        "conformance/judge/compare.py": "from conformance.kit.spec import s\n",
        "conformance/kit/spec.py": "",
    }
    for rel, text in files.items():
        path = tmp_path / rel
        for parent in reversed(path.relative_to(tmp_path).parents[:-1]):
            (tmp_path / parent).mkdir(exist_ok=True)
            (tmp_path / parent / "__init__.py").touch()
        path.write_text(text)
    g = import_graph(module_files(tmp_path, ("comparisons", "conformance")))
    studies = {s: ("provenance",) for s in ("liver", "timing")}
    assert crossings(g, "comparisons", studies) == [
        "comparisons.liver.study -> comparisons.timing.records"
    ]
    assert crossings(g, "conformance", STAGES) == [
        "conformance.diagnosis.diagnose -> conformance.engine.process"
    ]


def test_a_kit_is_read_in_one_place():
    """Only ``conformance.kit.read`` opens a kit (its manifest and the cases it lists; the writer
    writes one): the rest get its ``Kit``. The confined reader and the JSON loader are used
    inside the kit stage only.
    """
    mods = module_files(ROOT, ("conformance", "comparisons"))
    outside = {m: p for m, p in mods.items() if not m.startswith("conformance.kit.")}
    readers = ("conformance.kit.confine", "conformance.kit.exchange.load_json")
    bad = [
        f"{m} -> {n}"
        for m, p in outside.items()
        for n in imported_names(p)
        if n.startswith(readers)
    ]
    assert bad == []
    manifest = [m for m, p in mods.items() if '"manifest.json"' in p.read_text()]
    assert sorted(manifest) == ["conformance.kit.read", "conformance.kit.write"]


#: A study driver longer than this mixes setup, measurement and presentation; split it.
MAX_FUNCTION_LINES = 60


def long_functions(root: pathlib.Path, package: str, limit: int = MAX_FUNCTION_LINES) -> List[str]:
    """'file:function (lines)' for every function of ``package`` longer than ``limit`` lines
    (from its ``def`` to its last line, docstring included).
    """
    out = []
    for path in sorted((root / package).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append(f"{path.relative_to(root)}:{node.name} ({n})")
    return out


def test_no_function_of_the_studies_is_over_60_lines():
    assert long_functions(ROOT, "comparisons") == []


def test_the_length_check_finds_a_long_function(tmp_path):
    (tmp_path / "pkg").mkdir()
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    (tmp_path / "pkg" / "m.py").write_text(f"def short():\n    return 1\n\n\ndef long():\n{body}\n")
    assert long_functions(tmp_path, "pkg") == [f"pkg/m.py:long ({MAX_FUNCTION_LINES + 1})"]
