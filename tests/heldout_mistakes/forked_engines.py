"""Run a corpus engine, ``python ENGINE INPUT OUTPUT``, in a process forked from one that has
already imported NumPy and SciPy, instead of starting a new Python for every case.

Why: the corpora's engines are run ten times each (two states, four probes per state), about
330 runs per corpus, and a new Python importing NumPy and SciPy costs about 0.15 s of CPU
before the engine computes anything (the whole of a small engine's run on the kits' meshes).
A fork from a warm process costs a few milliseconds.

What stays the same as ``python ENGINE INPUT OUTPUT``: the script runs as ``__main__`` with
that ``sys.argv`` and its folder first on ``sys.path``, stdin closed, stdout and stderr
captured, the same exit codes (``sys.exit(n)``, 1 with the traceback on an uncaught exception),
killed at the time limit. The results are compared with the subprocess way, engine by engine,
by tests/test_run_corpus.py. Anything that is not such a command runs as the checker runs it
(:func:`conformance.engine.process.run_engine`).

Test tooling only: ``mjed-verify check --command`` always starts the user's command itself.
"""

from __future__ import annotations

import multiprocessing
import os
import runpy
import sys
import tempfile
from typing import Sequence

from conformance.engine.process import HEAD_BYTES, TAIL_BYTES, EngineRun, run_engine

#: what the fork server imports once; each engine imports these again for free
PRELOAD = ["numpy", "scipy", "scipy.linalg", "scipy.sparse", "json", "pathlib"]

_context = None


def _server():
    global _context
    if _context is None:
        _context = multiprocessing.get_context("forkserver")
        # "__main__" too: the judging process's main script is imported once by the server, not
        # again by every child (multiprocessing's spawn preparation would otherwise re-run it)
        _context.set_forkserver_preload(["__main__", __name__, *PRELOAD])
    return _context


def _script(path: str, args: Sequence[str], out_path: str, err_path: str) -> None:
    """The child: stdout and stderr to the two files, then the script as ``__main__``."""
    for fd, name in ((1, out_path), (2, err_path)):
        target = os.open(name, os.O_WRONLY | os.O_TRUNC)
        os.dup2(target, fd)
        os.close(target)
    sys.argv = [path, *args]
    sys.path.insert(0, os.path.dirname(os.path.abspath(path)))
    # multiprocessing flushes both streams and turns SystemExit and exceptions into the exit
    # code (a traceback on stderr, 1) as the interpreter does for a script
    runpy.run_path(path, run_name="__main__")


def _bounded(path: str) -> bytes:
    """The file's head and tail as run_engine keeps a stream's (the middle dropped, said so)."""
    with open(path, "rb") as f:
        data = f.read()
    if len(data) <= HEAD_BYTES + TAIL_BYTES:
        return data
    dropped = len(data) - HEAD_BYTES - TAIL_BYTES
    return data[:HEAD_BYTES] + f"...[{dropped} bytes dropped]...".encode() + data[-TAIL_BYTES:]


def is_python_script(argv: Sequence[str]) -> bool:
    """``[this Python, SCRIPT.py, ...]``: a command this module can run by forking."""
    return (
        len(argv) >= 2
        and os.path.abspath(argv[0]) == os.path.abspath(sys.executable)
        and argv[1].endswith(".py")
        and os.path.isfile(argv[1])
    )


def run_forked(argv: Sequence[str], timeout: float) -> EngineRun:
    """Run ``argv`` as :func:`run_engine` does, forking a Python script from the warm server."""
    if not is_python_script(argv):
        return run_engine(argv, timeout)
    with tempfile.TemporaryDirectory(prefix="mjed-forked-") as tmp:
        out_path, err_path = os.path.join(tmp, "stdout"), os.path.join(tmp, "stderr")
        for name in (out_path, err_path):
            open(name, "wb").close()
        child = _server().Process(
            target=_script, args=(argv[1], list(argv[2:]), out_path, err_path)
        )
        child.start()
        child.join(timeout)
        timed_out = child.is_alive()
        if timed_out:
            child.kill()
            child.join()
        code = child.exitcode
        child.close()
        return EngineRun(code, timed_out, _bounded(out_path), _bounded(err_path), 0)
