"""Figures of the liver study: Fig. 1 (porous stress, pressure field) and Fig. 4 (amplitudes)."""

from __future__ import annotations

from typing import Dict, Sequence

import numpy as np

__all__ = ["plot_porous_stress", "plot_amplitudes", "plot_pressure", "boundary_faces"]

_FACES = np.array([(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)])  # outward for positive cells


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def boundary_faces(cells: np.ndarray) -> np.ndarray:
    """Triangles (k, 3) that belong to exactly one cell, oriented outwards."""
    faces = cells[:, _FACES].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1]


def plot_porous_stress(path: str, params) -> str:
    """Fig. 1 left: sigma(J) of the Hencky law and after substitution, for f_w = 0.8 (the
    paper's value) and for the liver's f_w, both tangent choices."""
    from mjed.porous import PorousVolume

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, f_w in zip(axes, (0.8, params.f_w)):
        J = np.linspace(1 - f_w + 1e-4, 1.5, 600)
        Jwide = np.linspace(max(0.0, 1 - f_w - 0.15), 1.5, 600)
        for tangent, style in (("paper", ":"), ("slope", "--")):
            law = PorousVolume(f_w, params.K0, params.K_lim, tangent=tangent)
            ax.plot(Jwide, law.stress(Jwide), style, lw=2, label=f"substituted, J0 = {law.J0:.3f} ({tangent}, slope {law.tangent_slope:.0f} Pa)")
            ax.plot([law.J0], [law.stress(law.J0)], "o", color="k", ms=4)
        ax.plot(J, law.hencky_stress(J), "-", color="k", lw=1, label="Hencky K0 f_w ln J*")
        ax.axvline(1 - f_w, color="grey", lw=0.5)
        ax.set_ylim(-3 * params.K0, 1.2 * params.K0)
        ax.set_xlabel("J")
        ax.set_ylabel("volumetric Cauchy stress (Pa)")
        ax.set_title(f"f_w = {f_w}, K0 = {params.K0:g} Pa, K_lim = {params.K_lim:g} Pa")
        ax.legend(fontsize=7, loc="lower right")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_amplitudes(path: str, runs: Sequence[Dict], label: str) -> str:
    """Fig. 4: the maximum nodal displacement over time, the models on one axes as in the paper."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    for r, marker in zip(runs, "osd^v"):
        rate = "failed" if r["error"] else f"{r['fps']:.0f} FPS, paper {r['paper_fps']:g}"
        ax.plot(r["time"], 1e3 * np.asarray(r["max_displacement"]), f"-{marker}", ms=3,
                label=f"{r['model']} (dt = {r['dt']:g} s; {rate})")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("max displacement amplitude (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"Liver under gravity ({label})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


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
    ax.set_xlim(lo[0], hi[0]); ax.set_ylim(lo[1], hi[1]); ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.view_init(elev=20, azim=-70)
    ax.set_xlabel("x (m)"); ax.set_ylabel("y (m)"); ax.set_zlabel("z (m)")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(-lim, lim))
    fig.colorbar(sm, ax=ax, shrink=0.7, pad=0.12, label="fluid pressure (Pa)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("Fluid pressure under gravity (largest |P| reached)", fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
