# %% [markdown]
# # The liver under gravity
#
# The paper's application (its Fig. 1 and Fig. 4): a liver hanging from its vena cava and
# suspensory ligament falls under gravity, with three models of increasing richness:
# Arruda-Boyce; plus a Prony series (visco-hyperelastic); plus a porous solid whose fluid
# pressure diffuses (visco-poro-hyperelastic). Each is integrated by implicit Euler with
# MJED's forces and stiffness. Here the quick version: the coarse liver (200 nodes, 598
# cells) and 6 steps of 0.3 s (the full study: `mjed-verify liver`).
#
# The run writes its figures and one ParaView time series per model into `liver_out/` in
# the working directory, and returns a `comparisons.liver.records.LiverData`: one `LiverRun` per
# model (times in s, displacements in m), read by attribute; `result.to_dict()` is the JSON
# form the report writes to `results.json`, and `LiverData.from_dict` reads it back.

# %%
import numpy as np

from comparisons.liver.study import run_liver

result = run_liver(quick=True, out="liver_out")
print(
    f"mesh {result.mesh}: {result.n_nodes} nodes, {result.n_cells} cells, "
    f"{result.n_fixed} fixed nodes"
)
print(f"{'model':26s} {'dt':>5s} {'steps':>5s} {'final max |u|':>14s} {'CG/step':>8s} {'FPS':>6s}")
for run in result.runs:
    print(
        f"{run.model:26s} {run.dt:5.2f} {run.steps:5d} "
        f"{1e3 * run.final_max_displacement:11.1f} mm {run.cg_iterations_mean:8.1f} "
        f"{run.fps:6.0f}"
    )
terzaghi = result.terzaghi_error
print(
    "Terzaghi consolidation check of the pressure solver: worst relative L2 error "
    f"{100 * terzaghi:.2f} %"
)

assert all(run.error is None and run.steps == run.steps_planned for run in result.runs)
assert result.passed and terzaghi <= 0.01
final = {run.model: run.final_max_displacement for run in result.runs}
assert final["visco-hyperelastic"] > final["hyperelastic"] > 0, (
    "the Prony series softens the hanging organ"
)

# %% [markdown]
# (The frame rates printed are those of this run on a shared machine; they are not asserted.
# The study page gives the full run's table.)
#
# ## The ParaView series
#
# Each model's series is a `.pvd` index listing one `.vtu` file per step, with the nodal
# `displacement` (m) and, for the porous model, the nodal fluid `pressure` (Pa), and the
# volume ratio `J` on the cells. To look at it in ParaView:
#
# 1. `paraview liver_out/liver_visco-poro-hyperelastic.pvd` (or *File > Open*, then *Apply*);
# 2. colour by `displacement` or `pressure`; the time controls step through the run;
# 3. *Filters > Warp By Vector* with `displacement` (scale 1) shows the deformed organ.
#
# The same files read back in Python with meshio:

# %%
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio

series = {}
for pvd in sorted(Path("liver_out").glob("liver_*.pvd")):
    steps = [
        (float(d.get("timestep")), pvd.parent / d.get("file"))
        for d in ET.parse(pvd).iter("DataSet")
    ]
    series[pvd.stem.removeprefix("liver_")] = steps
    print(f"{pvd}: {len(steps)} time steps, t = {steps[0][0]:g} ... {steps[-1][0]:g} s")

runs = {run.model: run for run in result.runs}
for model, steps in series.items():
    last = meshio.read(steps[-1][1])
    u = last.point_data["displacement"]
    assert len(steps) == runs[model].steps + 1, "one file per step plus the initial state"
    assert abs(np.linalg.norm(u, axis=1).max() - runs[model].final_max_displacement) < 1e-12
    assert np.linalg.norm(u, axis=1).min() == 0.0, "the fixed nodes do not move"

# %% [markdown]
# ## Displacement and fluid pressure in 3-D
#
# The last state of the visco-poro-hyperelastic run, on the organ's surface (faces that belong
# to one cell only), coloured by the displacement magnitude on the deformed shape; then the
# fluid pressure at the step where it peaks: negative (suction) where the hanging tissue
# dilates, zero at the drained nodes of the vena cava and ligament.

# %%
import matplotlib.pyplot as plt
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

poro = series["visco-poro-hyperelastic"]
frames = [meshio.read(path) for _, path in poro]
points = frames[0].points
cells = frames[0].cells_dict["tetra"]
faces = np.sort(
    np.concatenate(
        [cells[:, [0, 1, 2]], cells[:, [0, 1, 3]], cells[:, [0, 2, 3]], cells[:, [1, 2, 3]]]
    ),
    axis=1,
)
unique, counts = np.unique(faces, axis=0, return_counts=True)
surface = unique[counts == 1]
print(f"surface: {len(surface)} triangles")

peak = int(np.argmax([np.abs(f.point_data["pressure"]).max() for f in frames]))
P = frames[peak].point_data["pressure"]
u_last = frames[-1].point_data["displacement"]
fixed = np.linalg.norm(u_last, axis=1) == 0.0
print(f"pressure peaks at t = {poro[peak][0]:g} s: min {P.min():.1f} Pa, max {P.max():.1f} Pa")
assert np.abs(P[fixed]).max() == 0.0, "drained at the fixed nodes"
assert P.min() < 0.0, "suction: the hanging tissue dilates"


def draw(ax, xyz, values, label, cmap):
    tri = xyz[surface]
    face_values = values[surface].mean(axis=1)
    norm = plt.Normalize(face_values.min(), face_values.max())
    poly = Poly3DCollection(
        tri, facecolors=plt.get_cmap(cmap)(norm(face_values)), edgecolor="k", linewidths=0.1
    )
    ax.add_collection3d(poly)
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.view_init(elev=15, azim=-60)
    ax.set_xlabel("x (m)", fontsize=7)
    ax.set_ylabel("y (m)", fontsize=7)
    ax.set_zlabel("z (m)", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.scatter(*xyz[fixed].T, color="k", s=4)
    plt.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.6, label=label)


fig = plt.figure(figsize=(13, 5))
ax0 = fig.add_subplot(1, 2, 1, projection="3d")
draw(ax0, points + u_last, 1e3 * np.linalg.norm(u_last, axis=1), "|u| (mm)", "viridis")
ax0.set_title(
    f"visco-poro-hyperelastic, t = {poro[-1][0]:g} s: displacement (deformed shape)", fontsize=9
)
ax1 = fig.add_subplot(1, 2, 2, projection="3d")
draw(ax1, points + frames[peak].point_data["displacement"], P, "fluid pressure P (Pa)", "coolwarm")
ax1.set_title(
    f"fluid pressure at its peak, t = {poro[peak][0]:g} s (black: fixed, drained nodes)", fontsize=9
)
fig.tight_layout()

# %% [markdown]
# ## The amplitude over time (Fig. 4)
#
# The maximum displacement of each model over the run: viscosity lets the organ sag further,
# and in these quick runs (6 steps) the porous model is still following the visco one.

# %%
fig, ax = plt.subplots(figsize=(6.4, 3.6))
for run in result.runs:
    ax.plot(run.time, 1e3 * np.array(run.max_displacement), marker="o", ms=3, label=run.model)
ax.set_xlabel("time (s)")
ax.set_ylabel("max displacement (mm)")
ax.legend(fontsize=8)
fig.tight_layout()
