"""The report runner: sections survive failures, runs never overwrite each other, latest moves last."""

import json
import os
import re

import pytest

from comparisons.cli import main
from comparisons.blocks import Figure, Paragraph, Table
from comparisons.report.runner import Study, StudyResult, publish_latest, run_report


def _figure_study(ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = ctx.figure_path("line.png")
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    fig.savefig(path)
    plt.close(fig)
    return StudyResult({"value": 1.5}, [Paragraph("a line"), Figure(ctx.relative(path), "a line"),
                                        Table(("a", "b"), [(1, 2.5e-12)])])


def _boom(ctx):
    raise RuntimeError("the rheometer exploded")


def _failing_check(ctx):
    return StudyResult({"cases": []}, [Paragraph("one case off")], passed=False, message="1 case failed")


def _interrupt(ctx):
    raise KeyboardInterrupt


STUDIES = [Study("figure", "A figure", "Shows a line.", "mjed-verify figure", _figure_study),
           Study("boom", "A study that raises", "Never finishes.", "mjed-verify boom", _boom),
           Study("check", "A failing check", "One case off.", "mjed-verify check", _failing_check)]
CTX = {"materials": (), "meshes": (), "states": (), "show_progress": False}


def test_a_failed_study_leaves_the_other_sections_and_says_why(tmp_path):
    out = run_report(str(tmp_path), STUDIES, CTX, quick=True, command_line=["mjed-verify", "all"], stream=open(os.devnull, "w"))
    assert out.complete and not out.all_passed
    status = {s.key: (s.status, s.message) for s in out.sections}
    assert status["figure"] == ("ok", "")
    assert status["boom"] == ("error", "RuntimeError: the rheometer exploded")
    assert status["check"] == ("failed", "1 case failed")
    assert status["verdict"][0] == "failed"
    page = (tmp_path / "latest" / "index.html").read_text()
    assert "the rheometer exploded" in page and "1 case failed" in page
    # Self-contained: the figure is embedded, nothing is fetched from elsewhere.
    assert "data:image/png;base64," in page
    assert not re.search(r"""src=["'](?!data:)""", page)
    results = json.loads((tmp_path / "latest" / "results.json").read_text())
    assert results["complete"] and results["results"]["figure"] == {"value": 1.5}
    assert (tmp_path / "latest" / "report.md").read_text().startswith("# MJED verification report")


def test_a_new_run_never_destroys_the_previous_one(tmp_path):
    first = run_report(str(tmp_path), STUDIES[:1], CTX, quick=True, stream=open(os.devnull, "w"))
    second = run_report(str(tmp_path), STUDIES[:1], CTX, quick=True, stream=open(os.devnull, "w"))
    assert first.run_dir != second.run_dir
    assert os.path.isfile(os.path.join(first.run_dir, "index.html"))
    assert os.path.realpath(tmp_path / "latest") == os.path.realpath(second.run_dir)


def test_an_interrupted_run_keeps_what_it_has_and_leaves_latest_alone(tmp_path):
    done = run_report(str(tmp_path), STUDIES[:1], CTX, quick=True, stream=open(os.devnull, "w"))
    studies = [STUDIES[0], Study("stop", "Interrupted", "", "", _interrupt), STUDIES[2]]
    cut = run_report(str(tmp_path), studies, CTX, quick=True, stream=open(os.devnull, "w"))
    assert not cut.complete and cut.run_dir.endswith("-interrupted")
    assert [s.status for s in cut.sections[1:]] == ["ok", "interrupted", "interrupted"]
    assert os.path.isfile(os.path.join(cut.run_dir, "index.html"))
    assert os.path.realpath(tmp_path / "latest") == os.path.realpath(done.run_dir)
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".partial")]


def test_latest_that_is_a_real_directory_is_not_replaced(tmp_path):
    (tmp_path / "latest").mkdir()
    (tmp_path / "run").mkdir()
    with pytest.raises(OSError, match="real directory"):
        publish_latest(str(tmp_path), "run")
    assert (tmp_path / "latest").is_dir()


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


def test_every_subcommand_has_examples_in_its_help(capsys):
    from comparisons.cli import command_modules

    for name in command_modules():
        with pytest.raises(SystemExit):
            main([name, "--help"])
        text = capsys.readouterr().out
        assert "examples:" in text and f"mjed-verify {name}" in text, name


@pytest.mark.oracle
def test_all_quick_equivalence_section_end_to_end(tmp_path):
    pytest.importorskip("dolfinx")
    code = main(["all", "--quick", "--only", "equivalence,ogden_tangent", "--material", "NeoHookean,Ogden",
                 "--mesh", "single-tet", "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    results = json.loads((tmp_path / "latest" / "results.json").read_text())
    cases = results["results"]["equivalence"]["cases"]
    assert len(cases) == 12 and all(c["passed"] for c in cases)
    assert "Ogden: SOFA" in (tmp_path / "latest" / "index.html").read_text()


@pytest.mark.parametrize("argv", [["all", "--out", "/proc/1/nowhere"], ["regularization", "--json", "/proc/x/r.json"],
                                  ["equivalence", "--json", "."]])
def test_unwritable_destinations_are_refused_before_any_work(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "cannot write there" in err or "is a directory" in err


def test_progress_is_drawn_only_when_enabled():
    import io

    from comparisons.progress import Progress, StatusLine

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
