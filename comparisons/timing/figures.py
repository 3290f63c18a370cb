"""Figures of the timing study: the Fig. 2-style bar chart and the scaling plot (PNG, Agg)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the figures read the studies' typed records
    from comparisons.timing.records import ScalingData, TimingData

__all__ = ["plot_fig2", "plot_scaling"]

_COLOURS = {
    "mjed": "#1f77b4",
    "mjed-numba": "#0b3d6b",
    "classical": "#ff7f0e",
    "classical-numba": "#a04a00",
    "dolfinx": "#2ca02c",
    "felupe": "#9467bd",
    "sfepy": "#8c564b",
}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plain_log_ticks(axis) -> None:
    """Ticks at 1, 2, 5 x 10^k labelled as plain numbers: a log axis spanning a decade or two
    would otherwise show a single labelled power of ten.
    """
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(ScalarFormatter())
    axis.set_minor_formatter(NullFormatter())


def plot_fig2(result: "TimingData", path: str) -> str:
    """Grouped bars per material: median force+stiffness time of each method (min-max as
    error bars; methods not timed for a material leave a gap), log scale so that a 5x gap
    and a 50x gap both read. Returns ``path``.
    """
    plt = _pyplot()
    methods = result.settings.methods
    labels = result.settings.labels
    mats = result.materials
    res = {(r.material, r.method): r for r in result.results if r.what == "force+stiffness"}
    fig, ax = plt.subplots(figsize=(max(7.0, 1.6 * len(mats) + 2), 4.4))
    width = 0.84 / max(1, len(methods))
    xs = np.arange(len(mats))
    for k, method in enumerate(methods):
        have = [i for i, m in enumerate(mats) if (m, method) in res]
        if not have:
            continue
        med = np.array([res[(mats[i], method)].median_s * 1e3 for i in have])
        lo = med - np.array([res[(mats[i], method)].min_s * 1e3 for i in have])
        hi = np.array([res[(mats[i], method)].max_s * 1e3 for i in have]) - med
        pos = xs[have] + (k - (len(methods) - 1) / 2) * width
        ax.bar(
            pos,
            med,
            width,
            label=labels.get(method, method),
            color=_COLOURS.get(method),
            yerr=[lo, hi],
            capsize=1.5,
        )
        for p, v, top in zip(pos, med, med + hi):
            ax.text(
                p,
                top * 1.05,
                f"{v:.0f}" if v >= 10 else f"{v:.1f}",
                ha="center",
                va="bottom",
                fontsize=5,
            )
    ax.set_yscale("log")
    _plain_log_ticks(ax.yaxis)
    ax.set_xticks(xs)
    ax.set_xticklabels([m.replace("VenantKirchhoff", "VK") for m in mats], rotation=20, ha="right")
    ax.set_ylabel("force + stiffness per call (ms, log)")
    mesh = result.mesh
    ax.set_title(
        f"Assembly time on {mesh.name} ({mesh.n_cells:,} tets, {mesh.n_nodes:,} nodes), "
        f"{result.settings.protocol} protocol",
        fontsize=10,
    )
    ax.legend(fontsize=7, ncol=2)
    ax.grid(axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def plot_scaling(result: "ScalingData", path: str) -> str:
    """Time per cell and peak memory per cell against the cell count, log-log."""
    plt = _pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    methods = list(dict.fromkeys(r.method for r in result.rows))
    for method in methods:
        rows = [r for r in result.rows if r.method == method]
        n = [r.n_cells for r in rows]
        label = result.settings.labels.get(method, method)
        a1.loglog(
            n,
            [r.seconds_per_cell * 1e6 for r in rows],
            "o-",
            label=label,
            color=_COLOURS.get(method),
        )
        a2.loglog(
            n,
            [r.peak_bytes_per_cell for r in rows],
            "o-",
            label=label,
            color=_COLOURS.get(method),
        )
    a1.set_xlabel("cells")
    a1.set_ylabel("force + stiffness time per cell (us)")
    a2.set_xlabel("cells")
    a2.set_ylabel("peak memory per cell (bytes)")
    _plain_log_ticks(a1.yaxis)
    for a in (a1, a2):
        a.grid(which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"Scaling, {result.material}, structured cube", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
