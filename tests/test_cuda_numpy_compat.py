"""mjed.cuda.availability.load_numba_cuda: numba-cuda's kernel typing on a NumPy without
``np.row_stack`` (NumPy 2.5), which failed every kernel on a real device.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[1]

# NumPy 2.5 is imitated by removing the name before numba.cuda is imported (after SciPy, which
# copies NumPy's names when it is imported).
PROBE = """
import importlib.util, sys
import numpy as np
from mjed.cuda.availability import load_numba_cuda
assert "numba.cuda" not in sys.modules
del np.row_stack
cuda = load_numba_cuda()
try:
    spec = importlib.util.find_spec("numba.cuda.np.arrayobj")
except ImportError:
    spec = None
print("row_stack after:", hasattr(np, "row_stack"))
print("typing loaded:", spec is None or "numba.cuda.np.arrayobj" in sys.modules)
print("numba-cuda:", spec is not None)
"""


def test_numba_cuda_types_kernels_on_a_numpy_without_row_stack():
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    env["PYTHONPATH"] = str(ROOT)
    ran = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=300
    )
    assert ran.returncode == 0, ran.stderr[-3000:]
    assert "row_stack after: False" in ran.stdout  # NumPy is left as it was
    assert "typing loaded: True" in ran.stdout
