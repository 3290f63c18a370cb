"""What the documentation tests share within one pytest process: executed tutorials and a built
site.

Each tutorial is executed once per test session (into a fresh temporary cache, so nothing
from an earlier run is reused), by ``tests/test_tutorials.py`` or by the site build of
``tests/test_docs_site.py``, whichever asks first; the build then reuses the executions
(``docs/_ext/tutorial_runner.py`` matches them by a hash of the sources). The two modules
usually run on different pytest-xdist workers: the session's cache is then one folder made by
the controlling process (``tests/conftest.py``, ``TUTORIAL_CACHE_VARIABLE``), and a lock per
tutorial makes the second worker wait for the first one's run and reuse it instead of running
the tutorial again.
"""

from __future__ import annotations

import atexit
import fcntl
import functools
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
import tutorial_runner  # noqa: E402


@functools.lru_cache(maxsize=None)
def session_dir() -> Path:
    path = Path(tempfile.mkdtemp(prefix="mjed-docs-tests-"))
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path


def tutorial_cache() -> Path:
    from conftest import TUTORIAL_CACHE_VARIABLE

    shared = os.environ.get(TUTORIAL_CACHE_VARIABLE)
    return Path(shared) if shared else session_dir() / "tutorials"


@functools.lru_cache(maxsize=None)
def executed(script: Path) -> "tutorial_runner.Execution":
    """Run one tutorial (subprocess, cwd a temporary directory) once per session: a process
    that finds another one running it waits for that run and reuses it.
    """
    cache = tutorial_cache()
    cache.mkdir(parents=True, exist_ok=True)
    with open(cache / f"{Path(script).stem}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return tutorial_runner.ensure_executed(Path(script), cache)


@dataclass(frozen=True)
class Build:
    html: Path
    returncode: int
    output: str


@functools.lru_cache(maxsize=None)
def built_site() -> Build:
    """The site built from the working tree into a temporary directory (tutorials reused)."""
    for script in tutorial_runner.tutorial_scripts():
        executed(script)
    out = session_dir() / "site"
    env = dict(os.environ, MJED_TUTORIAL_CACHE=str(tutorial_cache()))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-b",
            "html",
            "-q",
            str(DOCS),
            str(out / "html"),
            "-d",
            str(out / "doctrees"),
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )
    return Build(out / "html", proc.returncode, proc.stdout + proc.stderr)
