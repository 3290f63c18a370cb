"""Where a measurement was made: machine, software versions and source revision.

Every timing record carries this block, so that a number can be traced to the CPU, the
library versions and the commit that produced it. ``python -m comparisons.provenance`` prints
the record as JSON.
"""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any, Dict, Optional

from common.result import Status

__all__ = ["KEY", "TITLE", "cpu_model", "git_commit", "provenance", "provenance_study"]

KEY = "provenance"
TITLE = "Provenance"

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
            out = subprocess.run(
                ["git", "-C", str(path), *args], capture_output=True, text=True, timeout=10
            )
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
        "usable_cores": len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
        "machine": platform.machine(),
        "os": platform.platform(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "dolfinx": None,
        "petsc4py": None,
        "petsc": None,
        "threads_env": {
            k: os.environ.get(k)
            for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
        },
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


def provenance_study():
    """The record as a report section. It checks nothing, so it holds no check; a piece of the
    stack that is not installed is recorded as 'not available', which is a fact, not a gap.
    """
    import json

    from common.blocks import Paragraph, Table
    from common.result import StudyResult

    info = provenance()
    try:
        from reference_fem import compat

        info["oracle_stack"] = compat.stack_versions()
    except Exception as exc:  # dolfinx missing: say so, the rest of the record stands
        info["oracle_stack"] = f"unavailable: {type(exc).__name__}: {exc}"
    json.dumps(info)  # the record must serialise as it is
    commit = str(info.get("git_commit"))[:10] + (
        " (with uncommitted changes)" if info.get("git_dirty") else ""
    )
    return StudyResult(
        key=KEY,
        title=TITLE,
        status=Status.PASSED,
        command="python -m comparisons.provenance",
        headline=f"{info.get('cpu')}, {info.get('usable_cores')} usable cores; commit {commit}",
        data=info,
        blocks=(
            Paragraph(
                "The machine, the versions and the commit the numbers above were measured with."
            ),
            Table(("item", "value"), _flat_rows(info)),
        ),
    )


def _flat_rows(info: dict, prefix: str = "") -> list:
    """Nested records as (dotted key, readable value) rows; booleans as yes/no, not pass/FAIL."""
    rows = []
    for k, v in info.items():
        if isinstance(v, dict):
            rows += _flat_rows(v, f"{prefix}{k}.")
        elif isinstance(v, bool):
            rows.append((prefix + k, "yes" if v else "no"))
        else:
            rows.append(
                (prefix + k, "not available" if v is None else str(v).replace("\x00", "").strip())
            )
    return rows


if __name__ == "__main__":
    import json

    print(json.dumps(provenance_study().data, indent=1))
