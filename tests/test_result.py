"""The typed study result: status derivation, partial runs and the exit-code policy."""

import math

import pytest

from common.result import (
    EXIT_FAILED,
    EXIT_INCOMPLETE,
    EXIT_PASSED,
    Check,
    Status,
    StudyResult,
    exit_code,
    status_from_checks,
)


def _result(checks, **kw):
    return StudyResult.from_checks("k", "K", checks, headline="h", command="mjed-verify k", **kw)


def test_tolerance_failure_fails_and_names_the_check():
    r = _result([Check("force", 1e-9, 1e-10), Check("ratio", 4.0, 3.0, ">=", "target")])
    assert r.status is Status.FAILED
    assert "force" in r.reason and exit_code([r]) == EXIT_FAILED


def test_missed_target_is_not_a_pass():
    r = _result([Check("force", 1e-16, 1e-10), Check("ratio", 2.0, 3.0, ">=", "target")])
    assert r.status is Status.TARGET_MISSED and not r.complete_pass
    assert exit_code([r]) == EXIT_INCOMPLETE
    assert exit_code([r], allow_incomplete=True) == EXIT_PASSED


def test_nan_never_passes_and_unmeasured_makes_partial():
    assert Check("x", math.nan, 1.0).passed is False
    r = _result([Check("x", 0.5, 1.0), Check("y", None, 1.0, note="sizes too small")])
    assert r.status is Status.PASSED and r.partial and not r.complete_pass
    assert exit_code([r]) == EXIT_INCOMPLETE
    assert r.to_dict()["checks"][1]["passed"] is None


def test_not_covered_makes_partial_and_complete_pass_exits_zero():
    full = _result([Check("x", 0.5, 1.0)])
    quick = _result([Check("x", 0.5, 1.0)], not_covered=("quick sizes",))
    assert full.complete_pass and exit_code([full]) == EXIT_PASSED
    assert quick.partial and exit_code([full, quick]) == EXIT_INCOMPLETE


def test_not_run_and_error_need_a_reason():
    with pytest.raises(ValueError, match="must say why"):
        StudyResult("k", "K", Status.NOT_RUN, "h", "c")
    r = StudyResult.not_run("k", "K", "the modern stack is not installed", "make test-modern")
    assert exit_code([r]) == EXIT_INCOMPLETE
    e = StudyResult.error("k", "K", "RuntimeError: boom", "c")
    assert exit_code([r, e]) == EXIT_FAILED
    assert status_from_checks([]) is Status.PASSED
    assert exit_code([]) == EXIT_INCOMPLETE
