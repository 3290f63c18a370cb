"""The cross-release comparison itself: snapshots round-trip, differences are seen, missing
stacks are reported and fail the check rather than pass it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp

from common.json_fields import RecordError
from common.options import write_json
from comparisons.cross_release.records import (
    CrossReleaseResult,
    MissingStack,
    SnapshotDiff,
    StackComparison,
    StackError,
    StackRun,
)
from comparisons.cross_release.study import (
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
    assert diff == SnapshotDiff(1, 0.0, 0.0, 0.0, passed=True)


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
        assert not diff.passed and dict(diff.by_quantity())[what] > TOLERANCE, what
        assert diff.worst == dict(diff.by_quantity())[what]


def test_compare_refuses_different_cases():
    a = _snapshot(np.random.default_rng(0))
    b = {"meta": a["meta"], "cases": {"Ogden/random": a["cases"]["NeoHookean/random"]}}
    with pytest.raises(ValueError, match="different cases"):
        compare_snapshots(a, b)


def test_missing_stacks_are_reported_and_fail_the_check(tmp_path):
    result = cross_release_check([("nowhere", str(tmp_path / "bin" / "python"), 1)])
    assert isinstance(result, CrossReleaseResult)
    assert result.missing and "does not exist" in result.missing[0].reason
    assert result.passed is False and result.comparisons == () and result.reference is None
    assert json.loads(json.dumps(result.to_dict())) == {
        "tolerance": TOLERANCE,
        "reference": None,
        "stacks": [],
        "comparisons": [],
        "missing": [{"label": "nowhere", "reason": result.missing[0].reason}],
        "errors": [],
        "figures": [],
        "passed": False,
    }


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
    result = CrossReleaseResult(
        tolerance=TOLERANCE,
        reference="a",
        stacks=(
            StackRun("a", "/v/bin/python", 1, versions, (510,), 3.1),
            StackRun("b", "/v/bin/python", 2, versions, (255, 255), 5.2),
        ),
        comparisons=(StackComparison("b", SnapshotDiff(3, 1e-15, 3e-16, 2e-15, passed=True)),),
        missing=(MissingStack("c", "x"),),
    )
    path = tmp_path / "xr.json"
    write_json(str(path), result.to_dict())
    summary = provenance_summary(str(path))
    assert summary["passed"] is True and summary["reference"] == "a"
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
    return CrossReleaseResult(
        tolerance=TOLERANCE,
        reference=labels[0],
        stacks=tuple(StackRun(s, "p", 1, versions, (1,), 1.0) for s in labels),
        comparisons=tuple(
            StackComparison(s, SnapshotDiff(3, d, d, d, passed=d <= TOLERANCE))
            for s, d in zip(labels[1:], comparisons)
        ),
        missing=tuple(
            MissingStack(m, "/x/.venv-modern/bin/python does not exist") for m in missing
        ),
        errors=tuple(StackError(e, "snapshot failed") for e in errors),
    )


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
    from comparisons.cross_release import study as cross_release

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

    from comparisons.cli import main
    from comparisons.cross_release import study as cross_release

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
    assert [m.label for m in result.missing] == ["nodolfinx-serial", "nodolfinx-mpi2"]
    assert "dolfinx cannot be imported" in result.missing[0].reason and not result.errors


# ----------------------------------------------------------------------------- the records
def test_result_json_keeps_the_check_s_keys_and_reads_back():
    result = _check_result(comparisons=(1e-15, 2e-9), errors=("modern-mpi2",))
    payload = json.loads(json.dumps(result.to_dict()))
    assert list(payload) == [
        "tolerance",
        "reference",
        "stacks",
        "comparisons",
        "missing",
        "errors",
        "figures",
        "passed",
    ]
    assert list(payload["stacks"][0]) == [
        "label",
        "python",
        "ranks",
        "versions",
        "cells_per_rank",
        "seconds",
    ]
    assert payload["comparisons"][1] == {
        "label": "debian-mpi3",
        "n_cases": 3,
        "energy_rel_diff": 2e-9,
        "force_rel_diff": 2e-9,
        "stiffness_rel_diff": 2e-9,
        "passed": False,
    }
    assert payload["missing"] == [
        {"label": "modern-serial", "reason": "/x/.venv-modern/bin/python does not exist"}
    ]
    assert payload["errors"] == [{"label": "modern-mpi2", "error": "snapshot failed"}]
    assert payload["passed"] is False and payload["reference"] == "debian-serial"
    assert CrossReleaseResult.from_dict(payload) == result
    assert _check_result(missing=()).passed and not _check_result(comparisons=()).passed


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda p: p.pop("errors"), "xr.json: missing key 'errors'"),
        (lambda p: p["stacks"][1].pop("ranks"), "xr.json: stacks/1: missing key 'ranks'"),
        (
            lambda p: p["comparisons"][0].pop("force_rel_diff"),
            "xr.json: comparisons/0: missing key 'force_rel_diff'",
        ),
        (lambda p: p["missing"][0].pop("reason"), "xr.json: missing/0: missing key 'reason'"),
        (
            lambda p: p["stacks"][0].update(cells_per_rank=[1.5]),
            "xr.json: stacks/0/cells_per_rank/0: expected an integer, got 1.5",
        ),
        (
            lambda p: p["comparisons"][0].update(passed="yes"),
            "xr.json: comparisons/0/passed: expected true or false, got 'yes'",
        ),
        (
            lambda p: p.update(passed=False),
            "xr.json: passed: False contradicts the comparisons and errors",
        ),
        (
            lambda p: p.update(reference="modern-serial"),
            "xr.json: CrossReleaseResult: reference 'modern-serial' is not the first stack that "
            "ran ('debian-serial')",
        ),
        (
            lambda p: p["stacks"][1].update(ranks=0),
            "xr.json: stacks/1: StackRun 'debian-mpi2': key 'ranks' must be an integer >= 1, got 0",
        ),
    ],
)
def test_result_from_dict_names_what_is_wrong(change, message):
    payload = json.loads(json.dumps(_check_result(missing=("modern-serial",)).to_dict()))
    assert payload["passed"] is True
    change(payload)
    with pytest.raises(RecordError) as info:
        CrossReleaseResult.from_dict(payload, source="xr.json")
    assert str(info.value) == message


def test_provenance_summary_names_the_file_of_a_broken_result(tmp_path):
    payload = _check_result().to_dict()
    del payload["comparisons"][0]["stiffness_rel_diff"]
    path = tmp_path / "cross_release.json"
    path.write_text(json.dumps(payload))
    with pytest.raises(RecordError, match=f"^{path}: comparisons/0: missing key 'stiffness_rel"):
        provenance_summary(str(path))


def test_comparisons_must_follow_the_stacks_that_ran():
    result = _check_result(comparisons=(1e-15, 1e-15))
    with pytest.raises(ValueError, match="do not match the stacks after the reference"):
        CrossReleaseResult(
            result.tolerance, result.reference, result.stacks, result.comparisons[:1]
        )
    with pytest.raises(ValueError, match="key 'n_cases' must be an integer >= 0"):
        SnapshotDiff(-1, 0.0, 0.0, 0.0, passed=True)
