# %% [markdown]
# # One tetrahedron by hand
#
# Two discretisations of the same strain energy $W$ on one linear tetrahedron: MJED, which
# writes $W$ as a sum of products $f(J)\,g(C)$ and builds the stiffness from six *edge
# blocks*, and the classical Total Lagrangian FEM, which builds the second Piola-Kirchhoff
# stress $S$, the $6\times 6$ elasticity tensor $\mathbb{C}$ and
# $K_e = V_0\,(B^T \mathbb{C} B + \text{geometric})$. We compute every quantity by hand with
# NumPy, check it against `mjed.HyperelasticForceField` and
# `reference_fem.classical.ClassicalGalerkin`, and see that the two $12\times 12$ matrices are
# equal to round-off.
#
# Material: Mooney-Rivlin, $W = c_1(\bar I_1 - 3) + c_2(\bar I_2 - 3) + \tfrac{k_0}{2}(\ln J)^2$,
# chosen because its decomposition uses both kinds of MJED tangent pairs.

# %%
import numpy as np

import mjed
from mjed.materials import MooneyRivlin
from reference_fem.classical import ClassicalGalerkin, strain_displacement

np.set_printoptions(precision=4, suppress=False, linewidth=100)

material = MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4)
X = np.array(
    [[0.0, 0.0, 0.0], [1.0, 0.1, 0.0], [0.2, 0.9, 0.1], [0.1, 0.2, 1.1]]
)  # rest positions (m)
cells = np.array([[0, 1, 2, 3]])
mesh = mjed.TetMesh(X, cells)

# A deformed state: a homogeneous stretch and shear, then a small non-homogeneous
# perturbation of the nodes (a linear tetrahedron only sees the resulting constant F).
F0 = np.array([[1.15, 0.20, 0.00], [0.05, 0.92, 0.10], [0.00, -0.08, 1.05]])
rng = np.random.default_rng(7)
x = X @ F0.T + 0.03 * rng.standard_normal((4, 3)) + np.array([0.3, -0.1, 0.2])

# %% [markdown]
# ## Geometry and kinematics
#
# The rest volume is $V_0 = \det[X_1 - X_0, X_2 - X_0, X_3 - X_0]/6$. The *shape vectors*
# $D_a = \nabla_X N_a$ are the gradients of the four linear shape functions; they sum to
# zero. The deformation gradient is $F = \sum_a x_a \otimes D_a$, then $J = \det F$,
# $C = F^T F$, $I_1 = \operatorname{tr} C$, $I_2 = \tfrac12 (I_1^2 - \operatorname{tr} C^2)$.

# %%
edges = X[1:] - X[0]  # rows X_a - X_0, a = 1..3
V0 = np.linalg.det(edges) / 6.0
grads = np.linalg.inv(edges)  # columns: gradients of N_1, N_2, N_3
D = np.vstack([-grads.sum(axis=1), grads.T])  # (4, 3): D_0 = -(D_1 + D_2 + D_3)
F = sum(np.outer(x[a], D[a]) for a in range(4))
J = np.linalg.det(F)
C = F.T @ F
I1 = np.trace(C)
I2 = 0.5 * (I1**2 - np.trace(C @ C))
print(f"V0 = {V0:.6f} m^3, J = {J:.6f}, I1 = {I1:.6f}, I2 = {I2:.6f}")
print("F =\n", F)

assert np.allclose(D, mesh.D[0], rtol=0, atol=1e-14), "shape vectors differ from TetMesh.D"
assert abs(V0 - mesh.volumes[0]) < 1e-15
assert np.allclose(D.sum(axis=0), 0.0, atol=1e-14)

# %% [markdown]
# ## The MJED terms
#
# `material.decomposition()` lists term groups; each term pairs a function of $J$ (giving
# $f, f', f''$) with a function of $C$ (giving $g$, $S_g = 2\,\partial g/\partial C$, and the
# derivative of $S_g$ as MJED pairs):
#
# $$\frac{\partial S_g}{\partial C} : H = \sum_{\text{first}} \beta\,(A : H)\,A
#   + \sum_{\text{second}} \gamma\, B H B ,$$
#
# with constant matrices $A$, $B$ (known when the material is built, so the engine
# precomputes their products with the shape vectors) and scalars $\beta$, $\gamma$
# evaluated at each state. An invariant function reads what it needs ($C$, $I_1$, $I_2$, $E$,
# ...) from a kinematics object (`mjed.kinematics.Kinematics`) holding arrays over cells
# (here one cell), which computes each quantity from $F$ on first use.

# %%
from mjed.kinematics import Kinematics

kin = Kinematics(F[None])
# It sees the same cell as the hand computation above.
assert np.allclose(kin.C[0], C, rtol=1e-14, atol=0) and np.isclose(kin.J[0], J, rtol=1e-14)
terms = []
for group in material.decomposition():
    assert not group.exponential, "Mooney-Rivlin has plain groups only"
    for term in group.terms:
        f, df, d2f = (float(np.squeeze(v)) for v in term.f(np.array([J])))
        g = float(np.squeeze(term.g.value(kin)))
        S_g = term.g.stress(kin)
        # None when g is constant; a stress equal in every cell may come back as one (3, 3).
        S_g = np.zeros((3, 3)) if S_g is None else np.asarray(S_g).reshape(-1, 3, 3)[0]
        pairs = [
            (p.kind, float(np.squeeze(c)), np.asarray(p.matrix))
            for p, c in zip(term.g.tangent, term.g.tangent_coefficients(kin))
        ]
        terms.append(
            dict(
                name=f"{type(term.f).__name__} x {type(term.g).__name__}",
                c=group.coefficient,
                f=f,
                df=df,
                d2f=d2f,
                g=g,
                S_g=S_g,
                pairs=pairs,
            )
        )

for t in terms:
    print(
        f"{t['name']}: f = {t['f']:.6g}, f' = {t['df']:.6g}, f'' = {t['d2f']:.6g}, g = {t['g']:.6g}"
    )
    if t["S_g"].any():
        print(
            "    S_g = 2 dg/dC (Pa) =",
            np.array2string(t["S_g"], precision=5, prefix="    S_g = 2 dg/dC (Pa) ="),
        )
    for kind, coef, M in t["pairs"]:
        label = "beta" if kind == "first" else "gamma"
        print(
            f"    {kind} pair: {label} = {coef:.6g}, matrix = identity: {np.allclose(M, np.eye(3))}"
        )

# The energy is the sum of the products, and must equal the material's W (per unit volume).
W_terms = sum(t["c"] * t["f"] * t["g"] for t in terms)
I1b, I2b = J ** (-2 / 3) * I1, J ** (-4 / 3) * I2
W_formula = material.c1 * (I1b - 3) + material.c2 * (I2b - 3) + 0.5 * material.k0 * np.log(J) ** 2
field = mjed.HyperelasticForceField(mesh, material)
print(f"W from the terms = {W_terms:.10g} J/m^3, from the formula = {W_formula:.10g}")
assert abs(W_terms - W_formula) < 1e-12 * abs(W_formula)
assert abs(V0 * W_terms - field.energy(x)) < 1e-12 * abs(field.energy(x))
assert [len(t["pairs"]) for t in terms] == [0, 2, 0], (
    "I1 term: no pair; I2 term: one first + one second pair"
)

# %% [markdown]
# ## Forces
#
# With $j_a = \partial J/\partial x_a = J F^{-T} D_a$ (the cofactor of $F$ applied to $D_a$)
# and $s_a = \partial g/\partial x_a = F S_g D_a$, a term contributes
# $-V_0\,(f' g\, j_a + f\, s_a)$ to the force on node $a$. The second Piola-Kirchhoff stress
# of the whole material is $S = \sum (f\,S_g + f' g\, J\, C^{-1})$.

# %%
cof = J * np.linalg.inv(F).T
j = D @ cof.T  # rows j_a
force_hand = np.zeros((4, 3))
S_hand = np.zeros((3, 3))
for t in terms:
    s = D @ (F @ t["S_g"]).T  # rows s_a
    force_hand -= V0 * t["c"] * (t["df"] * t["g"] * j + t["f"] * s)
    S_hand += t["c"] * (t["f"] * t["S_g"] + t["df"] * t["g"] * J * np.linalg.inv(C))
force_mjed = field.force(x)
print("force by hand (N):\n", force_hand)
assert np.abs(force_hand - force_mjed).max() < 1e-12 * np.abs(force_mjed).max()
assert np.abs(force_hand.sum(axis=0)).max() < 1e-12 * np.abs(force_hand).max(), (
    "forces must balance"
)

# %% [markdown]
# ## The six edge blocks
#
# Differentiating the force once more gives, for an edge $(a, b)$ with $a \ne b$, the
# $3\times 3$ block (per term, times $V_0$):
#
# $$K_{ab} = f'' g\, j_a \otimes j_b + \frac{f' g}{J}\,(j_a \otimes j_b - j_b \otimes j_a)
#   + f'\,(j_a \otimes s_b + s_a \otimes j_b)
#   + f\Big[(D_a \cdot S_g D_b)\,I + \sum_{\text{first}} 2\beta\,(F A D_a)\otimes(F A D_b)
# + \sum_{\text{second}} \gamma\,\big((D_a\cdot B D_b)\,F B F^T + (F B D_b)\otimes(F B
# D_a)\big)\Big].$$
#
# The first two terms are the derivatives of $J$, the middle one couples $J$ and $g$, the
# bracket is $g$'s own Hessian: its geometric part and one product per tangent pair. Only
# the six blocks of the edges are computed; $K_{ba} = K_{ab}^T$, and the diagonal blocks
# follow from translation invariance, $K_{aa} = -\sum_{b \ne a} K_{ab}$.

# %%
EDGES = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def edge_pieces(t, a, b):
    """One term's contribution to K_ab (a != b), split into the pieces of the formula above."""
    s = D @ (F @ t["S_g"]).T
    scale = t["c"] * V0
    pieces = {
        "J-J": scale
        * (
            t["d2f"] * t["g"] * np.outer(j[a], j[b])
            + t["df"] * t["g"] / J * (np.outer(j[a], j[b]) - np.outer(j[b], j[a]))
        ),
        "J-g": scale * t["df"] * (np.outer(j[a], s[b]) + np.outer(s[a], j[b])),
        "geometric": scale * t["f"] * (D[a] @ t["S_g"] @ D[b]) * np.eye(3),
    }
    for kind, coef, M in t["pairs"]:
        if kind == "first":
            pieces["(beta, A)"] = scale * t["f"] * 2 * coef * np.outer(F @ M @ D[a], F @ M @ D[b])
        else:
            pieces["(gamma, B)"] = (
                scale
                * t["f"]
                * coef
                * ((D[a] @ M @ D[b]) * (F @ M @ F.T) + np.outer(F @ M @ D[b], F @ M @ D[a]))
            )
    return pieces


def edge_block(t, a, b):
    """One term's K_ab: the sum of its pieces."""
    return sum(edge_pieces(t, a, b).values())


def assemble(blocks):
    """12 x 12 element matrix from the six edge blocks {(a, b): (3, 3)}."""
    K = np.zeros((4, 3, 4, 3))
    for (a, b), blk in blocks.items():
        K[a, :, b, :] = blk
        K[b, :, a, :] = blk.T
    for a in range(4):
        K[a, :, a, :] = -sum(K[a, :, b, :] for b in range(4) if b != a)
    return K.reshape(12, 12)


blocks = {e: sum(edge_block(t, *e) for t in terms) for e in EDGES}
for e, blk in blocks.items():
    print(f"K_{e[0]}{e[1]} (N/m) =\n", blk)
K_mjed_hand = assemble(blocks)
K_mjed = field.element_stiffness(x)[0]
rel_hand = np.abs(K_mjed_hand - K_mjed).max() / np.abs(K_mjed).max()
print(
    "hand edge blocks vs HyperelasticForceField.element_stiffness: max rel. difference "
    f"{rel_hand:.2e}"
)
assert rel_hand < 1e-12

# %% [markdown]
# ## The classical side
#
# The classical FEM evaluates the material law as a whole: $S = 2\,\partial W/\partial C$ and the
# elasticity tensor $\mathbb{C} = 2\,\partial S/\partial C$ in Voigt notation (rows
# $xx, yy, zz, xy, yz, xz$), the strain-displacement matrix $B$ ($6\times 12$,
# $\delta E = B\,\delta x$), and
#
# $$K_e = V_0\,\big(B^T \mathbb{C} B + [(D_a \cdot S D_b)\, I]_{ab}\big).$$
#
# `ClassicalGalerkin` keeps its law in `.law` (`stress_and_tangent(C, J)`) and the $B$ matrix
# is `reference_fem.classical.strain_displacement(F, D)`.

# %%
classical = ClassicalGalerkin(X, cells, material)
S_cl, CC = classical.law.stress_and_tangent(C[None], np.array([J]))
S_cl, CC = S_cl[0], CC[0]
B = strain_displacement(F[None], D[None])[0]
K_material = V0 * B.T @ CC @ B
K_geometric = V0 * np.kron(D @ S_cl @ D.T, np.eye(3))
K_classical_hand = K_material + K_geometric
K_classical = classical.element_stiffness(x)[0]
print("classical S (Pa):\n", S_cl)
print("6x6 elasticity tensor (Pa):\n", CC)
print(f"|S_MJED - S_classical| / |S| = {np.abs(S_hand - S_cl).max() / np.abs(S_cl).max():.2e}")
assert np.abs(S_hand - S_cl).max() < 1e-12 * np.abs(S_cl).max()
assert np.allclose(CC, CC.T, rtol=1e-13, atol=0), "the elasticity tensor has the major symmetry"
assert np.abs(K_classical_hand - K_classical).max() < 1e-12 * np.abs(K_classical).max()

# %% [markdown]
# ## The two 12 x 12 matrices
#
# Same energy, same exact derivatives, two different factorisations of the arithmetic:
# the matrices agree to round-off (relative difference of order $10^{-16}$).

# %%
rel = np.linalg.norm(K_mjed - K_classical) / np.linalg.norm(K_classical)
sym = np.abs(K_mjed - K_mjed.T).max() / np.abs(K_mjed).max()
print(f"||K_MJED - K_classical||_F / ||K_classical||_F = {rel:.2e}")
translations = np.kron(np.ones((4, 1)), np.eye(3))  # (12, 3): rigid translations
print(
    f"symmetry error of K_MJED: {sym:.2e}; |K t| / |K| for the translations: "
    f"{np.abs(K_mjed @ translations).max() / np.abs(K_mjed).max():.1e}"
)
assert rel < 1e-13, f"MJED and classical element matrices differ: {rel:.2e}"
assert sym < 1e-13
assert np.abs(K_mjed @ translations).max() < 1e-13 * np.abs(K_mjed).max(), (
    "translations are zero modes"
)

# %% [markdown]
# ## Where each term lands in the matrix
#
# Left: the element matrix, with the six edge blocks MJED computes outlined (upper
# triangle; the lower one is their transpose, the diagonal blocks their negated row sums).
# Right: the size (Frobenius norm) of each piece of each term in each edge block. The
# volumetric $\ln J$ term has only $J$ pieces; the $\bar I_1$ term has no tangent pair
# ($S_g$ is constant) so its $g$-Hessian is the geometric piece alone; the $\bar I_2$ term
# carries one pair of each kind. Pieces that vanish identically are not listed.

# %%
import matplotlib.pyplot as plt
from matplotlib.patches import Rectangle

per_term = [assemble({e: edge_block(t, *e) for e in EDGES}) for t in terms]
assert np.abs(sum(per_term) - K_mjed).max() < 1e-12 * np.abs(K_mjed).max()
rows, norms = [], []
for t in terms:
    short = t["name"].split(" x ")[1]
    for piece in edge_pieces(t, 0, 1):
        values = [np.linalg.norm(edge_pieces(t, a, b)[piece]) for a, b in EDGES]
        if max(values) > 0:
            rows.append(f"{short}: {piece}")
            norms.append(values)
norms = np.array(norms)
print("Frobenius norm of each piece in each edge block (N/m):")
print(
    "\n".join(f"  {r:<24s}" + " ".join(f"{v:9.1f}" for v in vals) for r, vals in zip(rows, norms))
)
assert "Unity: (beta, A)" not in rows and "I1Power: (beta, A)" not in rows
assert {"LinearI2: (beta, A)", "LinearI2: (gamma, B)"} <= set(rows)

fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [1, 1.3]})
im0 = ax0.imshow(K_mjed, cmap="RdBu_r", vmin=-np.abs(K_mjed).max(), vmax=np.abs(K_mjed).max())
for a, b in EDGES:
    ax0.add_patch(Rectangle((3 * b - 0.5, 3 * a - 0.5), 3, 3, fill=False, ec="k", lw=1.5))
    ax0.text(3 * b + 1, 3 * a + 1, f"{a}{b}", ha="center", va="center", fontsize=8)
ax0.set_xticks(range(0, 12, 3))
ax0.set_yticks(range(0, 12, 3))
ax0.set_title("K_e (MJED); the six edge blocks outlined", fontsize=9)
fig.colorbar(im0, ax=ax0, shrink=0.8, label="N/m")
im1 = ax1.imshow(np.log10(norms), cmap="viridis", aspect="auto")
ax1.set_xticks(range(6))
ax1.set_xticklabels([f"K_{a}{b}" for a, b in EDGES])
ax1.set_yticks(range(len(rows)))
ax1.set_yticklabels(rows, fontsize=8)
ax1.set_title("where each term lands: log10 of each piece's norm per edge block", fontsize=9)
fig.colorbar(im1, ax=ax1, shrink=0.8, label="log10 (N/m)")
fig.tight_layout()
