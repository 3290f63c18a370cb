"""Running CUDA code on Numba's CUDA simulator from the tests.

The simulator replaces numba.cuda only when NUMBA_ENABLE_CUDASIM=1 is set before Numba is
imported, and the test process has imported Numba long before: so each simulated run is a
subprocess, which prints its results as JSON on its last line of output.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def max_relative(a, b) -> float:
    """Max |a - b| / max |b| (max |a| where b is all zero): how far a device result is from the
    host's.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = np.abs(b).max()
    return float(np.abs(a - b).max() / scale) if scale > 0 else float(np.abs(a).max())


def run_on_simulator(args: Sequence[str], *, timeout: float = 1200) -> dict:
    """``python ARGS`` under the simulator, in the repository root with the project and tests/
    importable; returns the JSON object of its last line of output. Fails the test with the
    end of its stderr when it exits non-zero.
    """
    path = [str(ROOT), str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=os.pathsep.join(path))
    ran = subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, env=env, cwd=ROOT, timeout=timeout
    )
    assert ran.returncode == 0, ran.stderr[-4000:]
    return json.loads(ran.stdout.strip().splitlines()[-1])
