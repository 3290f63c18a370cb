"""tests/heldout_mistakes/forked_engines.py: a Python engine script forked from a warm helper
gives what a new interpreter gives (exit status, streams, time limit), so the corpora's verdicts
do not depend on which way their engines were started.
"""

from __future__ import annotations

import importlib.util
import sys

import pytest
from heldout_support import TESTS

from conformance.engine.process import run_engine

_spec = importlib.util.spec_from_file_location(
    "forked_engines", TESTS / "heldout_mistakes" / "forked_engines.py"
)
forked = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(forked)

SCRIPTS = {
    "exit code": "import sys\nsys.exit(3)\n",
    "exit message": "import sys\nsys.exit('bad input: no nodes')\n",
    "crash": "import numpy\ndef f():\n    raise ValueError('boom')\nf()\n",
    "streams": "import sys\nprint('out', sys.argv[1:])\nprint('err', file=sys.stderr)\n",
    "own folder on sys.path": "import sys, os\nprint(sys.path[0] == os.path.dirname(__file__))\n",
    "at exit": "import atexit\natexit.register(lambda: print('bye'))\n",
}


def _run(run, script, timeout=30.0):
    ran = run([sys.executable, str(script), "IN", "OUT"], timeout)
    return ran.returncode, ran.timed_out, ran.stdout, ran.stderr


@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_a_forked_script_ends_as_a_new_interpreter_ends(tmp_path, name):
    script = tmp_path / "engine.py"
    script.write_text(SCRIPTS[name])
    assert _run(forked.run_forked, script) == _run(run_engine, script)


def test_a_forked_script_is_killed_at_the_time_limit(tmp_path):
    script = tmp_path / "slow.py"
    script.write_text("import time\ntime.sleep(60)\n")
    code, timed_out, _, _ = _run(forked.run_forked, script, timeout=0.5)
    assert timed_out and code == -9


def test_other_commands_run_as_the_checker_runs_them():
    assert not forked.is_python_script(["/bin/echo", "x.py"])
    ran = forked.run_forked(["/bin/echo", "hello"], 10)
    assert ran.returncode == 0 and ran.stdout.strip() == b"hello"
