"""Figures of the liver study: Fig. 1 (porous stress, pressure field) and Fig. 4 (amplitudes)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from comparisons.liver.oscillation_records import OscillationCurve, OscillationRow
from comparisons.liver.records import LiverRun, StepSplit

__all__ = [
    "plot_porous_stress",
    "plot_amplitudes",
    "plot_pressure",
    "boundary_faces",
    "plot_step_split",
    "plot_oscillations",
    "plot_decay",
]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str, *, tight: bool = True, **savefig) -> str:
    """Lay out (unless ``tight`` is False: a 3-D axes sets its own), write at 120 dpi, close
    the figure (so a long study does not keep every figure in memory) and return the path.
    """
    import matplotlib.pyplot as plt

    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=120, **savefig)
    plt.close(fig)
    return path


def boundary_faces(cells: np.ndarray) -> np.ndarray:
    """Triangles (k, 3) that belong to exactly one cell, oriented outwards."""
    from meshes.tetra import boundary_triangles

    return boundary_triangles(cells)


def plot_porous_stress(path: str, params) -> str:
    """Fig. 1 left: sigma(J) of the Hencky law and after substitution, for f_w = 0.8 (the
    paper's value) and for the liver's f_w, both tangent choices.
    """
    from mjed.porous import PorousVolume

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, f_w in zip(axes, (0.8, params.f_w)):
        J = np.linspace(1 - f_w + 1e-4, 1.5, 600)
        Jwide = np.linspace(max(0.0, 1 - f_w - 0.15), 1.5, 600)
        for tangent, style in (("paper", ":"), ("slope", "--")):
            law = PorousVolume(f_w, params.K0, params.K_lim, tangent=tangent)
            ax.plot(
                Jwide,
                law.stress(Jwide),
                style,
                lw=2,
                label=f"substituted, J0 = {law.J0:.3f} ({tangent}, slope {law.tangent_slope:.0f} "
                "Pa)",
            )
            ax.plot([law.J0], [law.stress(law.J0)], "o", color="k", ms=4)
        ax.plot(J, law.hencky_stress(J), "-", color="k", lw=1, label="Hencky K0 f_w ln J*")
        ax.axvline(1 - f_w, color="grey", lw=0.5)
        ax.set_ylim(-3 * params.K0, 1.2 * params.K0)
        ax.set_xlabel("J")
        ax.set_ylabel("volumetric Cauchy stress (Pa)")
        ax.set_title(f"f_w = {f_w}, K0 = {params.K0:g} Pa, K_lim = {params.K_lim:g} Pa")
        ax.legend(fontsize=7, loc="lower right")
        ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_amplitudes(path: str, runs: Sequence[LiverRun], label: str) -> str:
    """Fig. 4: the maximum nodal displacement over time, the models on one axes as in the paper."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    for r, marker in zip(runs, "osd^v"):
        rate = "failed" if r.error else f"{r.fps:.0f} FPS, paper {r.paper_fps:g}"
        split = f"; {r.steps_split} step(s) in substeps" if r.steps_split else ""
        (line,) = ax.plot(
            r.time,
            1e3 * np.asarray(r.max_displacement),
            f"-{marker}",
            ms=3,
            label=f"{r.model} (dt = {r.dt:g} s; {rate}{split})",
        )
        split_at = [k + 1 for k, n in enumerate(r.substeps) if n > 1]
        if split_at:  # steps the integrator had to take in substeps: ringed
            ax.plot(
                np.asarray(r.time)[split_at],
                1e3 * np.asarray(r.max_displacement)[split_at],
                "o",
                ms=8,
                mfc="none",
                color=line.get_color(),
            )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("max displacement amplitude (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"Liver under gravity ({label})", fontsize=10)
    return _save(fig, path)


def plot_pressure(path: str, mesh, x: np.ndarray, P: np.ndarray, fixed: np.ndarray) -> str:
    """Fig. 1 right: the deformed surface coloured by the fluid pressure (face mean)."""
    plt = _pyplot()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri = boundary_faces(mesh.cells)
    values = P[tri].mean(axis=1)
    lim = max(float(np.abs(values).max()), 1e-12)
    cmap = plt.get_cmap("coolwarm")
    fig = plt.figure(figsize=(7, 5))
    ax = fig.add_subplot(projection="3d")
    coll = Poly3DCollection(x[tri], facecolors=cmap(0.5 + 0.5 * values / lim), edgecolors="none")
    ax.add_collection3d(coll)
    ax.scatter(*x[fixed].T, s=2, c="k", label="fixed nodes")
    lo, hi = x.min(axis=0), x.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.view_init(elev=20, azim=-70)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(-lim, lim))
    fig.colorbar(sm, ax=ax, shrink=0.7, pad=0.12, label="fluid pressure (Pa)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("Fluid pressure under gravity (largest |P| reached)", fontsize=10)
    return _save(fig, path, tight=False)


def plot_step_split(path: str, split: Sequence[StepSplit], paper_share: float) -> str:
    """Where a step's time goes, per run (model and backend; stacked shares), beside the paper's
    hyperelastic share.
    """
    plt = _pyplot()
    phases = list(split[0].shares)
    fig, ax = plt.subplots(figsize=(8, 1.2 + 0.7 * len(split)))
    colours = plt.get_cmap("tab10").colors
    for row, r in enumerate(split):
        left = 0.0
        for k, phase in enumerate(phases):
            share = r.shares[phase]
            ax.barh(
                row,
                100 * share,
                left=100 * left,
                color=colours[k],
                label=phase if row == 0 else None,
            )
            if share >= 0.06:
                ax.text(
                    100 * (left + share / 2),
                    row,
                    f"{100 * share:.0f} %",
                    ha="center",
                    va="center",
                    fontsize=8,
                )
            left += share
    ax.axvline(100 * paper_share, color="k", ls="--", lw=1)
    ax.text(
        100 * paper_share,
        -0.55,
        f" paper: hyperelastic about {100 * paper_share:.0f} %",
        fontsize=8,
        va="bottom",
    )
    ax.set_yticks(range(len(split)))
    ax.set_yticklabels(
        [f"{r.model} ({r.backend})\n{r.ms_per_step:.1f} ms/step" for r in split],
        fontsize=8,
    )
    ax.set_xlim(0, 100)
    ax.set_ylim(len(split) - 0.5, -0.8)  # first model on top, room above it for the paper's mark
    ax.set_xlabel("share of the step's wall-clock time (%)")
    ax.legend(
        fontsize=7,
        ncol=3,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.35 if len(split) < 3 else -0.2 if len(split) == 3 else -0.11),
    )
    return _save(fig, path, bbox_inches="tight")


def plot_oscillations(path: str, curves: Sequence[OscillationCurve], label: str) -> str:
    """Fig. 4 as the paper describes it: max displacement over time, one panel per model,
    one curve per time step (little damping: the oscillations show, and fade faster with dt).
    """
    plt = _pyplot()
    models = list(dict.fromkeys(c.model for c in curves))
    fig, axes = plt.subplots(
        1, len(models), figsize=(4.2 * len(models), 3.6), sharey=True, squeeze=False
    )
    dts = sorted({c.dt for c in curves}, reverse=True)
    cmap = plt.get_cmap("viridis")
    for ax, model in zip(axes[0], models):
        for c in curves:
            if c.model != model:
                continue
            colour = cmap(dts.index(c.dt) / max(1, len(dts) - 1))
            tag = " (failed)" if c.error else ""
            ax.plot(
                c.time,
                1e3 * np.asarray(c.max_displacement),
                "-",
                color=colour,
                lw=1.2,
                marker="o" if c.dt >= 0.1 else None,
                ms=3,
                label=f"dt = {c.dt:g} s{tag}",
            )
        ax.set_title(model, fontsize=10)
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("max displacement (mm)")
    axes[0][-1].legend(fontsize=8, loc="lower right")
    fig.suptitle(f"Liver under gravity with little damping ({label})", fontsize=10)
    return _save(fig, path)


def plot_decay(path: str, rows: Sequence[OscillationRow]) -> str:
    """Measured decay rate of the oscillation against dt, with backward Euler's prediction."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    models = list(dict.fromkeys(r.model for r in rows))
    for model, marker in zip(models, "osd"):
        pts = [(r.dt, r.decay_rate) for r in rows if r.model == model and r.decay_rate is not None]
        if pts:
            ax.loglog(*zip(*pts), f"-{marker}", label=f"{model}: measured")
    theory = [
        (r.dt, r.euler_decay_rate) for r in rows if r.model == models[0] and r.euler_decay_rate
    ]
    if theory:
        ax.loglog(
            *zip(*theory),
            "k--",
            label="backward Euler on the measured frequency: ln(1 + (w dt)^2) / (2 dt)",
        )
    ax.set_xlabel("time step dt (s)")
    ax.set_ylabel("decay rate of the oscillation (1/s)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    return _save(fig, path)
