"""Whether the compiled backend can run here, without importing Numba at mjed's import."""

from __future__ import annotations

import importlib.util
from types import ModuleType

__all__ = ["BackendUnavailable", "numba_available", "require_numba"]


class BackendUnavailable(ImportError):
    """The asked-for backend cannot run on this installation (the message says what to install)."""


def numba_available() -> bool:
    """True when Numba can be imported (checked without importing it)."""
    return importlib.util.find_spec("numba") is not None


def require_numba() -> ModuleType:
    """The kernels module, importing Numba; BackendUnavailable if Numba is missing or broken."""
    if not numba_available():
        raise BackendUnavailable(
            "the 'numba' backend needs Numba, which is not installed: on Debian 12 `apt-get "
            "install python3-numba`, elsewhere `pip install numba`; or use backend='numpy'"
        )
    try:
        from mjed.compiled import kernels
    except ImportError as exc:  # e.g. a Numba built for another NumPy
        raise BackendUnavailable(f"the 'numba' backend could not load Numba: {exc}") from exc
    return kernels
