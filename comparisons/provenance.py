"""Where a measurement was made: machine, software versions and source revision.

Every timing record carries this block, so that a number can be traced to the CPU, the
library versions and the commit that produced it.
"""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any, Dict, Optional

__all__ = ["cpu_model", "git_commit", "provenance"]

_REPO = Path(__file__).resolve().parent.parent


def cpu_model() -> str:
    """The CPU model name (from /proc/cpuinfo on Linux, else platform.processor())."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def git_commit(path: Path = _REPO) -> Dict[str, Any]:
    """{'commit': sha or None, 'dirty': bool or None} of the repository at ``path``."""
    def run(*args) -> Optional[str]:
        try:
            out = subprocess.run(["git", "-C", str(path), *args], capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip() if out.returncode == 0 else None

    sha = run("rev-parse", "HEAD")
    status = run("status", "--porcelain", "--untracked-files=no")
    return {"commit": sha, "dirty": None if status is None else bool(status)}


def _version(module: str) -> Optional[str]:
    try:
        mod = __import__(module)
    except Exception:  # not installed, or broken: say so rather than fail the study
        return None
    return getattr(mod, "__version__", "unknown")


def provenance(*, with_dolfinx: bool = True) -> Dict[str, Any]:
    """A JSON-serialisable record of the machine and the software stack."""
    import numpy as np
    import scipy

    out: Dict[str, Any] = {
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "cpu": cpu_model(),
        "logical_cores": os.cpu_count(),
        "usable_cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "machine": platform.machine(),
        "os": platform.platform(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "dolfinx": None,
        "petsc4py": None,
        "petsc": None,
        "threads_env": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")},
    }
    if os.path.exists("/proc/meminfo"):
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemTotal"):
                    out["memory_kib"] = int(line.split()[1])
                    break
    if with_dolfinx:
        try:  # through the compat layer: the PyPI wheel needs its MPI loaded first
            from reference_fem import compat

            out["dolfinx"] = compat.import_dolfinx().__version__
        except Exception:
            out["dolfinx"] = None
        out["petsc4py"] = _version("petsc4py")
        try:
            from petsc4py import PETSc

            out["petsc"] = ".".join(str(v) for v in PETSc.Sys.getVersion())
        except Exception:
            pass
    out.update({"git_" + k: v for k, v in git_commit().items()})
    return out
