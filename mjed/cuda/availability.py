"""Whether the CUDA backend can run here: Numba with its CUDA target, and a CUDA device or
Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1`` set before Numba is imported). Checked
without importing Numba at mjed's import.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from types import ModuleType

from mjed.compiled.availability import BackendUnavailable, numba_available

__all__ = ["cuda_available", "load_numba_cuda", "require_cuda", "simulated"]


def simulated(environ=os.environ) -> bool:
    """True when Numba's CUDA simulator is (or will be) used instead of a device."""
    return environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


def load_numba_cuda() -> ModuleType:
    """``numba.cuda``, with its typing of NumPy functions loaded on a NumPy that lacks
    ``np.row_stack``.

    numba-cuda (0.30 and earlier) registers an overload of ``np.row_stack`` in
    ``numba.cuda.np.arrayobj``, which it imports when it first types a kernel; NumPy 2.5
    removed that function, so on NumPy 2.5 every kernel failed to compile with
    "module 'numpy' has no attribute 'row_stack'" (seen on an H200 with numba-cuda and NumPy
    2.5.2). That module is imported here once, with the old name present for that import only:
    NumPy is left as it was.
    """
    import numpy as np
    from numba import cuda

    if hasattr(np, "row_stack") or simulated():
        return cuda
    try:
        spec = importlib.util.find_spec("numba.cuda.np.arrayobj")
    except ImportError:  # Numba's own CUDA target (before numba-cuda): no such module
        spec = None
    if spec is not None:
        np.row_stack = np.vstack
        try:
            importlib.import_module("numba.cuda.np.arrayobj")
        finally:
            del np.row_stack
    return cuda


def cuda_available() -> bool:
    """True when the cuda backend can run: Numba is installed and a CUDA device (or the
    simulator) answers. Imports Numba.
    """
    if not numba_available():
        return False
    try:
        return bool(load_numba_cuda().is_available())
    except Exception:  # a broken driver or toolkit: not available
        return False


def require_cuda() -> ModuleType:
    """numba.cuda, or BackendUnavailable saying what is missing."""
    if not numba_available():
        raise BackendUnavailable(
            "the 'cuda' backend needs Numba with its CUDA target (Debian: python3-numba; PyPI: "
            "numba and numba-cuda) and an NVIDIA GPU; or use backend='numpy'"
        )
    try:
        cuda = load_numba_cuda()
    except ImportError as exc:
        raise BackendUnavailable(f"the 'cuda' backend could not import numba.cuda: {exc}") from exc
    if not cuda.is_available():
        raise BackendUnavailable(
            "the 'cuda' backend found no usable CUDA device (driver and GPU) on this machine; set "
            "NUMBA_ENABLE_CUDASIM=1 before Numba is imported to run its kernels on Numba's CUDA "
            "simulator (slow, for tests), or use backend='numpy' or 'numba'"
        )
    return cuda
