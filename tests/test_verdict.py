"""The words of a verdict never say more than the results: 'every check passed' only for exit 0."""

import pytest

from common.result import Check, StudyResult
from common.verdict import EXIT_POLICY, not_covered_lines, status_label, verdict_sentence


def _r(key, checks=(("x", 0.5, 1.0, "<=", "tolerance"),), **kw):
    return StudyResult.from_checks(
        key, key.upper(), [Check(*c) for c in checks], headline="h", command="c", **kw
    )


@pytest.mark.parametrize(
    "other, word, label",
    [
        (_r("b"), "every check passed", "passed"),
        (
            _r("b", not_covered=("quick: sizes up to 6,000 cells",)),
            "INCOMPLETE",
            "passed (partial)",
        ),
        (_r("b", (("ratio", 0.5, 1.0, ">=", "target"),)), "INCOMPLETE", "TARGET MISSED"),
        (_r("b", (("error", 2.0, 1.0, "<=", "tolerance"),)), "FAILED", "FAILED"),
        (StudyResult.not_run("b", "B", "not selected: --only a", "c"), "INCOMPLETE", "NOT RUN"),
        (StudyResult.error("b", "B", "RuntimeError: boom", "c"), "FAILED", "ERROR"),
        (
            _r("b", (("x", None, 1.0, "<=", "tolerance", "sizes too small"),)),
            "INCOMPLETE",
            "passed (partial)",
        ),
    ],
)
def test_verdict_and_labels(other, word, label):
    results = [_r("a"), other]
    sentence = verdict_sentence(results)
    assert word in sentence and (
        ("every check passed" in sentence) == (word == "every check passed")
    )
    assert status_label(other) == label


def test_what_was_left_out_is_listed_per_study():
    lines = not_covered_lines(
        [
            _r("a", not_covered=("quick: cube-small instead of cube-paper",)),
            StudyResult.not_run("b", "B", "the modern stack is not installed", "c"),
            _r("d", (("y", None, 1.0, "<=", "target", "fewer than two sizes"),)),
        ]
    )
    assert lines == [
        "A: quick: cube-small instead of cube-paper",
        "B: not run: the modern stack is not installed",
        "D: not measured: y (fewer than two sizes)",
    ]


def test_the_policy_names_every_code():
    for code in ("0 ", "1 ", "2 ", "3 ", "--allow-incomplete"):
        assert code in EXIT_POLICY
