"""Whether the CUDA backend can run here: Numba with its CUDA target, and a CUDA device or
Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1`` set before Numba is imported). Checked
without importing Numba at mjed's import.
"""

from __future__ import annotations

import os
from types import ModuleType

from mjed.compiled.availability import BackendUnavailable, numba_available

__all__ = ["cuda_available", "require_cuda", "simulated"]


def simulated() -> bool:
    """True when Numba's CUDA simulator is (or will be) used instead of a device."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


def cuda_available() -> bool:
    """True when the cuda backend can run: Numba is installed and a CUDA device (or the
    simulator) answers. Imports Numba.
    """
    if not numba_available():
        return False
    try:
        from numba import cuda

        return bool(cuda.is_available())
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
        from numba import cuda
    except ImportError as exc:
        raise BackendUnavailable(f"the 'cuda' backend could not import numba.cuda: {exc}") from exc
    if not cuda.is_available():
        raise BackendUnavailable(
            "the 'cuda' backend found no usable CUDA device (driver and GPU) on this machine; set "
            "NUMBA_ENABLE_CUDASIM=1 before Numba is imported to run its kernels on Numba's CUDA "
            "simulator (slow, for tests), or use backend='numpy' or 'numba'"
        )
    return cuda
