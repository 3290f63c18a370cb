"""tests/heldout_mistakes/run_corpus.py: judging the engines of a kit in one process, which reads
the kit and builds its oracles once, gives each engine exactly the results of its own
`mjed-verify check KIT --command ...` (the corpus tests rely on it to run in minutes).
"""

from __future__ import annotations

import pytest
from heldout_support import MARKS, RUNNER, TESTS

pytestmark = MARKS

#: three engines sharing one kit (a correct one first: its oracles then serve the next two), and
#: a float32 engine on a single-precision kit
ENGINES = [
    "correct_neohookean_coo.py",
    "neohookean_geometric_subtracted.py",
    "neohookean_i1b_for_i1.py",
    "correct_demiray_float32.py",
]


def _rows(summary: dict) -> dict:
    return {
        r["engine"]: (r["score"], r["verdict"], r["cause"], [c["errors"] for c in r["cases"]])
        for r in summary["rows"]
    }


def test_one_process_per_kit_gives_each_engine_its_own_checks_results(tmp_path):
    corpus = TESTS / "heldout_mistakes_3"
    shared = RUNNER.run_corpus(
        tmp_path / "shared", only=ENGINES, jobs=1, corpus=corpus, verdict_only=True
    )
    alone = RUNNER.run_corpus(
        tmp_path / "alone",
        only=ENGINES,
        jobs=2,
        corpus=corpus,
        verdict_only=True,
        one_process_per_engine=True,
    )
    assert len(shared["rows"]) == len(ENGINES)
    assert _rows(shared) == _rows(alone)
    scores = {r["engine"]: r["score"] for r in shared["rows"]}
    assert scores["correct_neohookean_coo.py"] == scores["correct_demiray_float32.py"] == "pass"
    assert all(scores[e] not in ("pass", "PASSED", "error") for e in ENGINES[1:3])


def test_an_engine_whose_judge_died_is_an_error_row(tmp_path, monkeypatch):
    """A judging process that ends without rows (here: killed before its first) leaves every
    engine it held as an error row with the process's last words, not a silent gap.
    """
    monkeypatch.setattr(RUNNER.sys, "executable", "/bin/false")
    entries = [
        e for e in RUNNER.load_manifest(TESTS / "heldout_mistakes_3") if e["file"] in ENGINES
    ]
    kits = {RUNNER.kit_key(e): tmp_path / "no-kit" for e in entries}
    rows = RUNNER.judge_in_processes(entries, kits, tmp_path, TESTS / "heldout_mistakes_3", 2, True)
    assert [r["engine"] for r in rows] == [e["file"] for e in entries]
    assert {r["score"] for r in rows} == {"FAIL", "error"}  # controls FAIL, mistakes error


def test_a_mistaken_engine_that_did_not_run_is_not_counted_as_caught():
    """An engine refused as bad input because its outputs were wrong is caught; one that never
    ran to its end (how it was started failed) was not checked, and the corpus test says so.
    """
    from heldout_support import check_verdict

    entry = {"file": "x.py", "family": "storage"}

    def row(message):
        case = {"status": "bad input", "message": message}
        return {"x.py": {"cases": [case], "score": "unexplained"}}

    check_verdict(row("x/stiffness_rows.i64: indices must lie in [0, 558)"), entry)
    with pytest.raises(AssertionError, match="did not run to its end"):
        check_verdict(row("case c: python failed (exit code 1); no stderr"), entry)


def test_a_kit_store_exports_each_kit_once(tmp_path, monkeypatch):
    """The corpus modules of one session share their kits: a kit of the same material,
    precision and states is exported into the store once; other states make another kit; an
    export that did not finish is done again, not trusted.
    """
    exported = []

    def export(kit, material, precision, states):
        exported.append((material, precision, states))
        if material == "Gent" and len(exported) == 3:
            raise RuntimeError("interrupted")
        kit.mkdir(parents=True)
        return kit

    monkeypatch.setattr(RUNNER, "_export", export)
    store, states = tmp_path / "store", "uniaxial,random"
    keys = [("NeoHookean", "double"), ("Demiray", "single"), ("NeoHookean", "double")]
    first = RUNNER.export_kits(keys, tmp_path / "a", states, store)
    again = RUNNER.export_kits(keys, tmp_path / "b", states, store)
    assert first == again and all(kit.parent == store for kit in first.values())
    assert exported == [("Demiray", "single", states), ("NeoHookean", "double", states)]
    with pytest.raises(RuntimeError):
        RUNNER.export_kits([("Gent", "double")], tmp_path / "c", states, store)
    RUNNER.export_kits([("Gent", "double")], tmp_path / "c", states, store)
    assert exported[-1] == ("Gent", "double", states) and len(exported) == 4
    RUNNER.export_kits(keys[:1], tmp_path / "d", "uniaxial", store)
    assert exported[-1] == ("NeoHookean", "double", "uniaxial")
