# %% [markdown]
# # Why MJED is faster
#
# Both methods compute the same force and the same tangent stiffness (the tutorial
# *One tetrahedron by hand* shows they agree to round-off). They differ in how the work is
# arranged:
#
# - the **classical** FEM evaluates the material law as a whole into a $6\times 6$
#   elasticity tensor $\mathbb{C}$, then forms $K_e = V_0 (B^T \mathbb{C} B + \text{geometric})$:
#   the products with the $6\times 12$ matrix $B$ cost the same for every material;
# - **MJED** never forms $\mathbb{C}$: each declared term contributes scalars and, per
#   tangent pair, one outer product of two node vectors per edge, and only the six edge
#   blocks are computed (the diagonal blocks come from translation invariance).
#
# Below, an operation-count model derived from each material's declared terms (walking
# `material.decomposition()`), then measured times of the two methods on the same mesh.

# %%
import time
from dataclasses import dataclass, field
from functools import singledispatch

import numpy as np

import mjed
from common.cases import DEFAULT_MATERIALS
from meshes.structured import structured_box
from mjed.fibre import FibreQuadratic
from mjed.spectral import EigenPowerSum
from mjed.terms import (
    GreenLagrangeQuadratic,
    I1Power,
    JLogJ,
    JPower,
    LinearI2,
    LogPolynomial,
    Unity,
)
from reference_fem.classical import ClassicalGalerkin

# %% [markdown]
# ## The counting model
#
# One *flop* is one multiplication or one addition of two doubles; a special function
# (`log`, `pow`, `exp`) is counted apart, and so is a $3\times 3$ symmetric eigensolve
# (Ogden), which both methods pay. The sparse assembly (scattering the element numbers into
# the CSR matrix) is shared code and left out. Per element, with 4 nodes and 6 edges:
#
# | work | flops | who pays |
# |---|---|---|
# | $F = \sum_a x_a \otimes D_a$ | 63 | both |
# | $C = F^T F$ | 45 | both (MJED: when some $g$ depends on $C$) |
# | $\operatorname{cof} F$, $J$ | 32 | both (MJED: when some $f$ is not constant) |
# | a term's $f, f', f''$ | `JPower` 5 + pow, `LogPolynomial` 11 + log, `JLogJ` 7 + log, constant 0
# | both |
# | a term's $g$, $S_g$, pair coefficients | by kind, table in `g_cost` below | both |
# | folding a term into the group sums $u, h, g_2, \bar S, \hat S$ and the pair weights | 2 per
# scalar, 18 per stress, 2 per pair | MJED |
# | force $F \bar S D_a + h\, d_a$, times $V_0$ | 105 + 84 + 12 | MJED |
# | geometric $(D_a \cdot \bar S D_b)\,I$ | 96 | MJED |
# | one tangent pair slot: $G_a = F M D_a$, weights, one outer product per edge | 60 + 12 + 6 x 18 |
# MJED |
# | second kind: also $F M F^T$ and $(D_a\cdot M D_b)\,F M F^T$ per edge | 45 + 6 + 6 x 18 | MJED |
# | spectral slot (Ogden): eigenvector products, three outer products per edge | 753 + 3 x 6 x 18 |
# MJED |
# | $J$ couplings: $\hat S$ terms (two outer products) or $g_2$ alone (one) | 105 + 24 + 2 x 108, or
# 12 + 108 | MJED |
# | $h\,\partial^2 J$ (skew, from precomputed $D_a \times D_b$) | 144 | MJED |
# | exponential group: $e^u$, its gradient and rank-one outer product | 3 + exp + 189 + 12 + 108 |
# MJED |
# | summing the 54 block numbers, times $V_0$ | 54 + 18 | MJED |
# | $S$ and $\mathbb{C}$ of the law, per term (36 entries, as the classical code forms them) | see
# `classical_term` below | classical |
# | $B$ ($6\times 12$), $\mathbb{C} B$, $B^T(\mathbb{C}B)$ | 180 + 792 + 1584 | classical |
# | geometric $D S D^T$ into the diagonal of each $3\times 3$ block, times $V_0$ | 140 + 48 + 144 |
# classical |
# | force $-V_0 F S D_a$ | 117 | classical |
#
# The model is a count of the arithmetic the two codes write, not of what a CPU executes
# (NumPy's temporaries, memory traffic and vectorisation are not in it), so it predicts
# ratios of work, not times.


# %%
@dataclass
class Count:
    flops: int = 0
    special: int = 0
    eig: int = 0
    parts: dict = field(default_factory=dict)

    def add(self, what: str, flops: int = 0, special: int = 0, eig: int = 0) -> None:
        self.flops += flops
        self.special += special
        self.eig += eig
        self.parts[what] = self.parts.get(what, 0) + flops


@singledispatch
def f_cost(f) -> tuple:
    """(flops, special functions) of f, f', f'' for one function of J."""
    raise TypeError(f"no cost declared for {type(f).__name__}")


@f_cost.register
def _(f: JPower):
    return (0, 0) if f.p == 0 else (5, 1)


@f_cost.register
def _(f: LogPolynomial):
    return (11, 1)


@f_cost.register
def _(f: JLogJ):
    return (7, 1)


@singledispatch
def g_cost(g) -> tuple:
    """(flops, special, eigensolves) of g's value, stress S_g and pair coefficients."""
    raise TypeError(f"no cost declared for {type(g).__name__}")


@g_cost.register
def _(g: Unity):
    return (0, 0, 0)


@g_cost.register
def _(g: I1Power):
    return (2 + g.n + 4 + (g.n + 2 if g.n >= 2 else 0), 0, 0)  # I1, c I1^n, 2 c n I1^(n-1) Id, beta


@g_cost.register
def _(g: LinearI2):
    return (2 + 20 + 1 + 18 + 2, 0, 0)  # I1, I2, c I2, 2c (I1 Id - C), +-2c


@g_cost.register
def _(g: GreenLagrangeQuadratic):
    return (12 + 23 + 24, 0, 0)  # E, g, S


@g_cost.register
def _(g: FibreQuadratic):
    return (
        12 + 90 + 26 + 90 + 9 + 90 + 9,
        0,
        0,
    )  # E, R^T E R, g, (again) R^T E R, B o Ef, R (.) R^T, 2x


@g_cost.register
def _(g: EigenPowerSum):
    return (5 + 60 + 50, 6, 1)  # sum of lambda^q, V diag V^T, divided differences; 3 + 3 pow


def uses_C(g) -> bool:
    return not isinstance(g, Unity)


def mjed_count(material) -> Count:
    """Operations per element of MJED's force and edge-block stiffness, from the declared terms."""
    c = Count()
    groups = material.decomposition()
    terms = [t for grp in groups for t in grp.terms]
    c.add("kinematics", 63)
    if any(uses_C(t.g) for t in terms):
        c.add("kinematics", 45)
    varying_f = [t for t in terms if not (isinstance(t.f, JPower) and t.f.p == 0)]
    if varying_f:
        c.add("kinematics", 32)
    slots, has = set(), dict(S=False, S_hat=False, h=False, g2=False)
    for t in terms:
        fl, sp = f_cost(t.f)
        c.add("terms: f, g, S", fl, sp)
        gl, gs, ge = g_cost(t.g)
        c.add("terms: f, g, S", gl, gs, min(ge, 1 - c.eig))  # one eigensolve per cell at most
        const_f = isinstance(t.f, JPower) and t.f.p == 0
        has_S = not isinstance(t.g, Unity)
        c.add(
            "folding",
            2
            + (0 if const_f else 4)
            + (18 if has_S else 0)
            + (18 if has_S and not const_f else 0)
            + 2 * len(t.g.tangent),
        )
        has["S"] |= has_S
        has["S_hat"] |= has_S and not const_f
        has["h"] |= not const_f
        has["g2"] |= not const_f
        for pair in t.g.tangent:
            slots.add((pair.kind, id(pair.matrix) if pair.kind != "spectral" else None))
    for grp in groups:
        if grp.exponential:
            c.add("exponential", 3 + 189 + 12 + 108, 1)
    c.add("force", (105 if has["S"] else 0) + (84 if has["h"] else 0) + 12)
    if has["S"]:
        c.add("edge blocks: geometric", 96)
    for kind, _ in slots:
        if kind == "spectral":
            c.add("edge blocks: tangent pairs", 753 + 3 * 108)
        else:
            c.add(
                "edge blocks: tangent pairs",
                60 + 12 + 108 + ((45 + 6 + 108) if kind == "second" else 0),
            )
    if has["S_hat"]:
        c.add("edge blocks: J couplings", 105 + 24 + 216)
    elif has["g2"]:
        c.add("edge blocks: J couplings", 12 + 108)
    if has["h"]:
        c.add("edge blocks: J couplings", 144)
    c.add("edge blocks: sum", 54 + 18)
    return c


def classical_term(t) -> int:
    """Flops of one term's contribution to the classical S and 6x6 tensor (36 entries)."""
    const_f = isinstance(t.f, JPower) and t.f.p == 0
    n = 0
    if not const_f:
        n += 36 * 3 + 36 * 4  # f'' g J^2 C^-1 (x) C^-1 and f' g J (C^-1 (x) C^-1 - 2 C^-1 o C^-1)
        n += 9 * 3  # f' g J C^-1 in S
        if uses_C(t.g):
            n += 36 * 4  # f' J (C^-1 (x) S_g + S_g (x) C^-1)
    if uses_C(t.g):
        n += 18  # f S_g into S
    for pair in t.g.tangent:
        n += {"first": 36 * 3, "second": 36 * 5, "spectral": 9 * 36 * 4}[pair.kind]
    return n


def classical_count(material) -> Count:
    c = Count()
    groups = material.decomposition()
    terms = [t for grp in groups for t in grp.terms]
    c.add("kinematics", 63 + 45 + 32 + 40)  # F, C, cof and J, C^-1
    for t in terms:
        fl, sp = f_cost(t.f)
        gl, gs, ge = g_cost(t.g)
        c.add("law: S and 6x6 tensor", fl + gl + classical_term(t), sp + gs, min(ge, 1 - c.eig))
    for grp in groups:
        if grp.exponential:  # e^u (dS dS^T + its own tensor): a rank-one 6x6 update
            c.add("law: S and 6x6 tensor", 3 + 36 * 2 + 18, 1)
    c.add("B, CB, B^T CB", 180 + 792 + 1584)
    c.add("geometric + V0", 140 + 48 + 144)
    c.add("force", 117)
    return c


rows = []
for name, material in DEFAULT_MATERIALS.items():
    m, k = mjed_count(material), classical_count(material)
    rows.append((name, m, k))
    print(
        f"{name:18s} MJED {m.flops:5d} flops + {m.special} special + {m.eig} eig | classical "
        f"{k.flops:5d} flops + {k.special} special + {k.eig} eig | ratio {k.flops / m.flops:4.2f}"
    )

assert all(m.flops > 0 and k.flops > 0 for _, m, k in rows)
assert all(k.flops > m.flops for _, m, k in rows), (
    "the model must find MJED cheaper for every material"
)
fixed = 180 + 792 + 1584
cheap = [name for name, m, k in rows if m.flops < fixed]
print("materials whose whole MJED count is below the classical B-products alone:", ", ".join(cheap))
assert {"StVenantKirchhoff", "NeoHookean"} <= set(cheap)
# The special functions and eigensolves are the same on both sides: they come from f and g.
assert all(m.special == k.special and m.eig == k.eig for _, m, k in rows)

# %% [markdown]
# ## Measured times
#
# A structured cube of 6 x 12^3 = 10,368 tetrahedra, the seeded smooth random state of the
# equivalence study, `force_and_stiffness` of each method (forces and the assembled CSR
# matrix: the assembly both pay is included here, unlike in the counts). Median of 9 calls
# after one warm-up; a short run on a shared machine, so expect a spread of tens of percent.
# The full protocol is the timing study (`mjed-verify timing`).

# %%
from common.states import smooth_random

X, cells = structured_box(12)
mesh = mjed.TetMesh(X, cells)
x = smooth_random(X, cells, seed=1)


def median_time(fn, calls=9):
    fn()
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


measured = {}
for name, material in DEFAULT_MATERIALS.items():
    field_ = mjed.HyperelasticForceField(mesh, material)
    classical = ClassicalGalerkin(mesh, None, material)
    f_m, K_m = field_.force_and_stiffness(x)
    f_c, K_c = classical.force_and_stiffness(x)
    # Same numbers first: timing two methods only makes sense if they compute the same thing.
    assert np.abs(f_m - f_c).max() <= 1e-10 * np.abs(f_c).max(), name
    assert abs(K_m - K_c).max() <= 1e-10 * abs(K_c).max(), name
    measured[name] = (
        median_time(lambda: field_.force_and_stiffness(x)),
        median_time(lambda: classical.force_and_stiffness(x)),
    )
    t_m, t_c = measured[name]
    print(
        f"{name:18s} MJED {1e3 * t_m:6.1f} ms  classical {1e3 * t_c:6.1f} ms  measured ratio "
        f"{t_c / t_m:4.2f}"
    )
assert all(t > 0 for pair in measured.values() for t in pair)

# %% [markdown]
# ## Counts against times
#
# Left: each method's count per element, split by where the work goes. Right: the measured
# speed-up against the one the counts predict. Both say the same thing in broad strokes:
# the classical method's fixed $B$ products dominate its work for every material, so the
# cheap isotropic MJED materials gain the most, while Costa (three second-kind pairs and an
# exponential group) and Ogden (a spectral pair; the eigensolve is paid on both sides) gain
# least. Points off the diagonal show what the model leaves out: the sparse assembly both
# methods pay (it dilutes every measured ratio), the memory traffic of NumPy temporaries, and
# how well each kind of operation vectorises (the classical $B^T \mathbb{C} B$ runs as a
# batched matrix product, MJED's outer products as long contiguous rows). The timing study
# separates element work from assembly on the paper's cube.

# %%
import matplotlib.pyplot as plt

names = [r[0] for r in rows]
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(14, 4.8), gridspec_kw={"width_ratios": [1.5, 1]})
ypos = np.arange(len(names))
for offset, idx, label, cmap in (
    (-0.2, 1, "MJED", plt.cm.Blues),
    (0.2, 2, "classical", plt.cm.Oranges),
):
    left = np.zeros(len(names))
    parts = sorted({p for r in rows for p in r[idx].parts})
    for i, p in enumerate(parts):
        vals = np.array([r[idx].parts.get(p, 0) for r in rows])
        if vals.any():
            ax0.barh(
                ypos + offset,
                vals,
                left=left,
                height=0.38,
                label=f"{label}: {p}",
                color=cmap(0.35 + 0.6 * i / max(1, len(parts) - 1)),
                edgecolor="white",
                linewidth=0.3,
            )
            left += vals
ax0.set_yticks(ypos)
ax0.set_yticklabels(names)
ax0.set_xlabel("flops per element (model)")
ax0.legend(fontsize=6, ncol=1, loc="upper left", bbox_to_anchor=(1.01, 1.0))
predicted = np.array([k.flops / m.flops for _, m, k in rows])
observed = np.array([measured[n][1] / measured[n][0] for n in names])
ax1.scatter(predicted, observed)
for n, p, o in zip(names, predicted, observed):
    ax1.annotate(n, (p, o), fontsize=7, xytext=(3, 3), textcoords="offset points")
lim = [0, max(predicted.max(), observed.max()) * 1.15]
ax1.plot(lim, lim, "k:", lw=1, label="measured = predicted")
ax1.set_xlim(lim)
ax1.set_ylim(lim)
ax1.set_xlabel("classical / MJED, counted")
ax1.set_ylabel("classical / MJED, measured")
ax1.legend(fontsize=8)
fig.tight_layout()
