"""The report: one generic renderer for study results, a summary that says no more than was
checked, the exit-code policy, and the runner's safety rules (runs never overwrite each other,
latest moves last, a raising study becomes ERROR and the others still run).
"""

import json
import os
import re

import pytest
from conftest import parse_reproduce

from common.blocks import Figure, Paragraph, Table
from common.result import Check, Status, StudyResult
from common.states import state_names
from comparisons.cli import main
from comparisons.report.runner import ReportStudy, publish_latest, run_report

EVERY = "every check passed"


def _figure_study(ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = ctx.figure_path("line.png")
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    fig.savefig(path)
    plt.close(fig)
    return StudyResult.from_checks(
        "figure",
        "A figure",
        [Check("error", 1e-16, 1e-10)],
        headline="a line",
        command="mjed-verify figure",
        data={"value": 1.5},
        blocks=[
            Paragraph("a line"),
            Figure(path, "a line"),  # absolute: made relative
            Table(("a", "b"), [(1, 2.5e-12)]),
        ],
    )


def _passing(key):
    return lambda ctx: StudyResult.from_checks(
        key, key.title(), [Check("x", 0.5, 1.0)], headline="fine", command=f"mjed-verify {key}"
    )


def _boom(ctx):
    raise RuntimeError("the rheometer exploded")


def _failing_check(ctx):
    return StudyResult.from_checks(
        "check",
        "A failing check",
        [Check("force error", 1e-6, 1e-10)],
        headline="one case off",
        command="mjed-verify check",
    )


def _missed_target(ctx):
    return StudyResult.from_checks(
        "speed",
        "Speed",
        [Check("classical/mjed", 0.8, 1.0, ">=", "target")],
        headline="slower",
        command="mjed-verify speed",
    )


def _interrupt(ctx):
    raise KeyboardInterrupt


STUDIES = [
    ReportStudy("figure", "A figure", _figure_study),
    ReportStudy("boom", "A study that raises", _boom),
    ReportStudy("check", "A failing check", _failing_check),
]
CTX = {"materials": (), "meshes": (), "states": (), "show_progress": False}
QUIET = dict(quick=True, stream=open(os.devnull, "w"))


def _read(run_dir):
    return (
        {name: open(os.path.join(run_dir, name)).read() for name in ("index.html", "report.md")},
        json.load(open(os.path.join(run_dir, "results.json"))),
    )


def test_a_raising_study_is_an_error_the_others_run_and_the_exit_code_is_1(tmp_path):
    out = run_report(str(tmp_path), STUDIES, CTX, command_line=["mjed-verify", "all"], **QUIET)
    assert out.complete and not out.all_passed and out.exit_code() == 1
    status = {r.key: r for r in out.results}
    assert status["figure"].status is Status.PASSED and status["figure"].complete_pass
    assert (
        status["boom"].status is Status.ERROR
        and status["boom"].reason == "RuntimeError: the rheometer exploded"
    )
    assert "--only boom" in status["boom"].command  # re-runs just that study
    assert status["check"].status is Status.FAILED and "force error" in status["check"].reason
    pages, results = _read(tmp_path / "latest")
    for text in pages.values():
        assert "the rheometer exploded" in text and "force error" in text and EVERY not in text
        assert "ERROR" in text and "FAILED" in text
    # Self-contained: the figure is embedded, nothing is fetched from elsewhere.
    assert "data:image/png;base64," in pages["index.html"]
    assert not re.search(r"""src=["'](?!data:)""", pages["index.html"])
    assert results["complete"] and results["exit_code"] == 1 and EVERY not in results["verdict"]
    by_key = {s["key"]: s for s in results["studies"]}
    assert by_key["figure"]["data"] == {"value": 1.5} and by_key["boom"]["status"] == "error"
    assert pages["report.md"].startswith("# MJED verification report")
    assert (
        "![a line](figures/line.png)" in pages["report.md"]
    )  # still valid once the run dir is renamed


def test_every_check_passed_only_when_every_study_ran_and_passed_completely(tmp_path):
    studies = [ReportStudy("a", "A", _passing("a")), ReportStudy("b", "B", _passing("b"))]
    out = run_report(str(tmp_path / "full"), studies, CTX, **QUIET)
    pages, results = _read(out.run_dir)
    assert out.exit_code() == 0 and results["exit_code"] == 0
    assert EVERY in results["verdict"] and all(EVERY in t for t in pages.values())


@pytest.mark.parametrize("case", ["target", "only", "partial", "not_run"])
def test_an_incomplete_run_never_says_every_check_passed_and_exits_3(tmp_path, case):
    studies = [ReportStudy("a", "A", _passing("a"))]
    only = None
    if case == "target":
        studies.append(ReportStudy("speed", "Speed", _missed_target))
    elif case == "only":
        studies.append(ReportStudy("b", "B", _passing("b")))
        only = ["a"]
    elif case == "partial":
        studies.append(
            ReportStudy(
                "q",
                "Q",
                lambda ctx: StudyResult.from_checks(
                    "q",
                    "Q",
                    [Check("x", 0.5, 1.0)],
                    headline="h",
                    command="c",
                    not_covered=("quick: cube-small instead of cube-paper",),
                ),
            )
        )
    else:
        studies.append(
            ReportStudy(
                "x",
                "X",
                lambda ctx: StudyResult.not_run("x", "X", "the modern stack is not installed", "c"),
            )
        )
    out = run_report(str(tmp_path), studies, CTX, only=only, **QUIET)
    pages, results = _read(out.run_dir)
    assert out.exit_code() == 3 and results["exit_code"] == 3
    assert out.exit_code(allow_incomplete=True) == 0
    assert EVERY not in results["verdict"] and all(EVERY not in t for t in pages.values())
    expected = {
        "target": "TARGET MISSED",
        "only": "NOT RUN",
        "partial": "passed (partial)",
        "not_run": "NOT RUN",
    }[case]
    toc = pages["report.md"].split("## Summary")[0]
    assert (
        expected in toc and expected in pages["index.html"].split("<h2")[0]
    )  # the table of contents
    if case == "only":
        assert (
            results["studies"][1]["status"] == "not run"
            and "not selected: --only a" in results["studies"][1]["reason"]
        )
    if case == "partial":
        assert any(
            "quick: cube-small instead of cube-paper" in line for line in results["not_covered"]
        )
        assert "quick: cube-small instead of cube-paper" in pages["report.md"]


def test_a_study_returning_something_else_is_an_error(tmp_path):
    out = run_report(
        str(tmp_path),
        [ReportStudy("dict", "Old style", lambda ctx: {"passed": True})],
        CTX,
        **QUIET,
    )
    assert out.results[0].status is Status.ERROR and "not a StudyResult" in out.results[0].reason


def test_a_new_run_never_destroys_the_previous_one(tmp_path):
    first = run_report(str(tmp_path), STUDIES[:1], CTX, **QUIET)
    second = run_report(str(tmp_path), STUDIES[:1], CTX, **QUIET)
    assert first.run_dir != second.run_dir
    assert os.path.isfile(os.path.join(first.run_dir, "index.html"))
    assert os.path.realpath(tmp_path / "latest") == os.path.realpath(second.run_dir)


def test_an_interrupted_run_keeps_what_it_has_and_leaves_latest_alone(tmp_path):
    done = run_report(str(tmp_path), STUDIES[:1], CTX, **QUIET)
    studies = [STUDIES[0], ReportStudy("stop", "Interrupted", _interrupt), STUDIES[2]]
    cut = run_report(str(tmp_path), studies, CTX, **QUIET)
    assert not cut.complete and cut.run_dir.endswith("-interrupted") and cut.exit_code() == 130
    assert [r.status for r in cut.results] == [Status.PASSED, Status.NOT_RUN, Status.NOT_RUN]
    assert "interrupted" in cut.results[1].reason and "interrupted" in cut.results[2].reason
    assert os.path.isfile(os.path.join(cut.run_dir, "index.html"))
    assert os.path.realpath(tmp_path / "latest") == os.path.realpath(done.run_dir)
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".partial")]


def test_latest_that_is_a_real_directory_is_not_replaced(tmp_path):
    (tmp_path / "latest").mkdir()
    (tmp_path / "run").mkdir()
    with pytest.raises(OSError, match="real directory"):
        publish_latest(str(tmp_path), "run")
    assert (tmp_path / "latest").is_dir()


# ----------------------------------------------------------------------------- the command
@pytest.fixture
def fake_registry(monkeypatch):
    """`mjed-verify all` on a registry of cheap studies, the outcome of each chosen by the test."""
    from comparisons.report import studies

    registry = {}
    monkeypatch.setattr(studies, "report_studies", lambda: tuple(registry.values()))
    return registry


@pytest.mark.parametrize(
    "make, code, allowed",
    [
        (_passing, 0, 0),
        (lambda k: _failing_check, 1, 1),
        (lambda k: _boom, 1, 1),
        (lambda k: _missed_target, 3, 0),
    ],
)
def test_all_exits_by_the_written_policy(tmp_path, capsys, fake_registry, make, code, allowed):
    fake_registry["a"] = ReportStudy("a", "A", _passing("a"))
    fake_registry["b"] = ReportStudy("b", "B", make("b"))
    argv = ["all", "--mesh", "single-tet", "--out", str(tmp_path), "--no-progress"]
    assert main(argv) == code
    assert (EVERY in capsys.readouterr().out) == (code == 0)
    assert main(argv + ["--allow-incomplete"]) == allowed


def test_all_only_lists_the_others_as_not_run_and_exits_3(tmp_path, capsys, fake_registry):
    fake_registry["a"] = ReportStudy("a", "A", _passing("a"))
    fake_registry["b"] = ReportStudy("b", "B", _passing("b"))
    assert (
        main(
            ["all", "--only", "a", "--mesh", "single-tet", "--out", str(tmp_path), "--no-progress"]
        )
        == 3
    )
    out = capsys.readouterr().out
    assert "B: NOT RUN: not selected: --only a" in out and EVERY not in out


def test_the_reproduce_lines_of_a_report_parse_back_to_what_ran(tmp_path, fake_registry):
    import meshes
    from comparisons.report.runner import report_command

    points, cells = meshes.load("single-tet")
    mesh_file = tmp_path / "my organ.vtu"
    meshes.write_mesh(str(mesh_file), points, cells)
    fake_registry["a"] = ReportStudy(
        "a",
        "A",
        lambda ctx: StudyResult.from_checks(
            "a", "A", [Check("x", 0.5, 1.0)], headline="h", command=report_command(ctx)
        ),
    )
    fake_registry["b"] = ReportStudy("b", "B", _passing("b"))
    argv = [
        "all",
        "--quick",
        "--material",
        "Ogden,NeoHookean",
        "--mesh",
        f"single-tet,{mesh_file}",
        "--states",
        "rest,shear",
        "--only",
        "a",
        "--out",
        str(tmp_path / "r"),
        "--no-progress",
    ]
    assert main(argv) == 3
    results = json.loads((tmp_path / "r" / "latest" / "results.json").read_text())
    ran, skipped = results["studies"]
    for line, only in ((ran["command"], None), (skipped["command"], "b")):
        args = parse_reproduce(line)
        assert args["command"] == "all" and args["quick"] is True
        assert args["material"] == "Ogden,NeoHookean" and args["mesh"] == f"single-tet,{mesh_file}"
        assert args["states"] == "rest,shear" and args["only"] == only


def test_every_subcommand_has_examples_and_the_exit_policy_in_its_help(capsys):
    from comparisons.cli import command_modules

    for name in command_modules():
        with pytest.raises(SystemExit):
            main([name, "--help"])
        text = capsys.readouterr().out
        assert "examples:" in text and f"mjed-verify {name}" in text, name
        assert "exit codes:" in text and "3  incomplete" in text, name


@pytest.mark.parametrize(
    "argv, message",
    [
        (["all", "--material", "Rubber"], "unknown material 'Rubber'"),
        (["all", "--mesh", "nowhere.msh"], "nowhere.msh"),
        (["all", "--states", "twisted"], "unknown state"),
        (["all", "--only", "astrology"], "unknown study key"),
    ],
)
def test_all_refuses_bad_input_before_any_work(tmp_path, capsys, argv, message):
    assert main([*argv, "--out", str(tmp_path / "r")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_all_refuses_a_non_tetrahedral_mesh(tmp_path, capsys):
    meshio = pytest.importorskip("meshio")
    import numpy as np

    path = tmp_path / "triangles.vtu"
    meshio.write(str(path), meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 2]]))]))
    assert main(["all", "--mesh", str(path), "--out", str(tmp_path / "r")]) == 2
    assert "tetra" in capsys.readouterr().err.lower()


@pytest.mark.oracle
def test_all_quick_equivalence_section_end_to_end(tmp_path):
    pytest.importorskip("dolfinx")
    code = main(
        [
            "all",
            "--quick",
            "--only",
            "equivalence",
            "--material",
            "NeoHookean,Ogden",
            "--mesh",
            "single-tet",
            "--out",
            str(tmp_path),
            "--no-progress",
        ]
    )
    assert code == 3  # quick, and the other studies were not selected
    results = json.loads((tmp_path / "latest" / "results.json").read_text())
    eq = results["studies"][0]
    assert eq["key"] == "equivalence" and eq["status"] == "passed" and eq["partial"]
    cases = eq["data"]["cases"]
    assert len(cases) == 2 * len(state_names()) and all(c["passed"] for c in cases)
    args = parse_reproduce(eq["command"])
    assert (args["command"], args["material"], args["mesh"], args["states"]) == (
        "equivalence",
        "NeoHookean,Ogden",
        "single-tet",
        "all",
    )
    assert (
        "coaxial tangent against the exact Hessian"
        in (tmp_path / "latest" / "index.html").read_text()
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["all", "--out", "/proc/1/nowhere"],
        ["regularization", "--json", "/proc/x/r.json"],
        ["equivalence", "--json", "."],
    ],
)
def test_unwritable_destinations_are_refused_before_any_work(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "cannot write there" in err or "is a directory" in err


def test_progress_is_drawn_only_when_enabled():
    import io

    from common.progress import Progress, StatusLine

    quiet, loud = io.StringIO(), io.StringIO()
    for stream, enabled in ((quiet, None), (loud, True)):  # StringIO is not a terminal
        bar = Progress(2, "work", stream=stream, enabled=enabled)
        bar.advance("one")
        bar.close()
        line = StatusLine("study", stream=stream, enabled=enabled)
        line("step 1")
        line.close()
    assert quiet.getvalue() == ""
    assert "work [" in loud.getvalue() and "1/2" in loud.getvalue() and "step 1" in loud.getvalue()


@pytest.mark.slow
def test_all_quick_timing_and_liver_sections_are_their_studies_results(tmp_path):
    """The report runs timing and liver through their own study functions (no ERROR), and
    each section's reproduce line names the material that ran.
    """
    from comparisons.liver.records import LiverData

    pytest.importorskip("dolfinx")
    code = main(
        [
            "all",
            "--quick",
            "--only",
            "timing,liver",
            "--material",
            "NeoHookean",
            "--out",
            str(tmp_path),
            "--no-progress",
        ]
    )
    assert code in (1, 3) or code == 0
    results = json.loads((tmp_path / "latest" / "results.json").read_text())
    by_key = {s["key"]: s for s in results["studies"]}
    for key in ("timing", "liver"):
        assert by_key[key]["status"] not in ("error", "not run"), by_key[key]["reason"]
    assert [r["material"] for r in by_key["timing"]["data"]["results"]][:1] == ["NeoHookean"]
    assert "NeoHookean" in by_key["timing"]["command"]
    # The figure paths in the data resolve from the published run directory (it was renamed).
    figures = LiverData.from_dict(by_key["liver"]["data"]).figures  # every key read and checked
    assert figures and all(
        not os.path.isabs(p) and (tmp_path / "latest" / p).is_file() for p in figures
    )


def test_paths_into_the_run_directory_become_relative_and_nothing_else_changes(tmp_path):
    from comparisons.report.runner import _paths_relative_to

    run = str(tmp_path / ".partial-x")
    payload = {
        "a": [f"{run}/liver/fig.png", os.path.abspath(run) + "/t.png"],
        "b": {"c": run + "-other/x"},
        "d": "/data/mine.png",
        "e": 3,
        "f": "plain words",
    }
    assert _paths_relative_to(payload, run) == {
        "a": ["liver/fig.png", "t.png"],
        "b": {"c": run + "-other/x"},
        "d": "/data/mine.png",
        "e": 3,
        "f": "plain words",
    }


def test_reproduce_lines_drop_only_an_out_into_the_run_directory(tmp_path):
    from comparisons.report.runner import _without_run_dir_out

    run = str(tmp_path / ".partial-x")
    cmd = f"mjed-verify liver --quick --out {run}/figures/liver --json liver.json"
    assert _without_run_dir_out(cmd, run) == "mjed-verify liver --quick --json liver.json"
    mine = "mjed-verify liver --out /data/my-reports"
    assert _without_run_dir_out(mine, run) == mine


def test_sigterm_ends_the_run_like_ctrl_c_and_leaves_no_partial_folder(tmp_path):
    import subprocess
    import sys

    # in a child: SIGTERM's default action would kill the test process itself
    script = f"""
import os, signal, sys, time
sys.path.insert(0, {os.getcwd()!r})
from common.result import Check, StudyResult
from comparisons.report.runner import ReportStudy, run_report

def fine(ctx):
    return StudyResult.from_checks("a", "A", [Check("x", 0.5, 1.0)], headline="ok", command="c")

def terminated(ctx):
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(5)

studies = [ReportStudy("a", "A", fine), ReportStudy("t", "T", terminated)]
context = {{"materials": (), "meshes": (), "states": (), "show_progress": False}}
out = run_report({str(tmp_path)!r}, studies, context, quick=True, stream=open(os.devnull, "w"))
print(out.run_dir, out.complete, out.results[1].reason)
"""
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    run_dir, complete, reason = proc.stdout.split(" ", 2)
    assert run_dir.endswith("-interrupted") and complete == "False"
    assert reason.strip() == "terminated (SIGTERM) during this study"
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".partial")]
    assert os.path.isfile(os.path.join(run_dir, "index.html"))


def test_the_interruption_message_names_the_out_folder(tmp_path, monkeypatch, capsys):
    from comparisons.report import runner

    def cut(reports_dir, *args, **kwargs):
        return runner.RunOutcome(
            run_dir=os.path.join(reports_dir, "x-interrupted"), complete=False, results=[]
        )

    monkeypatch.setattr(runner, "run_report", cut)
    out = str(tmp_path / "elsewhere")
    assert main(["all", "--only", "provenance", "--out", out, "--no-progress"]) == 130
    err = capsys.readouterr().err
    assert f"{out}/latest unchanged" in err and "reports/latest" not in err
