# %% [markdown]
# # Viscosity: Prony relaxation and the rheometer
#
# The paper's visco-hyperelastic model (its section 3.1) relaxes the hyperelastic second
# Piola-Kirchhoff stress $S_h$ by a Prony series,
#
# $$\frac{G(t)}{G_0} = \alpha_\infty + \sum_i \alpha_i\, e^{-t/\tau_i}, \qquad \alpha_\infty = 1 -
# \sum_i \alpha_i,$$
#
# integrated by backward Euler: $S_v = S_h - \sum_i \gamma_i$ with the history
# $\gamma_i^n = a_i S_h^n + b_i \gamma_i^{n-1}$, $a_i = \Delta t\,\alpha_i/(\Delta t + \tau_i)$,
# $b_i = \tau_i/(\Delta t + \tau_i)$. We check it on one element held at a fixed stretch, then
# run the simulated rheometer of the paper's Fig. 3 (quick version).

# %%
import numpy as np

import mjed
from mjed.materials import StVenantKirchhoff
from mjed.viscous import Prony, ViscoHyperelasticForceField, prony_coefficients

G0, nu = 770.0, 0.45
material = StVenantKirchhoff(mu=G0, lam=2 * G0 * nu / (1 - 2 * nu))
prony = Prony(alphas=(0.235, 0.333), taus=(0.27, 0.03))
print(f"lambda = {material.lam:.0f} Pa, alpha_inf = {prony.alpha_inf:.3f}")

# %% [markdown]
# ## One element, a step stretch held
#
# At $t = 0^+$ the element is stretched by 10 % along $x$ and held. With a constant $S_h$ the
# recursion has the closed form
# $S_v^n / S_h = 1 - \sum_i \alpha_i\,(1 - b_i^n)$ (the stress of step $n$ uses the history of
# step $n-1$), and since the nodal forces are linear in $S$, the force relaxes by the same
# factor. As $\Delta t \to 0$ this tends to the continuous $G(t)/G_0$, at first order.

# %%
X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) * 1e-2
mesh = mjed.TetMesh(X, np.array([[0, 1, 2, 3]]))
x = X * np.array([1.1, 1.0, 1.0])
f_h = mjed.HyperelasticForceField(mesh, material).force(x)


def relaxation(dt, t_end=0.6):
    visco = ViscoHyperelasticForceField(mesh, material, prony=prony, dt=dt)
    ratios = []
    for _ in range(int(round(t_end / dt))):
        f_v = visco.force(x)
        ratios.append(np.vdot(f_v, f_h) / np.vdot(f_h, f_h))  # the force is kappa f_h
        assert np.abs(f_v - ratios[-1] * f_h).max() < 1e-12 * np.abs(f_h).max(), (
            "S_v must stay parallel to S_h"
        )
        visco.accept_step(x)
    return np.array(ratios)


dt = 0.005
simulated = relaxation(dt)
n = np.arange(1, len(simulated) + 1)
_, b = prony_coefficients(prony, dt)
discrete = 1.0 - sum(a_i * (1.0 - b_i**n) for a_i, b_i in zip(prony.alphas, b))
t = (n - 1) * dt  # step n sees the history accumulated up to t = (n - 1) dt
continuous = prony.relaxation(t)
err_discrete = np.abs(simulated - discrete).max()
print(f"max |simulated - discrete closed form| = {err_discrete:.1e}")
assert err_discrete < 1e-13

errs = {}
for step in (0.01, 0.005, 0.0025):
    r = relaxation(step)
    tt = np.arange(len(r)) * step
    errs[step] = np.abs(r - prony.relaxation(tt)).max()
    print(f"dt = {step:.4f} s: max |simulated - continuous G(t)/G0| = {errs[step]:.2e}")
order = np.log2(errs[0.005] / errs[0.0025])
print(f"observed order of convergence to the continuous relaxation: {order:.2f}")
assert 0.8 < order < 1.2, "backward Euler is first order"
assert np.all(np.diff(simulated) < 0) and simulated[-1] > prony.alpha_inf, (
    "relaxes monotonically towards alpha_inf"
)

# %%
import matplotlib.pyplot as plt

fig, ax = plt.subplots(figsize=(6.4, 3.6))
fine = np.linspace(0, t.max(), 400)
ax.plot(fine, prony.relaxation(fine), "k-", lw=1, label="continuous G(t)/G0")
ax.plot(t, discrete, "C1-", lw=2, alpha=0.5, label=f"backward Euler closed form, dt = {dt} s")
ax.plot(t[::4], simulated[::4], "C0o", ms=3, label="one element, ViscoHyperelasticForceField")
ax.axhline(prony.alpha_inf, color="0.6", ls=":", lw=1, label="alpha_inf")
ax.set_xlabel("time after the step (s)")
ax.set_ylabel("force / hyperelastic force")
ax.legend(fontsize=8)
fig.tight_layout()

# %% [markdown]
# ## The rheometer (Fig. 3)
#
# A cylinder of the rheometer's size, lower face clamped, upper face rotated by
# $\theta_0 \sin \omega t$; the torque on the upper plate, fitted over whole periods and divided by
# the elastic torque of the same mesh, gives $G^*(\omega)/G_0 = (G' + i G'')/G_0$.
# `run_rheometer(quick=True)` uses 5 frequencies, a coarse cylinder and 32 steps per
# period (the full study: `mjed-verify dma`). Two references: the continuous generalised
# Maxwell moduli $1 - \sum_i \alpha_i/(1 + i\omega\tau_i)$, which backward Euler only
# approaches as $\omega\Delta t \to 0$, and the exact steady state of the discrete recursion,
# $1 - \sum_i \alpha_i h_i/(1 + h_i - e^{-i\omega\Delta t})$ with $h_i = \Delta t/\tau_i$, which the
# simulation must match up to the geometric nonlinearity of the small rotation and round-off.
# It returns a typed `RheometerResult` (`comparisons.rheometer.records`): the spec, the mesh's
# counts, one `FrequencyRow` per frequency (moduli in Pa) and the error summaries; its
# `to_dict()` is the JSON that `mjed-verify dma --json` holds under `data`.

# %%
from comparisons.rheometer.study import run_rheometer

result = run_rheometer(quick=True)
print(f"cylinder: {result.mesh.n_cells} cells; {len(result.frequencies)} frequencies")
print(
    f"{'omega':>8} {'G_sim':>8} {'G_disc':>8} {'G_cont':>8} | {'G_sim':>8} {'G_disc':>8} "
    f"{'G_cont':>8}"
)
for r in result.frequencies:
    print(
        f"{r.omega:8.3g} {r.G_storage:8.2f} {r.discrete[0]:8.2f} "
        f"{r.continuous[0]:8.2f} | {r.G_loss:8.2f} {r.discrete[1]:8.2f} "
        f"{r.continuous[1]:8.2f}"
    )
e_d, e_c = result.errors.discrete, result.errors.continuous
print(f"relative error against the discrete response: mean {e_d.mean:.1e}, max {e_d.max:.1e}")
print(
    f"relative error against the continuous moduli: mean {100 * e_c.mean:.1f} %, max "
    f"{100 * e_c.max:.1f} %"
)
assert e_d.max < 1e-7, "the simulation must reproduce the discrete recursion"
assert e_c.max < 0.1, (
    "backward Euler at 32 steps per period stays within 10 % of the continuous moduli"
)

# %%
w = np.array([r.omega for r in result.frequencies])
fine = np.geomspace(w.min() / 1.5, w.max() * 1.5, 300)
G = G0 * prony.complex_modulus(fine)
fig, ax = plt.subplots(figsize=(6.4, 4))
ax.semilogx(fine, G.real, "C0-", lw=1, label="G' generalised Maxwell")
ax.semilogx(fine, G.imag, "C1-", lw=1, label="G'' generalised Maxwell")
ax.semilogx(
    w,
    [r.discrete[0] for r in result.frequencies],
    "k+",
    ms=10,
    label="discrete recursion (exact)",
)
ax.semilogx(w, [r.discrete[1] for r in result.frequencies], "k+", ms=10)
ax.semilogx(w, [r.G_storage for r in result.frequencies], "C0o", mfc="none", label="G' simulated")
ax.semilogx(w, [r.G_loss for r in result.frequencies], "C1s", mfc="none", label="G'' simulated")
ax.set_xlabel("angular frequency (rad/s)")
ax.set_ylabel("modulus (Pa)")
ax.legend(fontsize=8)
fig.tight_layout()
