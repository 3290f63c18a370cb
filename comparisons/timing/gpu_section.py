"""The report's GPU section: the figures of the hardware benchmark's GPU section
(comparisons.timing.gpu) when a JSON of them is present, "not run: no GPU" otherwise.

The figures are measured on a machine with an NVIDIA GPU by

    python -m comparisons.timing.hardware --json docs/studies/gpu_figures.json

and read from that file (or from ``$MJED_GPU_FIGURES``); the report never measures them
itself and says so, naming the device and the date they were measured on. A file holding
no measurement (a run without a device, or Numba's CUDA simulator) is "not run: no GPU" too:
a target is only ever judged on a device's figures.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import List, Optional

from common.blocks import Paragraph, Table
from common.result import Check, StudyResult
from comparisons.timing.gpu import GpuFigures

__all__ = ["KEY", "TITLE", "COMMAND", "figures_path", "load_gpu_figures", "gpu_study"]

KEY = "gpu"
TITLE = "GPU speed: MJED and the classical element on the device"
# comparisons/timing/gpu_section.py -> the repository
DEFAULT_PATH = Path(__file__).resolve().parents[2] / "docs" / "studies" / "gpu_figures.json"
COMMAND = "python -m comparisons.timing.hardware --json docs/studies/gpu_figures.json"


def figures_path() -> Path:
    """Where the GPU figures are read from: ``$MJED_GPU_FIGURES``, else
    docs/studies/gpu_figures.json.
    """
    return Path(os.environ.get("MJED_GPU_FIGURES") or DEFAULT_PATH)


def _shown(path: Path) -> str:
    """``path`` relative to the repository when inside it (the report is read elsewhere)."""
    root = DEFAULT_PATH.parents[2]
    try:
        return str(Path(path).resolve().relative_to(root))
    except ValueError:
        return str(path)


def load_gpu_figures(path: Path) -> Optional[GpuFigures]:
    """The GPU section of a hardware_bench ``--json`` file (or a bare section), None if the
    file is absent.
    """
    if not path.is_file():
        return None
    data = json.loads(path.read_text())
    return GpuFigures.from_dict(data["gpu"] if "gpu" in data else data)


def gpu_study(path: Optional[Path] = None) -> StudyResult:
    """The GPU figures as a report section (see the module docstring)."""
    path = figures_path() if path is None else Path(path)
    fig = load_gpu_figures(path)
    if fig is None:
        why = f"no figures file at {_shown(path)}"
    elif fig.simulated:
        why = f"{_shown(path)} holds a run on Numba's CUDA simulator, not on a device"
    elif not fig.measured:
        why = f"{_shown(path)} records '{fig.status}'"
    else:
        return _measured(fig, path)
    reason = f"no GPU ({why}; measure them with `{COMMAND}` on a machine with an NVIDIA GPU)"
    return StudyResult.not_run(KEY, TITLE, reason, COMMAND)


def _checks(fig: GpuFigures) -> List[Check]:
    checks = [
        Check(
            f"{v.method} {v.dtype} on the GPU matches the NumPy element before timing, {v.cells:,} "
            "tets (force, stiffness)",
            max(v.force_err, v.stiffness_err),
            v.tol,
        )
        for v in fig.verification
    ]
    for t in fig.targets:
        checks.append(Check(t.name, t.measured, t.required, ">=", "target", t.note.strip()))
    return checks


def _measured(fig: GpuFigures, path: Path) -> StudyResult:
    rows = [
        [
            f"{size.cells:,}",
            t.method,
            t.dtype,
            t.quantity,
            f"{t.best_s * 1e3:.3f}",
            f"{t.tets_per_s:.3e}",
            f"{t.GBs:.1f}",
            f"{100 * t.copy_fraction:.1f}",
        ]
        for size in fig.sizes
        for t in size.timings
    ]
    skipped = [f"{size.cells:,} tets, {r}" for size in fig.sizes for r in size.skipped]
    blocks = [
        Paragraph(
            f"Measured on {fig.device} on {fig.date} ({fig.material}), read from "
            f"{_shown(path)}: not measured by this run. Device copy bandwidth "
            f"{fig.copy_GBs:.0f} GB/s (same run)."
        ),
        Table(
            ["tets", "method", "precision", "quantity", "ms", "tets/s", "GB/s", "% of copy"],
            rows,
            "Per call, positions, forces and CSR values on the device; best of the repeats.",
        ),
    ]
    if fig.cpu is not None:
        blocks.append(
            Paragraph(
                f"Compiled CPU backend, {fig.cpu.threads} threads, {fig.cpu.cells:,} tets: force "
                f"{fig.cpu.f_s * 1e3:.2f} ms, force + stiffness {fig.cpu.fK_s * 1e3:.2f} ms."
            )
        )
    if skipped:
        blocks.append(Paragraph("Skipped: " + "; ".join(skipped) + "."))
    best = max((t.tets_per_s for s in fig.sizes for t in s.timings), default=0.0)
    return StudyResult.from_checks(
        KEY,
        TITLE,
        _checks(fig),
        headline=f"{fig.device}, {fig.date}: up to {best:.2e} tets/s (figures from {path.name})",
        command=COMMAND,
        data=fig.to_dict(),
        blocks=tuple(blocks),
    )
