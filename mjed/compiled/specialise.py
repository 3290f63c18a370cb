"""Generated kernels: written once to a cache directory, imported, compiled once per machine.

:func:`kernel_module` returns the module of the kernel of a :class:`KernelShape`
(:func:`generated_module` any generated source, e.g. the classical kernel of one law). A
source (:mod:`mjed.compiled.codegen`) is named by a hash of itself and of the compiled
helpers it calls, so:

- two shapes never share a file, hence never share compiled code (Numba's on-disk cache is
  keyed by the source file); two materials of one shape share it, their numbers being
  arguments;
- a change to the generator or to the helpers gives new files, never a stale cache;
- the file is written only when missing (atomically, so a concurrent process never imports
  half a file) and is checked against the expected source before it is imported, so a
  damaged or altered file is rewritten rather than trusted;
- Numba's cache (``cache=True``) sits next to it, in ``__pycache__``, and a second process
  loads the compiled code instead of compiling again.

The directory is ``$MJED_KERNEL_CACHE`` if set, else ``$XDG_CACHE_HOME/mjed/kernels`` (by
default ``~/.cache/mjed/kernels``), else a per-user directory under the system's temporary
directory; it is created private to the user. Nothing is written inside the repository.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
import threading
from pathlib import Path
from types import ModuleType
from typing import Dict, Sequence

from mjed.compiled.codegen import PARALLEL, kernel_source
from mjed.compiled.shape import KernelShape

__all__ = ["kernel_module", "generated_module", "cache_directory"]

_MODULES: Dict[str, ModuleType] = {}
_LOCK = threading.Lock()
# The compiled helpers a generated kernel calls: their sources are part of its name, since
# Numba's cache of the kernel does not notice when a callee changes.
_HELPERS = ("kernels.py",)


def cache_directory() -> Path:
    """Where generated kernels (and their Numba caches) are kept; created if missing."""
    env = os.environ.get("MJED_KERNEL_CACHE")
    candidates = [Path(env)] if env else []
    xdg = os.environ.get("XDG_CACHE_HOME")
    candidates.append((Path(xdg) if xdg else Path.home() / ".cache") / "mjed" / "kernels")
    candidates.append(
        Path(tempfile.gettempdir())
        / f"mjed-kernels-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
    )
    for path in candidates:
        try:
            path.mkdir(mode=0o700, parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(path, os.W_OK):
            return path
    raise OSError(
        f"no writable directory for generated kernels (tried {', '.join(map(str, candidates))}); "
        "set MJED_KERNEL_CACHE"
    )


def _digest(paths: Sequence[Path]) -> str:
    h = hashlib.sha256()
    for path in paths:
        h.update(path.read_bytes())
    return h.hexdigest()


def generated_module(source: str, prefix: str, helpers: Sequence[Path] = ()) -> ModuleType:
    """The imported module of a generated ``source`` (written and imported once per process;
    its functions compile on first call, or load from Numba's cache).

    prefix: the file name's prefix; helpers: the source files of the compiled functions it
    calls besides mjed.compiled's own (their contents are part of the file's name).
    """
    here = Path(__file__).parent
    text = f"# helpers {_digest([here / name for name in _HELPERS] + list(helpers))}\n{source}"
    name = f"{prefix}_{hashlib.sha256(text.encode()).hexdigest()[:20]}"
    with _LOCK:
        module = _MODULES.get(name)
        if module is None:
            path = cache_directory() / f"{name}.py"
            if _write_if_changed(path, text) and sys.stderr.isatty():
                print(
                    f"mjed: compiling the Numba kernel {prefix} on its first call (first use "
                    f"on this machine, 10 s to 2 min; kept in {path.parent})",
                    file=sys.stderr,
                    flush=True,
                )
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module  # Numba's cache finds the function's module by name
            spec.loader.exec_module(module)
            _MODULES[name] = module
    return module


def kernel_module(shape: KernelShape, parallel: bool = False, batch: int = 0) -> ModuleType:
    """The module of the MJED kernel of ``shape`` (its function ``mjed_cells``): serial, or
    parallel over cells (:data:`mjed.compiled.codegen.PARALLEL`); with ``batch`` > 0, the
    cell-batched kernel of that many lanes (:mod:`mjed.compiled.batched`).
    """
    if batch:
        from mjed.compiled.batched import batched_source

        prefix = f"mjed_batch{batch}" + ("_parallel" if parallel else "")
        return generated_module(batched_source(shape, batch, parallel), prefix)
    if parallel:
        return generated_module(kernel_source(shape, PARALLEL), "mjed_parallel")
    return generated_module(kernel_source(shape), "mjed_kernel")


def _write_if_changed(path: Path, text: str) -> bool:
    """Write ``text`` to ``path`` unless it already holds exactly that (its modification time,
    which Numba's cache index checks, then stays the same). True if it was written (a kernel
    new to this cache: Numba compiles it on its first call).
    """
    try:
        if path.read_text() == text:
            return False
    except (OSError, UnicodeDecodeError):
        pass
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return True
