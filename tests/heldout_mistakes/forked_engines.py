"""Run a corpus engine, ``python ENGINE INPUT OUTPUT``, in a process forked from a warm Python
that has already imported NumPy and SciPy, instead of starting a new Python for every case.

Why: the corpora's engines are run ten times each (two states, four probes per state), about
330 runs per corpus, and a new Python importing NumPy and SciPy costs about 0.15 s of CPU
before the engine computes anything (most of a small engine's run on the kits' meshes). A
fork of a warm process costs a few milliseconds.

How: one helper process per judging process (``python forked_engines.py --zygote``) imports
:data:`PRELOAD` and then, for each request on its stdin (one JSON line), forks a child that
becomes the engine: its own session, stdin closed, stdout and stderr into files, ``sys.argv``
``[ENGINE, INPUT, OUTPUT]``, the engine's folder first on ``sys.path``, the script run as
``__main__``, and the interpreter's exit codes (``sys.exit(n)``; 1 with the traceback on an
uncaught exception). The helper waits for it at most the time limit, then kills its session,
and answers with the exit status (negative: the signal that ended it).

What is not the same as a new interpreter: modules the engine imports that the helper had
already imported are not run again (their state is that of a fresh import: nothing ran
between). The results are compared with the subprocess way, engine by engine, by
tests/test_run_corpus.py. Any command that is not ``[this Python, SCRIPT.py, ...]`` runs as the
checker runs it (:func:`conformance.engine.process.run_engine`). Test tooling only:
``mjed-verify check --command`` always starts the user's command itself.
"""

from __future__ import annotations

import atexit
import json
import os
import runpy
import select
import signal
import subprocess
import sys
import tempfile
import traceback
from typing import Optional, Sequence

#: what the helper imports once; an engine's own imports of these then cost nothing
PRELOAD = ["numpy", "scipy", "scipy.linalg", "scipy.sparse", "pathlib", "argparse"]


# -- the helper (its own process) ---------------------------------------------------------
def _become_engine(argv: Sequence[str], out_path: str, err_path: str) -> int:
    """In the forked child: set the process up as ``python SCRIPT ARGS`` would, run the script,
    and return its exit code.
    """
    os.setsid()
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    for fd, name in ((1, out_path), (2, err_path)):
        target = os.open(name, os.O_WRONLY | os.O_TRUNC)
        os.dup2(target, fd)
        os.close(target)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    script = argv[1]
    sys.argv = list(argv[1:])
    sys.path[0] = os.path.dirname(os.path.abspath(script))
    try:
        runpy.run_path(script, run_name="__main__")
        code = 0
    except SystemExit as exc:  # what the interpreter makes of sys.exit(...)
        if exc.code is None:
            code = 0
        elif isinstance(exc.code, int):
            code = exc.code & 0xFF
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException as exc:  # noqa: BLE001 - a crash is the exit status, as for python
        _print_from_script(exc, script)
        code = 1
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a closed stream cannot change the exit code
            pass
    return code


def _print_from_script(exc: BaseException, script: str) -> None:
    """The traceback as the interpreter prints it for a script: from the script's own frame,
    without this module's and runpy's frames above it.
    """
    tb = exc.__traceback__
    path = os.path.abspath(script)
    while tb is not None and os.path.abspath(tb.tb_frame.f_code.co_filename) != path:
        tb = tb.tb_next
    traceback.print_exception(type(exc), exc, tb or exc.__traceback__)


def _wait(pid: int, timeout: float) -> tuple:
    """(exit status as subprocess gives it, timed out): the child is waited at most ``timeout``
    seconds, then its whole session is killed.
    """
    fd = os.pidfd_open(pid)
    try:
        ready, _, _ = select.select([fd], [], [], timeout)
    finally:
        os.close(fd)
    timed_out = not ready
    if timed_out:
        try:
            os.killpg(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), timed_out


def serve() -> None:
    """The helper's loop: one JSON request per line on stdin, one JSON answer per line."""
    for name in PRELOAD:
        __import__(name)
    requests, answers = sys.stdin.buffer, sys.stdout.buffer
    for line in requests:
        req = json.loads(line)
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                code = _become_engine(req["argv"], req["stdout"], req["stderr"])
            finally:
                os._exit(code)
        code, timed_out = _wait(pid, req["timeout"])
        answers.write((json.dumps({"returncode": code, "timed_out": timed_out}) + "\n").encode())
        answers.flush()


# -- the judging process's side -----------------------------------------------------------
_helper: Optional[subprocess.Popen] = None


def _helper_process() -> subprocess.Popen:
    global _helper
    if _helper is None or _helper.poll() is not None:
        _helper = subprocess.Popen(
            [sys.executable, os.path.abspath(__file__), "--zygote"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        atexit.register(_stop_helper, _helper)
    return _helper


def _stop_helper(helper: subprocess.Popen) -> None:
    """At exit: end of requests, and the helper waited for (no orphan left behind)."""
    try:
        helper.stdin.close()
        helper.wait(timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        helper.kill()
        helper.wait()


def is_python_script(argv: Sequence[str]) -> bool:
    """``[this Python, SCRIPT.py, ...]``: a command this module can run by forking."""
    return (
        len(argv) >= 2
        and os.path.abspath(argv[0]) == os.path.abspath(sys.executable)
        and argv[1].endswith(".py")
        and os.path.isfile(argv[1])
    )


def _bounded(path: str) -> bytes:
    """The file's head and tail as run_engine keeps a stream's."""
    from conformance.engine.process import head_and_tail

    with open(path, "rb") as f:
        return head_and_tail(f.read())


def run_forked(argv: Sequence[str], timeout: float):
    """Run ``argv`` as :func:`conformance.engine.process.run_engine` does (the same EngineRun),
    forking a Python script from the warm helper.
    """
    from conformance.engine.process import EngineRun, run_engine

    if not is_python_script(argv):
        return run_engine(argv, timeout)
    helper = _helper_process()
    with tempfile.TemporaryDirectory(prefix="mjed-forked-") as tmp:
        out_path, err_path = os.path.join(tmp, "stdout"), os.path.join(tmp, "stderr")
        for name in (out_path, err_path):
            open(name, "wb").close()
        request = {"argv": list(argv), "stdout": out_path, "stderr": err_path, "timeout": timeout}
        helper.stdin.write((json.dumps(request) + "\n").encode())
        helper.stdin.flush()
        answer = helper.stdout.readline()
        if not answer:  # the helper died: this case runs the ordinary way
            return run_engine(argv, timeout)
        ran = json.loads(answer)
        return EngineRun(
            ran["returncode"], ran["timed_out"], _bounded(out_path), _bounded(err_path), 0
        )


if __name__ == "__main__" and sys.argv[1:] == ["--zygote"]:
    serve()
