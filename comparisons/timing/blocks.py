"""The report blocks and headlines of the timing and scaling studies (built from their data)."""

from __future__ import annotations

from typing import List, Optional, Sequence

from common.blocks import Figure, Paragraph, Table
from common.result import Check
from comparisons.timing.records import MEMORY_NOTE, ScalingData, TimingData

__all__ = ["timing_blocks", "timing_headline", "scaling_blocks", "scaling_headline"]


def _ms(s: Optional[float]) -> str:
    return "-" if s is None else (f"{s * 1e3:.2f}" if s < 0.1 else f"{s * 1e3:.1f}")


def _verdict(c: Check) -> str:
    if c.passed is None:
        return "not measured"
    return "met" if c.passed else "MISSED"


def _checks_table(checks: Sequence[Check], kind: str, caption: str) -> Table:
    rows = [
        (
            c.name,
            "-" if c.measured is None else f"{c.measured:.3g}",
            f"{c.relation} {c.limit:g}",
            _verdict(c) if kind == "target" else ("pass" if c.passed else "FAIL"),
            c.note,
        )
        for c in checks
        if c.kind == kind
    ]
    return Table(("check", "measured", "required", "verdict", "why / note"), rows, caption=caption)


def timing_headline(data: TimingData) -> str:
    parts = []
    fk = [r for r in data.ratios if r.what == "force+stiffness"]
    for pair, label in (
        ("classical-numba/mjed-numba", "compiled classical/MJED"),
        ("classical/mjed", "NumPy classical/MJED"),
        ("mjed/mjed-numba", "MJED NumPy/compiled"),
        ("felupe/mjed", "FElupe/MJED"),
    ):
        vals = [r.median for r in fk if r.ratio == pair]
        if vals:
            parts.append(f"{label} {min(vals):.2f} to {max(vals):.2f}")
    return f"force+stiffness on {data.mesh.name} ({data.settings.protocol} protocol): " + "; ".join(
        parts
    )


def timing_blocks(data: TimingData, checks: Sequence[Check]) -> List:
    """The timing section of the report: figure, setting, times, ratios, floor, checks."""
    blocks: List = [
        Figure(
            p,
            "Force + stiffness per call, per material and method (log scale), in the style of the "
            "paper's Fig. 2; bars are medians, whiskers the range over the rounds",
        )
        for p in data.figures
    ]
    blocks.append(_setting_paragraph(data))
    blocks.append(_times_table(data))
    blocks.append(_ratios_table(data))
    blocks += _floor_blocks(data)
    blocks += _verification_blocks(data)
    blocks.append(
        _checks_table(
            checks, "target", "Speed targets (force+stiffness unless said), each met or missed"
        )
    )
    if any(c.kind == "tolerance" for c in checks):
        blocks.append(_checks_table(checks, "tolerance", "Results checked before timing"))
    return blocks


def _setting_paragraph(data: TimingData) -> Paragraph:
    mesh, s, load = data.mesh, data.settings, data.load_average or {}
    return Paragraph(
        f"Mesh {mesh.name}: {mesh.n_cells:,} cells, {mesh.n_nodes:,} nodes, {mesh.nnz:,} stiffness "
        f"entries; state: {s.state}. Protocol: {s.protocol_text}. Machine load average (1, 5, 15 "
        f"min) before {load.get('before')} and after {load.get('after')} on "
        f"{data.provenance.get('usable_cores')} usable core(s): the machine is shared, so times "
        "vary with the other work on it; ratios are formed within each round."
    )


def _times_table(data: TimingData) -> Table:
    s = data.settings
    rows = []
    for name in data.materials:
        for w in ("force+stiffness", "force", "stiffness"):
            row = [name, w]
            for m in s.methods:
                r = data.call(name, m, w)
                row.append(
                    "-" if r is None else f"{_ms(r.median_s)} ({r.repeats}x{r.calls_per_repeat})"
                )
            rows.append(row)
    return Table(
        ("material", "what", *[f"{s.labels[m]} ms" for m in s.methods]),
        rows,
        caption=f"Median time per call in ms ({s.protocol} protocol; in brackets rounds x calls "
        "per round); '-': not timed (see below)",
    )


def _ratios_table(data: TimingData) -> Table:
    rows = []
    for name in data.materials:
        opc = data.opcount[name]
        row = [name]
        for pair in (
            "classical-numba/mjed-numba",
            "classical/mjed",
            "mjed/mjed-numba",
            "dolfinx/mjed",
            "felupe/mjed",
        ):
            r = data.ratio(name, pair)
            row.append("-" if r is None else f"{r.median:.2f} [{r.min:.2f}, {r.max:.2f}]")
        r = data.ratio(name, "classical-numba/mjed-numba")
        row += [
            f"{opc['mjed_source']} ({opc['mjed']['total']})",
            f"{opc['classical']['total']}",
            f"{opc['predicted_ratio']:.2f}",
            "-" if r is None else f"{r.median / opc['predicted_ratio']:.2f}",
        ]
        f = data.ratio(name, "dolfinx/mjed", "force")
        row.append("-" if f is None else f"{f.median:.2f}")
        rows.append(row)
    return Table(
        (
            "material",
            "classical/MJED compiled",
            "classical/MJED NumPy",
            "MJED NumPy/compiled",
            "dolfinx/MJED",
            "FElupe/MJED",
            "MJED flops/cell (hand model)",
            "classical flops/cell",
            "model ratio",
            "measured/model",
            "dolfinx/MJED force only",
        ),
        rows,
        caption="Force+stiffness ratios, median [min, max] of per-round ratios (> 1: MJED faster), "
        "and the operation-count model of the two compiled kernels "
        "(comparisons/timing/opcount.py, both counted from their generated sources; MJED's "
        "count derived by hand from its terms in brackets): measured/model near 1 means the "
        "ratio is explained by the arithmetic",
    )


def _floor_blocks(data: TimingData) -> List:
    floor, bw, labels = data.floor, data.bandwidth, data.settings.labels
    rows = []
    for name in data.materials:
        for m in data.settings.methods:
            r = data.call(name, m)
            if r is not None:
                rows.append((name, labels[m], _ms(r.median_s), f"{r.median_s / floor.seconds:.1f}"))
    text = (
        f"Bandwidth floor: a {bw.kernel} copy of {bw.array_bytes / 2**20:.0f} MiB runs at "
        f"{bw.bytes_per_s / 1e9:.1f} GB/s (read + write); force+stiffness must move at least "
        f"{floor.bytes / 1e6:.2f} MB ({floor.what}), so no method can take less than "
        f"{floor.seconds * 1e3:.3f} ms on this mesh."
    )
    return [
        Paragraph(text),
        Table(
            ("material", "method", "force+stiffness ms", "x floor"),
            rows,
            caption="Each method's force+stiffness time against the bandwidth floor",
        ),
    ]


def _verification_blocks(data: TimingData) -> List:
    labels = data.settings.labels
    blocks: List = []
    if data.verification or data.skipped:
        rows = [
            (
                v.material,
                labels.get(v.method, v.method),
                _err(v.check.force_err),
                _err(v.check.stiffness_err),
                v.check.note,
            )
            for v in data.verification
        ]
        blocks.append(
            Table(
                ("material", "method", "force error", "stiffness error", "verdict"),
                rows,
                caption="Every method's result at the timing state against NumPy MJED before it is "
                "timed (tolerance 1e-10, the equivalence study's)",
            )
        )
    if data.skipped:
        blocks.append(
            Table(
                ("material", "method", "why not timed"),
                [(k.material, labels.get(k.method, k.method), k.reason) for k in data.skipped],
            )
        )
    if data.memory:
        rows = [
            (
                r.material,
                labels.get(r.method, r.method),
                f"{r.peak_bytes / 2**20:.0f}" if r.peak_bytes is not None else (r.error or "-"),
            )
            for r in data.memory
        ]
        blocks.append(Table(("material", "method", "peak MiB"), rows, caption=MEMORY_NOTE))
    return blocks


def _err(e: Optional[float]) -> str:
    return "-" if e is None else f"{e:.1e}"


def scaling_headline(data: ScalingData) -> str:
    parts = []
    for m in data.settings.methods:
        per = [1e6 * r.seconds_per_cell for r in data.rows if r.method == m]
        top = max((r.n_cells for r in data.rows if r.method == m), default=0)
        if per:
            parts.append(
                f"{data.settings.labels[m]} {min(per):.2f}-{max(per):.2f} us/cell up to {top:,}"
            )
    return "; ".join(parts) or "nothing measured"


def scaling_blocks(data: ScalingData, checks: Sequence[Check]) -> List:
    labels = data.settings.labels
    blocks: List = [
        Figure(p, "Time and peak memory per cell against mesh size (log axes)")
        for p in data.figures
    ]
    rows = [
        (
            labels[r.method],
            r.n_cells,
            r.n_nodes,
            f"{r.seconds:.4f}",
            f"{1e6 * r.seconds_per_cell:.2f}",
            f"{r.peak_bytes / 2**20:.0f}",
            f"{r.peak_bytes_per_cell:.0f}",
        )
        for r in data.rows
    ]
    blocks.append(
        Table(
            ("method", "cells", "nodes", "f+K (s)", "us per cell", "peak MiB", "bytes per cell"),
            rows,
            caption=f"{data.material} on {data.settings.mesh}; best of {data.settings.repeats} "
            "calls",
        )
    )
    blocks.append(
        Table(("method", "how far it went"), [(labels[m], why) for m, why in data.stopped.items()])
    )
    if checks:
        blocks.append(_checks_table(checks, "target", "Scaling targets"))
    return blocks
