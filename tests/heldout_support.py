"""What the tests of the held-out corpora of engine mistakes share (tests/test_heldout_mistakes*.py,
one module per corpus so that parallel test workers can take one corpus each).

A corpus is a folder of standalone mistaken engines and correct controls with a manifest.toml,
written from docs/conventions.md alone to measure the diagnosis on mistakes it was not written
against. The tests assert only the verdicts: every correct engine passes and no mistaken engine
is passed. How often the diagnosis *names* the mistake is reported by
`python tests/heldout_mistakes/run_corpus.py [--corpus DIR]` and is not asserted.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import pytest

from reference_fem import dolfinx_available

TESTS = Path(__file__).resolve().parent
MARKS = [
    pytest.mark.slow,
    pytest.mark.oracle,
    pytest.mark.skipif(
        not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
    ),
]
FAMILIES = {
    "parameters", "coefficient", "sign", "units", "kinematics", "volume", "frame",
    "finite_difference", "tangent", "storage", "precision", "formula", "correct",
}  # fmt: skip


def _load_runner():
    path = TESTS / "heldout_mistakes" / "run_corpus.py"
    spec = importlib.util.spec_from_file_location("heldout_run_corpus", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


RUNNER = _load_runner()
#: what conformance.engine.command says of a case whose engine did not run to its end
ENGINE_DID_NOT_RUN = (
    "failed (exit code",
    "failed (killed by signal",
    "ran past the time limit",
    "cannot start",
)


def entries(name: str) -> list:
    """The manifest entries of corpus ``name`` (a folder of tests/)."""
    return RUNNER.load_manifest(TESTS / name)


def check_manifest(name: str, *, controls: int, mistakes: int) -> None:
    """Every engine of the folder is in the manifest and the other way round, each with a known
    family and, unless correct, the keywords that name its mistake; at least ``controls``
    correct engines and ``mistakes`` mistaken ones.
    """
    folder, listed = TESTS / name, entries(name)
    files = {p.name for p in folder.glob("*.py")} - {"run_corpus.py", "forked_engines.py"}
    assert files == {e["file"] for e in listed}
    for e in listed:
        assert e["family"] in FAMILIES, e["file"]
        assert e["family"] == "correct" or e["match"], e["file"]
    assert sum(e["family"] == "correct" for e in listed) >= controls
    assert sum(e["family"] != "correct" for e in listed) >= mistakes


def corpus_rows(name: str, tmp_path_factory) -> dict:
    """Corpus ``name`` judged (`mjed-verify check --verdict-only` on each engine, results in a
    new temporary folder): {engine file: its row of run_corpus's summary}. Only the verdicts
    are asserted, so the readings that name causes (most of a full run's time: they compile
    the variant energies) are left to `run_corpus.py`, which reports them. The kits (one per
    material and precision) are exported once per session into :func:`kit_store` and shared by
    every corpus.
    """
    summary = RUNNER.run_corpus(
        tmp_path_factory.mktemp(name),
        jobs=min(2, os.cpu_count() or 1),
        corpus=TESTS / name,
        verdict_only=True,
        kit_store=kit_store(tmp_path_factory),
    )
    return {row["engine"]: row for row in summary["rows"]}


def kit_store(tmp_path_factory) -> Path:
    """The folder of the kits the corpus modules of this pytest session share: beside the
    session's base temporary folder, which under pytest-xdist is the workers' common parent
    (each worker's own base folder is one level down), so every worker finds it.
    """
    base = tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "heldout-kits"


def check_verdict(rows: dict, entry: dict) -> None:
    """A correct engine passed every case; a mistaken one failed at least one (or was refused
    as bad input), and the check did not end in an error.
    """
    row = rows[entry["file"]]
    assert row.get("cases"), f"{entry['file']}: no results ({row.get('detail', '')})"
    if entry["family"] == "correct":
        assert row["score"] == "pass", f"a correct engine failed: {row}"
    else:
        assert row["score"] not in ("PASSED", "error"), f"a mistaken engine was passed: {row}"
        # an engine refused as bad input must have run: its outputs were read and refused.
        # One that did not run to its end (a crash of the way it was started, the time limit)
        # would count as caught without having been checked at all.
        for case in row["cases"]:
            if case["status"] == "bad input":
                assert not any(s in case["message"] for s in ENGINE_DID_NOT_RUN), (
                    f"{entry['file']}: the engine did not run to its end: {case['message']}"
                )
