"""The held-out corpus of engine mistakes (tests/heldout_mistakes/): every correct engine
passes and no mistaken engine is passed.

The engines were written from docs/conventions.md alone, each with one realistic mistake, to
measure the diagnosis on mistakes it was not written against. How often the diagnosis *names*
the mistake is reported by `python tests/heldout_mistakes/run_corpus.py` and is not asserted
here: only the verdicts are.
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

HERE = Path(__file__).resolve().parent / "heldout_mistakes"


def _load_runner():
    spec = importlib.util.spec_from_file_location("heldout_run_corpus", HERE / "run_corpus.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


RUNNER = _load_runner()
ENTRIES = RUNNER.load_manifest()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    out = tmp_path_factory.mktemp("heldout")
    summary = RUNNER.run_corpus(out, jobs=min(2, os.cpu_count() or 1))
    return {row["engine"]: row for row in summary["rows"]}


def test_manifest_lists_every_engine():
    files = {p.name for p in HERE.glob("*.py")} - {"run_corpus.py"}
    assert files == {e["file"] for e in ENTRIES}
    families = {
        "parameters", "coefficient", "sign", "units", "kinematics", "volume", "frame",
        "finite_difference", "tangent", "storage", "precision", "formula", "correct",
    }  # fmt: skip
    for e in ENTRIES:
        assert e["family"] in families, e["file"]
        assert e["family"] == "correct" or e["match"], e["file"]
    assert sum(e["family"] == "correct" for e in ENTRIES) >= 3
    assert sum(e["family"] != "correct" for e in ENTRIES) >= 30


@pytest.mark.parametrize("entry", ENTRIES, ids=[e["file"] for e in ENTRIES])
def test_verdict(corpus, entry):
    row = corpus[entry["file"]]
    assert row.get("cases"), f"{entry['file']}: no results ({row.get('detail', '')})"
    if entry["family"] == "correct":
        assert row["score"] == "pass", f"a correct engine failed: {row}"
    else:
        assert row["score"] not in ("PASSED", "error"), f"a mistaken engine was passed: {row}"
