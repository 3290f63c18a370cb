"""Terzaghi's 1-D consolidation: the Darcy pressure solver coupled to the solid, against the
series solution p(z, t) = sum_k (4 p0 / ((2k+1) pi)) sin((2k+1) pi z / 2h) exp(-((2k+1) pi / 2)^2
T_v).

A column of height h on lateral rollers with a fixed base, loaded at t = 0 by a pressure p0 on
its top, drained at the top (P = 0) and sealed elsewhere (zero flux). The solid is a
NeoHookean at small strain (p0 = 1e-4 of its constrained modulus M = lam + 2 mu), so it is
linear to about 1e-4. The model's fluid law (1/K_lim) dP/dt = kappa P_zz - dJ/dt / J has a
storage 1/K_lim, so (with dJ/J = d eps and eps = (P - p0)/M in 1-D):

    (1/K_lim + 1/M) dP/dt = kappa P_zz,     P(t = 0+) = B p0,   B = K_lim / (K_lim + M),

which is Terzaghi's problem with c_v = kappa / (1/K_lim + 1/M) and the initial pressure B p0:

    P(z, t) = (4 B p0 / pi) sum_k (-1)^(k-1)/(2k-1) cos((2k-1) pi z / (2h)) exp(-(2k-1)^2 pi^2 c_v t
    / (4 h^2)).

Each time step solves the solid at fixed P (Newton), then advances P from the cells' change
of J: the paper's semi-implicit scheme. ``coupling_iterations`` > 1 repeats the pair within
the step (fixed point), which makes the coupling implicit.
"""

from __future__ import annotations

from typing import Callable, Dict, List, Optional

import numpy as np
import scipy.sparse.linalg as spla

import mjed
from comparisons.liver.terzaghi_records import TerzaghiResult, TerzaghiTime
from mjed.darcy import DarcyParameters, FluidPressureForce, cell_jacobians
from mjed.materials import NeoHookean

__all__ = ["column_mesh", "terzaghi_pressure", "run_terzaghi"]


def column_mesh(h: float, n_layers: int, width: float = 0.1):
    """A width x width x h column, one hexahedron (6 tetrahedra) per layer.

    Returns points (4 (n_layers + 1), 3) and cells (6 n_layers, 4), positively oriented.
    """
    z = np.linspace(0.0, h, n_layers + 1)
    corners = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], dtype=float) * width
    points = np.array([(cx, cy, zz) for zz in z for cx, cy in corners])
    hexes = np.array(
        [
            [4 * k + i for i in range(4)] + [4 * (k + 1) + i for i in range(4)]
            for k in range(n_layers)
        ]
    )
    split = [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6)]
    cells = np.concatenate([hexes[:, list(t)] for t in split])
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    neg = np.einsum("mi,mi->m", e[:, 0], np.cross(e[:, 1], e[:, 2])) < 0
    cells[neg, 2], cells[neg, 3] = cells[neg, 3], cells[neg, 2].copy()
    return points, cells


def terzaghi_pressure(
    z: np.ndarray, t: float, h: float, c_v: float, p_init: float, n_terms: int = 400
) -> np.ndarray:
    """The series solution, z measured from the sealed base, (len(z),)."""
    k = np.arange(1, n_terms + 1)
    a = (2 * k - 1) * np.pi / (2 * h)
    coef = (4 * p_init / np.pi) * (-1.0) ** (k - 1) / (2 * k - 1) * np.exp(-(a**2) * c_v * t)
    return np.cos(np.outer(z, a)) @ coef


def run_terzaghi(
    *,
    n_layers: int = 20,
    dt: float = 0.002,
    times=(0.05, 0.1, 0.2, 0.5),
    coupling_iterations: int = 1,
    mu: float = 1000.0,
    lam: float = 2000.0,
    K_lim: float = 2000.0,
    c_v: float = 1.0,
    h: float = 1.0,
    figure: Optional[str] = None,
) -> TerzaghiResult:
    """Run the coupled column and compare P with the series at ``times`` (= T_v when c_v = h = 1).

    Args:
        figure: optional PNG path for the pressure profiles against the series.

    Returns the parameters and, per time, the relative L2 (nodal) error
    ||P - P_exact|| / ||P_exact|| along the column, and the figure (the PNG, if written).
    """
    M = lam + 2.0 * mu
    kappa = c_v * (1.0 / K_lim + 1.0 / M)  # c_v = kappa / storage, storage = 1/K_lim + 1/M
    p0 = 1e-4 * M
    B = K_lim / (K_lim + M)
    X, T = column_mesh(h, n_layers)
    mesh = mjed.TetMesh(X, T)
    solid = mjed.HyperelasticForceField(mesh, NeoHookean(mu=mu, lam=lam))
    top = np.flatnonzero(np.isclose(X[:, 2], h))
    fluid = FluidPressureForce(mesh, DarcyParameters(K_lim, kappa), drained_nodes=top)
    free, load = _column_loads(X, top, p0)
    results = _march(
        solid,
        fluid,
        mesh,
        load,
        free,
        dt,
        times,
        coupling_iterations,
        lambda z, t: terzaghi_pressure(z, t, h, c_v, B * p0),
        c_v / h**2,
    )
    figures = () if figure is None else (_plot(figure, results, h, c_v, B * p0),)
    return TerzaghiResult(
        figures=figures,
        n_layers=n_layers,
        dt=dt,
        coupling_iterations=coupling_iterations,
        B=B,
        c_v=c_v,
        K_lim=K_lim,
        constrained_modulus=M,
        # the profiles (z, P) were only for the figure
        times=tuple(TerzaghiTime(r["T_v"], r["relative_l2_error"]) for r in results),
    )


def _march(
    solid,
    fluid,
    mesh,
    load,
    free,
    dt: float,
    times,
    coupling_iterations: int,
    exact: Callable,
    tv_per_s: float,
) -> List[Dict]:
    """Step to max(times); at each of ``times`` compare P along one vertical edge with
    ``exact(z, t)``: one dict per time (T_v, relative L2 error, and the profile z, P).
    """
    X = mesh.points
    axis = np.flatnonzero(np.isclose(X[:, 0], 0) & np.isclose(X[:, 1], 0))
    check_steps = {int(round(t / dt)): t for t in times}
    results: List[Dict] = []
    x = X.copy()
    for step in range(1, int(round(max(times) / dt)) + 1):
        x = _coupled_step(solid, fluid, mesh, x, load, free, dt, coupling_iterations)
        if step in check_steps:
            t = check_steps[step]
            P_exact = exact(X[axis, 2], t)
            err = np.linalg.norm(fluid.P[axis] - P_exact) / np.linalg.norm(P_exact)
            results.append(
                {
                    "T_v": tv_per_s * t,
                    "relative_l2_error": float(err),
                    "z": X[axis, 2].tolist(),
                    "P": fluid.P[axis].tolist(),
                }
            )
    return results


def _column_loads(X: np.ndarray, top: np.ndarray, p0: float):
    """Free dofs (3n,) of the column on lateral rollers with a fixed base, and the nodal load
    (n, 3) of the pressure p0 spread evenly over the top face's nodes.
    """
    free = np.zeros((len(X), 3), dtype=bool)
    free[:, 2] = X[:, 2] > 0  # only z moves; the base does not move at all
    load = np.zeros((len(X), 3))
    load[top, 2] = -p0 * 0.1 * 0.1 / len(top)  # the 0.1 x 0.1 top face carries p0
    return free.ravel(), load


def _coupled_step(
    solid,
    fluid,
    mesh,
    x: np.ndarray,
    load: np.ndarray,
    free: np.ndarray,
    dt: float,
    coupling_iterations: int,
) -> np.ndarray:
    """One time step of the column; returns the new positions (n, 3).

    Newton on the solid at the step's start pressure (with ``coupling_iterations`` > 1, trial
    pressures in between), then the fluid step is accepted at the new positions.
    """
    P_start = fluid.P.copy()
    for it in range(coupling_iterations):
        for _newton in range(3):  # the solid is nearly linear: 3 Newton steps reach round-off
            f_s, K_s = solid.force_and_stiffness(x)
            f_p, K_p = fluid.force_and_stiffness(x)
            r = (f_s + f_p + load).ravel()
            K = (K_s + K_p).tocsr()[free][:, free]
            dx = np.zeros(x.size)
            dx[free] = spla.spsolve(K.tocsc(), r[free])
            x = x + dx.reshape(-1, 3)
        if it < coupling_iterations - 1:  # trial pressure for the next pass (implicit coupling)
            fluid.P = fluid.solver.step(P_start, fluid.J_accepted, cell_jacobians(mesh, x), dt)
    fluid.P = P_start
    fluid.accept_step(x, dt)
    return x


def _plot(path: str, results: List[Dict], h: float, c_v: float, p_init: float) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 4))
    zz = np.linspace(0.0, h, 200)
    for r in results:
        t = r["T_v"] * h**2 / c_v
        (line,) = ax.plot(terzaghi_pressure(zz, t, h, c_v, p_init) / p_init, zz / h, "-", lw=1)
        ax.plot(
            np.asarray(r["P"]) / p_init,
            np.asarray(r["z"]) / h,
            "o",
            ms=3,
            color=line.get_color(),
            label=f"T_v = {r['T_v']:g}: error {100 * r['relative_l2_error']:.2f} %",
        )
    ax.set_xlabel("P / P(t = 0+)")
    ax.set_ylabel("z / h (drained top at 1)")
    ax.set_title("Terzaghi: semi-implicit Darcy step (dots) vs series (lines)", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
