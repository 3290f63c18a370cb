"""Every tutorial of docs/tutorials runs to the end, its asserts included.

Each one is executed as a script in a subprocess whose working directory is a temporary
directory (docs/_ext/tutorial_runner.py runs its cells in order, as `python FILE` would, and
records outputs and figures for the site). A failure names the tutorial, the cell and the
failed assert with its traceback.
"""

from __future__ import annotations

import json
import os

import pytest
from docs_support import executed, tutorial_runner

SCRIPTS = tutorial_runner.tutorial_scripts()


def test_there_are_tutorials():
    names = {p.stem for p in SCRIPTS}
    assert {
        "one_tetrahedron",
        "why_mjed_is_faster",
        "compressed_elements",
        "viscosity",
        "liver",
    } <= names


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_tutorial_runs_with_its_asserts(script):
    run = executed(script)
    if not run.ok:
        pytest.fail(f"tutorial {script.name} failed:\n{run.error}", pytrace=False)
    status = json.loads((run.outdir / "status.json").read_text())
    assert status["ok"] and (run.outdir / "page.md").read_text().strip()
    # Its asserts are what make a tutorial a test: one that asserts nothing proves nothing.
    assert "assert " in script.read_text(), f"{script.name} asserts none of its numbers"


def test_a_failing_assert_is_reported_with_the_tutorial_and_the_line(tmp_path):
    script = tmp_path / "broken.py"
    script.write_text(
        "# %% [markdown]\n# # Broken\n\n# %%\nvalue = 2 + 2\n\n# %%\nassert value == 5, 'four is "
        "not five'\n"
    )
    run = tutorial_runner.ensure_executed(script, tmp_path / "cache")
    assert not run.ok
    assert "broken.py" in run.error and "line 8" in run.error
    assert "assert value == 5" in run.error and "four is not five" in run.error


def test_what_a_tutorial_makes_in_the_temporary_folder_goes_with_its_run(tmp_path):
    script = tmp_path / "keeps.py"
    out = tmp_path / "made.txt"
    script.write_text(
        "# %% [markdown]\n# # Keeps a folder\n\n# %%\nimport tempfile\n"
        f"made = tempfile.mkdtemp(prefix='kept-')\nopen({str(out)!r}, 'w').write(made)\n"
    )
    run = tutorial_runner.ensure_executed(script, tmp_path / "cache")
    assert run.ok, run.error
    made = out.read_text()
    assert made and not os.path.exists(made)


def test_cells_and_markdown_are_parsed_with_their_lines():
    cells = tutorial_runner.parse_cells(
        "# %% [markdown]\n# # Title\n#\n# text\n\n# %%\nx = 1\n\n\n# %%\ny = 2\n"
    )
    assert [(c.kind, c.line) for c in cells] == [("markdown", 2), ("code", 7), ("code", 11)]
    assert cells[0].text == "# Title\n\ntext"
