"""The cross-release comparison itself: snapshots round-trip, differences are seen, missing
stacks are reported and fail the check rather than pass it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp

from comparisons.cross_release import (
    TOLERANCE,
    compare_snapshots,
    cross_release_check,
    load_snapshot,
    provenance_summary,
    save_snapshot,
)


def _snapshot(rng, scale=1.0):
    K = sp.random(12, 12, density=0.4, format="csr", random_state=1)
    K = (K + K.T).tocsr() * scale
    return {
        "meta": {"versions": {"dolfinx": "test"}, "mpi_ranks": 1, "cells_per_rank": [1]},
        "cases": {
            "NeoHookean/random": {
                "energy": 2.5 * scale,
                "force": rng.standard_normal((4, 3)),
                "stiffness": K,
            }
        },
    }


def test_snapshot_round_trip(tmp_path):
    snap = _snapshot(np.random.default_rng(0))
    save_snapshot(str(tmp_path / "s.npz"), snap)
    back = load_snapshot(str(tmp_path / "s.npz"))
    assert back["meta"] == snap["meta"]
    diff = compare_snapshots(snap, back)
    assert (
        diff["passed"]
        and diff["energy_rel_diff"] == diff["force_rel_diff"] == diff["stiffness_rel_diff"] == 0.0
    )


def test_compare_sees_each_quantity():
    a = _snapshot(np.random.default_rng(0))
    for what in ("energy", "force", "stiffness"):
        b = _snapshot(np.random.default_rng(0))
        case = b["cases"]["NeoHookean/random"]
        if what == "energy":
            case["energy"] *= 1 + 1e-11
        elif what == "force":
            case["force"][1, 2] += 1e-10
        else:
            case["stiffness"] = case["stiffness"] * (1 + 1e-11)
        diff = compare_snapshots(a, b)
        assert not diff["passed"] and diff[f"{what}_rel_diff"] > TOLERANCE, what


def test_compare_refuses_different_cases():
    a = _snapshot(np.random.default_rng(0))
    b = {"meta": a["meta"], "cases": {"Ogden/random": a["cases"]["NeoHookean/random"]}}
    with pytest.raises(ValueError, match="different cases"):
        compare_snapshots(a, b)


def test_missing_stacks_are_reported_and_fail_the_check(tmp_path):
    result = cross_release_check([("nowhere", str(tmp_path / "bin" / "python"), 1)])
    assert result["missing"] and "does not exist" in result["missing"][0]["reason"]
    assert result["passed"] is False and result["comparisons"] == []
    json.dumps(result)  # JSON-serialisable as it is


def test_provenance_summary(tmp_path):
    assert provenance_summary(str(tmp_path / "absent.json")) is None
    versions = {
        "dolfinx": "0.5.2",
        "ufl": "2022.2.0",
        "petsc": "3.18.5",
        "numpy": "1.24.2",
        "python": "3.11",
        "mpi": "Open MPI",
    }
    result = {
        "passed": True,
        "tolerance": TOLERANCE,
        "reference": "a",
        "missing": [{"label": "c", "reason": "x"}],
        "errors": [],
        "stacks": [
            {"label": "a", "ranks": 1, "versions": versions},
            {"label": "b", "ranks": 2, "versions": versions},
        ],
        "comparisons": [
            {
                "label": "b",
                "energy_rel_diff": 1e-15,
                "force_rel_diff": 3e-16,
                "stiffness_rel_diff": 2e-15,
                "passed": True,
            }
        ],
    }
    path = tmp_path / "xr.json"
    path.write_text(json.dumps(result))
    summary = provenance_summary(str(path))
    assert summary["worst_rel_diff"] == {"b": 2e-15} and summary["not_run"] == ["c"]
    assert summary["stacks"][1]["ranks"] == 2 and summary["stacks"][0]["dolfinx"] == "0.5.2"


# ----------------------------------------------------------------------------- the typed result
def _check_result(*, comparisons=(1e-15,), missing=("modern-serial",), errors=()):
    versions = {
        "dolfinx": "0.5.2",
        "ufl": "2022.2.0",
        "petsc": "3.18",
        "numpy": "1.24",
        "python": "3.11",
    }
    labels = ["debian-serial"] + [f"debian-mpi{i + 2}" for i in range(len(comparisons))]
    return {
        "tolerance": TOLERANCE,
        "reference": labels[0],
        "figures": [],
        "stacks": [
            {
                "label": s,
                "python": "p",
                "ranks": 1,
                "versions": versions,
                "cells_per_rank": [1],
                "seconds": 1.0,
            }
            for s in labels
        ],
        "comparisons": [
            {
                "label": s,
                "n_cases": 3,
                "energy_rel_diff": d,
                "force_rel_diff": d,
                "stiffness_rel_diff": d,
                "passed": d <= TOLERANCE,
            }
            for s, d in zip(labels[1:], comparisons)
        ],
        "missing": [
            {"label": m, "reason": "/x/.venv-modern/bin/python does not exist"} for m in missing
        ],
        "errors": [{"label": e, "error": "snapshot failed"} for e in errors],
        "passed": not errors and all(d <= TOLERANCE for d in comparisons) and len(comparisons) > 0,
    }


@pytest.mark.parametrize(
    "kwargs, status, code",
    [
        (dict(), "passed", 3),  # the modern stack is not installed: partial
        (dict(missing=()), "passed", 0),
        (dict(comparisons=(1e-9,)), "failed", 1),
        (dict(errors=("modern-serial",)), "failed", 1),
        (dict(comparisons=()), "not run", 3),  # one stack only: nothing compared
    ],
)
def test_study_result_follows_the_policy(monkeypatch, kwargs, status, code):
    from common.result import exit_code
    from comparisons import cross_release

    monkeypatch.setattr(
        cross_release, "cross_release_check", lambda stacks, quick: _check_result(**kwargs)
    )
    r = cross_release.cross_release_study(quick=False)
    assert r.status.value == status and exit_code([r]) == code
    if kwargs.get("missing", ("modern-serial",)):
        assert (
            any("modern-serial: not installed here" in s for s in r.not_covered)
            or "modern-serial" in r.reason
        )


def test_a_stack_that_is_not_installed_makes_the_command_exit_3(monkeypatch, tmp_path, capsys):
    from conftest import parse_reproduce

    from comparisons import cross_release
    from comparisons.cli import main

    missing = str(tmp_path / "no-venv" / "bin" / "python")
    monkeypatch.setattr(cross_release, "default_stacks", lambda: [("modern-serial", missing, 1)])
    out = tmp_path / "xr.json"
    assert main(["cross-release", "--quick", "--json", str(out)]) == 3
    written = json.loads(out.read_text())
    assert written["status"] == "not run" and "nothing was compared" in written["reason"]
    assert (
        "does not exist" in written["reason"]
        and written["data"]["missing"][0]["label"] == "modern-serial"
    )
    assert parse_reproduce(written["command"])["quick"] is True
    assert "every check passed" not in capsys.readouterr().out


def test_an_interpreter_without_dolfinx_is_a_missing_stack_not_an_error(tmp_path):
    fake = tmp_path / "python"
    fake.write_text(
        "#!/bin/sh\nexit 3\n"
    )  # what the dolfinx probe returns when dolfinx cannot be imported
    fake.chmod(0o755)
    result = cross_release_check(
        [("nodolfinx-serial", str(fake), 1), ("nodolfinx-mpi2", str(fake), 2)]
    )
    assert [m["label"] for m in result["missing"]] == ["nodolfinx-serial", "nodolfinx-mpi2"]
    assert "dolfinx cannot be imported" in result["missing"][0]["reason"] and not result["errors"]
