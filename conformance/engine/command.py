"""Run an external engine per case: ``my_engine {input} {output}``.

The template is split like a POSIX shell command line (``shlex``; no pipes or redirections: wrap
them in a script), then ``{input}`` and ``{output}`` are replaced in each word by the case's input
directory and a fresh output directory. The engine runs through
:func:`conformance.engine.process.run_engine`: its own session, a time limit, bounded output, and
its whole process tree ended after the case. A non-zero exit, a time limit or a missing output is
an error for that case only, reported with the tail of the engine's stderr.
"""

from __future__ import annotations

import os
import shlex
from typing import Callable, List, Sequence

from conformance.engine.process import EngineRun, run_engine
from conformance.kit.cases import KitCase
from conformance.kit.exchange import CaseError, EngineOutput, read_output

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
            f"--command {template!r} must contain {' and '.join(missing)} "
            "(replaced by the case's input and output directories)"
        )
    return words


def _tail(data: bytes) -> str:
    text = data.decode("utf-8", errors="replace").strip()
    return ("..." + text[-STDERR_TAIL:]) if len(text) > STDERR_TAIL else text


def command_evaluator(
    template: str,
    input_dir: Callable[[KitCase], str],
    output_root: str,
    timeout: float,
    run: Callable[[Sequence[str], float], EngineRun] = run_engine,
) -> Callable[[KitCase], EngineOutput]:
    """An evaluator running the command for each case; outputs go to ``output_root/<case id>``
    (a new directory per case, never the user's kit). ``run`` runs one command line with a time
    limit (the check always uses :func:`run_engine`; a test harness may start a script faster
    but must give the same EngineRun).
    """
    words = command_words(template)

    def evaluate(case: KitCase) -> EngineOutput:
        src = os.path.abspath(input_dir(case))
        out = os.path.abspath(os.path.join(output_root, case.case_id))
        os.makedirs(out)
        argv = [w.replace("{input}", src).replace("{output}", out) for w in words]
        try:
            ran = run(argv, timeout)
        except OSError as exc:
            raise CaseError(
                f"case {case.case_id}: cannot start {argv[0]!r}: {exc.strerror or exc}"
            ) from None
        # quote stderr, or stdout when the engine wrote its complaint there
        stream, err = ("stderr", ran.stderr) if ran.stderr.strip() else ("stdout", ran.stdout)
        said = f"; {stream}: {_tail(err)}" if err.strip() else "; no stderr"
        if ran.timed_out:
            raise CaseError(
                f"case {case.case_id}: {argv[0]} ran past the time limit of "
                f"{timeout:g} s and was killed, with every process it started{said}"
            )
        if ran.returncode != 0:
            code = ran.returncode
            how = f"killed by signal {-code}" if code < 0 else f"exit code {code}"
            raise CaseError(f"case {case.case_id}: {argv[0]} failed ({how}){said}")
        return read_output(
            out,
            case.input.n_nodes,
            case.case_id,
            n_cells=case.input.n_cells,
            within=os.path.abspath(output_root),
        )

    return evaluate
