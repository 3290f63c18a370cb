"""Run an external engine per case: ``my_engine {input} {output}``.

The template is split like a POSIX shell command line (``shlex``; no pipes or redirections: wrap
them in a script), then ``{input}`` and ``{output}`` are replaced in each word by the case's input
directory and a fresh output directory. The process runs in its own session with a time limit;
on expiry its whole process group is killed. A non-zero exit, a time limit or a missing output
is an error for that case only, reported with the tail of the engine's stderr.
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
from typing import Callable, List

from conformance.exchange import EngineOutput, read_output
from conformance.kit import KitCase
from conformance.run import CaseError

__all__ = ["command_words", "command_evaluator", "STDERR_TAIL"]

STDERR_TAIL = 1500  # characters of stderr kept in a message


def command_words(template: str) -> List[str]:
    """Split and check the template: it must name {input} and {output}."""
    try:
        words = shlex.split(template)
    except ValueError as exc:
        raise ValueError(f"--command {template!r}: {exc}") from None
    if not words:
        raise ValueError("--command is empty")
    text = " ".join(words)
    missing = [k for k in ("{input}", "{output}") if k not in text]
    if missing:
        raise ValueError(
            f"--command {template!r} must contain {' and '.join(missing)} (replaced by the case's "
            "input and output directories)"
        )
    return words


def _tail(data: bytes) -> str:
    text = data.decode("utf-8", errors="replace").strip()
    return ("..." + text[-STDERR_TAIL:]) if len(text) > STDERR_TAIL else text


def command_evaluator(
    template: str, input_dir: Callable[[KitCase], str], output_root: str, timeout: float
) -> Callable[[KitCase], EngineOutput]:
    """An evaluator running the command for each case; outputs go to ``output_root/<case id>``
    (a new directory per case, never the user's kit).
    """
    words = command_words(template)

    def evaluate(case: KitCase) -> EngineOutput:
        src = os.path.abspath(input_dir(case))
        out = os.path.abspath(os.path.join(output_root, case.case_id))
        os.makedirs(out)
        argv = [w.replace("{input}", src).replace("{output}", out) for w in words]
        try:
            proc = subprocess.Popen(
                argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True
            )
        except OSError as exc:
            raise CaseError(
                f"case {case.case_id}: cannot start {argv[0]!r}: {exc.strerror or exc}"
            ) from None
        try:
            _, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the engine and anything it started
            _, err = proc.communicate()
            raise CaseError(
                f"case {case.case_id}: {argv[0]} ran past the time limit of {timeout:g} s and was "
                "killed" + (f"; stderr: {_tail(err)}" if err.strip() else "")
            ) from None
        if proc.returncode != 0:
            how = (
                f"killed by signal {-proc.returncode}"
                if proc.returncode < 0
                else f"exit code {proc.returncode}"
            )
            raise CaseError(
                f"case {case.case_id}: {argv[0]} failed ({how})"
                + (f"; stderr: {_tail(err)}" if err.strip() else "; no stderr")
            )
        return read_output(out, case.input.n_nodes, case.case_id)

    return evaluate
