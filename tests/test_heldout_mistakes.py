"""The held-out corpora of engine mistakes (tests/heldout_mistakes/ and
tests/heldout_mistakes_2/): in each, every correct engine passes and no mistaken engine is
passed.

The engines were written from docs/conventions.md alone, each with one realistic mistake, to
measure the diagnosis on mistakes it was not written against (the second corpus by another
author, blind to the diagnosis). How often the diagnosis *names* the mistake is reported by
`python tests/heldout_mistakes/run_corpus.py [--corpus DIR]` and is not asserted here: only
the verdicts are.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import pytest

from reference_fem import dolfinx_available

pytestmark = [
    pytest.mark.slow,
    pytest.mark.oracle,
    pytest.mark.skipif(
        not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
    ),
]

TESTS = Path(__file__).resolve().parent
HERE = TESTS / "heldout_mistakes"
CORPORA = {
    "heldout_mistakes": HERE,
    "heldout_mistakes_2": TESTS / "heldout_mistakes_2",
    "heldout_mistakes_3": TESTS / "heldout_mistakes_3",
}
# the least number of controls and of mistaken engines each corpus must hold
SIZES = {"heldout_mistakes": (3, 30), "heldout_mistakes_2": (2, 15), "heldout_mistakes_3": (3, 25)}
FAMILIES = {
    "parameters", "coefficient", "sign", "units", "kinematics", "volume", "frame",
    "finite_difference", "tangent", "storage", "precision", "formula", "correct",
}  # fmt: skip


def _load_runner():
    spec = importlib.util.spec_from_file_location("heldout_run_corpus", HERE / "run_corpus.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


RUNNER = _load_runner()
ENTRIES = {name: RUNNER.load_manifest(folder) for name, folder in CORPORA.items()}
CASES = [(name, e) for name, entries in ENTRIES.items() for e in entries]


@pytest.fixture(scope="module")
def corpora(tmp_path_factory):
    """Each corpus run once, on first use: {corpus name: {engine file: row}}."""
    done = {}

    def run(name):
        if name not in done:
            out = tmp_path_factory.mktemp(name)
            summary = RUNNER.run_corpus(out, jobs=min(2, os.cpu_count() or 1), corpus=CORPORA[name])
            done[name] = {row["engine"]: row for row in summary["rows"]}
        return done[name]

    return run


@pytest.mark.parametrize("name", sorted(CORPORA))
def test_manifest_lists_every_engine(name):
    folder, entries = CORPORA[name], ENTRIES[name]
    files = {p.name for p in folder.glob("*.py")} - {"run_corpus.py"}
    assert files == {e["file"] for e in entries}
    for e in entries:
        assert e["family"] in FAMILIES, e["file"]
        assert e["family"] == "correct" or e["match"], e["file"]
    controls, mistakes = SIZES[name]
    assert sum(e["family"] == "correct" for e in entries) >= controls
    assert sum(e["family"] != "correct" for e in entries) >= mistakes


@pytest.mark.parametrize("name, entry", CASES, ids=[f"{name}/{e['file']}" for name, e in CASES])
def test_verdict(corpora, name, entry):
    row = corpora(name)[entry["file"]]
    assert row.get("cases"), f"{entry['file']}: no results ({row.get('detail', '')})"
    if entry["family"] == "correct":
        assert row["score"] == "pass", f"a correct engine failed: {row}"
    else:
        assert row["score"] not in ("PASSED", "error"), f"a mistaken engine was passed: {row}"
