"""A study result on the terminal: blocks, checks, left-outs, verdict line and reproduce line."""

from common.blocks import Figure, Paragraph, Table
from common.result import Check, StudyResult
from common.terminal import format_result


def test_format_result_shows_what_was_checked_and_left_out():
    r = StudyResult.from_checks(
        "k",
        "A study",
        [Check("force error", 2e-10, 1e-10), Check("ratio", None, 1.0, ">=", "target")],
        headline="1 case off",
        command="mjed-verify k --quick",
        not_covered=("quick: cube-small",),
        blocks=[
            Paragraph("What it does."),
            Table(("a", "b"), [(1, 2.5e-12)]),
            Figure("f.png", "a figure"),
        ],
    )
    text = format_result(r)
    for piece in (
        "What it does.",
        "2.50e-12",
        "figure: f.png",
        "force error",
        "NOT MET",
        "not measured",
        "not covered: quick: cube-small",
        "A study: FAILED: 1 case off",
        "reproduce: mjed-verify k --quick",
    ):
        assert piece in text, piece
    assert "What it does." not in format_result(r, details=False)
