"""Execute a jupytext percent-format tutorial cell by cell and render it as a MyST page.

A tutorial is a plain Python file (``python docs/tutorials/NAME.py`` runs it) whose cells are
separated by ``# %%`` lines; a ``# %% [markdown]`` cell holds Markdown in commented lines.
This module runs the cells in order in one namespace, as ``python`` would, and records what
each code cell printed and every matplotlib figure it left open. The result is a directory:

    page.md        the tutorial as MyST Markdown: prose, code, outputs, figures
    figN.png       the figures, numbered in order of appearance
    status.json    {"ok": bool, "seconds": float, "key": str, "error": str | None}

Used two ways: by the documentation build (``docs/_ext/site_generation.py``, one subprocess
per tutorial) and by ``tests/test_tutorials.py``. Both go through :func:`ensure_executed`,
which reuses a directory whose key (a hash of the tutorial, this runner and the project's
sources) matches, so one ``make test`` executes each tutorial once.

Command line (exit code 1 and the failing cell's traceback on stderr when a cell raises)::

    python docs/_ext/tutorial_runner.py docs/tutorials/one_tetrahedron.py OUTDIR
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL_DIR = ROOT / "docs" / "tutorials"
# The project's sources whose change must re-execute every tutorial.
SOURCE_PACKAGES = ("mjed", "reference_fem", "common", "comparisons", "meshes", "conformance")

_CELL_MARK = re.compile(r"^# %%(.*)$")


@dataclass(frozen=True)
class Cell:
    """One cell: kind "code" or "markdown", its text and the 1-based line of its first text line."""

    kind: str
    text: str
    line: int


def parse_cells(source: str) -> List[Cell]:
    """Split a percent-format script into cells (a jupytext YAML header is dropped)."""
    lines = source.splitlines()
    start = 0
    if lines and lines[0].strip() == "# ---":  # jupytext header block
        for i in range(1, len(lines)):
            if lines[i].strip() == "# ---":
                start = i + 1
                break
    cells: List[Cell] = []
    kind, body, first = "code", [], start + 1
    for i in range(start, len(lines)):
        m = _CELL_MARK.match(lines[i])
        if m:
            _append_cell(cells, kind, body, first)
            kind = "markdown" if "[markdown]" in m.group(1) else "code"
            body, first = [], i + 2
        else:
            body.append(lines[i])
    _append_cell(cells, kind, body, first)
    return cells


def _append_cell(cells: List[Cell], kind: str, body: List[str], first: int) -> None:
    # Drop blank lines at both ends (keeping the line number of the first kept line).
    lo, hi = 0, len(body)
    while lo < hi and not body[lo].strip():
        lo += 1
    while hi > lo and not body[hi - 1].strip():
        hi -= 1
    if lo == hi:
        return
    text = "\n".join(body[lo:hi])
    if kind == "markdown":
        text = "\n".join(_uncomment(line) for line in body[lo:hi])
    cells.append(Cell(kind, text, first + lo))


def _uncomment(line: str) -> str:
    if line.startswith("# "):
        return line[2:]
    if line.startswith("#"):
        return line[1:]
    raise ValueError(f"a Markdown cell line must be a comment: {line!r}")


class TutorialError(RuntimeError):
    """A cell raised; the message names the tutorial, the cell's line and the traceback."""


def execute(script: Path, outdir: Path) -> dict:
    """Run every cell of ``script``; write page.md, the figures and status.json into ``outdir``.

    The working directory is left as the caller set it (tutorials write their files there).
    Raises TutorialError when a cell raises, after writing status.json with ok = false.
    """
    script = Path(script).resolve()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    for old in outdir.glob("fig*.png"):
        old.unlink()
    os.environ.setdefault("MPLBACKEND", "Agg")
    cells = parse_cells(script.read_text())
    namespace = {"__name__": "__main__", "__file__": str(script)}
    parts: List[str] = []
    n_fig = 0
    t0 = time.perf_counter()
    sys.path.insert(0, str(script.parent))
    try:
        for cell in cells:
            if cell.kind == "markdown":
                parts.append(cell.text)
                continue
            parts.append(f"```python\n{cell.text}\n```")
            buffer = io.StringIO()
            code = compile("\n" * (cell.line - 1) + cell.text + "\n", str(script), "exec")
            try:
                with contextlib.redirect_stdout(buffer), contextlib.redirect_stderr(buffer):
                    exec(code, namespace)  # noqa: S102 - running the tutorial is the point
            except BaseException as exc:  # noqa: BLE001 - reported with the cell's location
                message = _failure_message(script, cell, exc, buffer.getvalue())
                _write_status(outdir, ok=False, seconds=time.perf_counter() - t0, error=message)
                raise TutorialError(message) from None
            output = buffer.getvalue().rstrip()
            if output:
                parts.append(f"```text\n{output}\n```")
            for fig_path in _save_figures(outdir, n_fig):
                n_fig += 1
                parts.append(f"![Figure {n_fig} of the tutorial {script.stem}]({fig_path.name})")
    finally:
        sys.path.remove(str(script.parent))
    seconds = time.perf_counter() - t0
    (outdir / "page.md").write_text("\n\n".join(parts) + "\n")
    return _write_status(outdir, ok=True, seconds=seconds, error=None)


def _save_figures(outdir: Path, n_before: int) -> List[Path]:
    """Save and close every open matplotlib figure (none if pyplot was never imported)."""
    plt = sys.modules.get("matplotlib.pyplot")
    if plt is None:
        return []
    paths = []
    for num in plt.get_fignums():
        fig = plt.figure(num)
        path = outdir / f"fig{n_before + len(paths) + 1}.png"
        fig.savefig(path, dpi=96, bbox_inches="tight")
        plt.close(fig)
        paths.append(path)
    return paths


def _failure_message(script: Path, cell: Cell, exc: BaseException, output: str) -> str:
    # Keep the frames from the tutorial itself and below (not this runner's exec frame).
    tb = exc.__traceback__
    while tb is not None and tb.tb_frame.f_code.co_filename != str(script):
        tb = tb.tb_next
    text = "".join(traceback.format_exception(type(exc), exc, tb))
    where = (
        f"tutorial {script.name}: the cell starting at line {cell.line} raised {type(exc).__name__}"
    )
    tail = f"\n--- output of that cell ---\n{output.rstrip()}" if output.strip() else ""
    return f"{where}\n{text.rstrip()}{tail}"


def _write_status(outdir: Path, *, ok: bool, seconds: float, error: Optional[str]) -> dict:
    status = {"ok": ok, "seconds": round(seconds, 3), "error": error}
    (outdir / "status.json").write_text(json.dumps(status, indent=1))
    return status


# ---------------------------------------------------------------------------- caching
def source_key(script: Path) -> str:
    """Hash of the tutorial, this runner, the project's sources and the interpreter's versions."""
    h = hashlib.sha256()
    h.update(Path(script).read_bytes())
    h.update(Path(__file__).read_bytes())
    h.update(sys.version.encode())
    for pkg in SOURCE_PACKAGES:
        base = ROOT / pkg
        if not base.is_dir():
            continue
        for path in sorted(
            p for p in base.rglob("*") if p.is_file() and "__pycache__" not in p.parts
        ):
            h.update(str(path.relative_to(ROOT)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


@dataclass(frozen=True)
class Execution:
    """Where a tutorial's page was written, whether it ran through, and its failure message."""

    script: Path
    outdir: Path
    ok: bool
    seconds: float
    error: Optional[str]
    reused: bool


def ensure_executed(script: Path, cache_dir: Path, *, python: str = sys.executable) -> Execution:
    """Execute ``script`` in a fresh subprocess (cwd: a temporary directory) into
    ``cache_dir/<stem>``, unless that directory already holds a run with the same source key.
    """
    script = Path(script).resolve()
    outdir = Path(cache_dir) / script.stem
    key = source_key(script)
    status_path = outdir / "status.json"
    if status_path.exists() and (outdir / "key").exists() and (outdir / "key").read_text() == key:
        st = json.loads(status_path.read_text())
        return Execution(script, outdir, st["ok"], st["seconds"], st["error"], reused=True)
    outdir.mkdir(parents=True, exist_ok=True)
    (outdir / "key").unlink(missing_ok=True)
    env = dict(
        os.environ,
        MPLBACKEND="Agg",
        PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    )
    with tempfile.TemporaryDirectory(prefix=f"tutorial-{script.stem}-") as cwd:
        # What a tutorial makes under the system's temporary folder (a reader keeps it to look
        # at; the check tutorial's engine and report) goes inside cwd here, and goes with it.
        proc = subprocess.run(
            [python, str(Path(__file__).resolve()), str(script), str(outdir.resolve())],
            cwd=cwd,
            env=dict(env, TMPDIR=cwd),
            capture_output=True,
            text=True,
        )
    if proc.returncode != 0 and not status_path.exists():
        # The runner itself failed before a cell ran (import error of the runner, killed...).
        _write_status(
            outdir,
            ok=False,
            seconds=0.0,
            error=f"tutorial {script.name}: runner exited with "
            f"{proc.returncode}\n{proc.stderr.strip()}",
        )
    st = json.loads(status_path.read_text())
    if st["ok"] != (proc.returncode == 0):
        st = _write_status(
            outdir,
            ok=False,
            seconds=st["seconds"],
            error=f"tutorial {script.name}: runner exited with "
            f"{proc.returncode}\n{proc.stderr.strip()}",
        )
    (outdir / "key").write_text(key)
    return Execution(script, outdir, st["ok"], st["seconds"], st["error"], reused=False)


def tutorial_scripts(directory: Path = TUTORIAL_DIR) -> List[Path]:
    """The tutorials, sorted by name."""
    return sorted(p for p in Path(directory).glob("*.py") if not p.name.startswith("_"))


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if len(args) != 2:
        print("usage: tutorial_runner.py TUTORIAL.py OUTDIR", file=sys.stderr)
        return 2
    try:
        status = execute(Path(args[0]), Path(args[1]))
    except TutorialError as exc:
        print(exc, file=sys.stderr)
        return 1
    print(f"{Path(args[0]).name}: ran in {status['seconds']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
