# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Check your own implementation
#
# You have written hyperelastic forces and a tangent stiffness for linear tetrahedra in your
# own engine, and you want to know whether they are right, and if not, what is wrong. This
# tutorial writes a small engine with a mistake that is common in practice, checks it against
# the oracle from Python and from the command line, reads the diagnosis, fixes the engine, and
# checks it against the energy it really implements.
#
# Everything the engine must agree on (signs, degree-of-freedom order, energies, the file
# format) is in {doc}`the conventions </conventions>` (`docs/conventions.md`).

# %%
import logging
import os
import subprocess
import sys
import tempfile
import textwrap

import numpy as np

logging.disable(logging.INFO)  # the oracle's form compiler logs every compilation

# %% [markdown]
# ## A small engine
#
# A compressible Neo-Hookean solid, `W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2` in the
# conventions. Our engine writes the bulk term as `lam/2 (J - 1)^2`, a penalty that many codes
# use: it agrees with `(ln J)^2` to second order at rest, so small tests do not see it.
#
# The engine is vectorised over cells: first Piola-Kirchhoff stress `P = dW/dF`, force
# `f_a = -V0 P D_a`, stiffness `K_ab = V0 D_a . (dP/dF) D_b`, with `D_a` the shape-function
# gradients. It follows the protocol of `conformance`: it receives a case (rest points,
# cells, current positions, model) and returns `(force, stiffness, energy)`.

# %%
import scipy.sparse as sp


def shape_gradients(points, cells):
    """Rest volumes (m,) and shape-function gradients D (m, 4, 3)."""
    edges = np.swapaxes(points[cells[:, 1:]] - points[cells[:, :1]], 1, 2)  # columns X_a - X_0
    inv = np.linalg.inv(edges)
    D = np.concatenate([-inv.sum(axis=1, keepdims=True), inv], axis=1)
    return np.linalg.det(edges) / 6.0, D


def my_engine(case, bulk="(J-1)^2"):
    mu, lam = case.model.mu, case.model.lam
    V0, D = shape_gradients(case.points, case.cells)
    F = np.einsum("mak,mai->mki", case.positions[case.cells], D)
    J = np.linalg.det(F)
    FiT = np.swapaxes(np.linalg.inv(F), 1, 2)
    lnJ = np.log(J)
    if bulk == "(J-1)^2":  # U(J) = lam/2 (J-1)^2: U' = lam (J-1), U'' = lam
        U, dU, d2U = 0.5 * lam * (J - 1) ** 2, lam * (J - 1), lam + 0 * J
    else:  # the conventions: U = lam/2 (ln J)^2
        U, dU, d2U = 0.5 * lam * lnJ**2, lam * lnJ / J, lam * (1 - lnJ) / J**2
    I1 = np.einsum("mki,mki->m", F, F)
    energy = float(np.sum(V0 * (0.5 * mu * (I1 - 3) - mu * lnJ + U)))
    # P = mu (F - F^-T) + J U'(J) F^-T
    P = mu * (F - FiT) + (J * dU)[:, None, None] * FiT
    # dP_iI/dF_jJ = mu d_ij d_IJ + (mu - J U') FiT_iJ FiT_jI + (J U' + J^2 U'') FiT_iI FiT_jJ
    eye = np.eye(3)
    A = (
        mu * np.einsum("ij,IJ->iIjJ", eye, eye)[None]
        + (mu - J * dU)[:, None, None, None, None] * np.einsum("miJ,mjI->miIjJ", FiT, FiT)
        + (J * dU + J**2 * d2U)[:, None, None, None, None] * np.einsum("miI,mjJ->miIjJ", FiT, FiT)
    )
    n = len(case.points)
    fe = -V0[:, None, None] * np.einsum("miI,maI->mai", P, D)
    force = np.zeros((n, 3))
    np.add.at(force, case.cells, fe)
    Ke = V0[:, None, None, None, None] * np.einsum("maI,miIjJ,mbJ->maibj", D, A, D)
    dofs = (3 * case.cells[:, :, None] + np.arange(3)).reshape(-1, 12)
    rows, cols = np.repeat(dofs, 12, axis=1).ravel(), np.tile(dofs, (1, 12)).ravel()
    K = sp.csr_matrix((Ke.reshape(-1, 144).ravel(), (rows, cols)), shape=(3 * n, 3 * n))
    return force, K, energy


# %% [markdown]
# ## Check it from Python
#
# `check_implementation` runs the engine on every state of the conventions (here three), on a
# small cube mesh, together with four perturbed copies of each state that test the engine
# against itself (is its stiffness the derivative of its own force?). Each case is compared
# with the UFL oracle.

# %%
from conformance import assert_matches_oracle, check_implementation

run = check_implementation(
    my_engine, material="NeoHookean", mesh="cube-small", states=("shear", "uniaxial", "random")
)
print(run.text())

# %% [markdown]
# The `shear` state has `J = 1` in every cell, where `(J - 1)^2` and `(ln J)^2` have the same
# value, slope and curvature: it passes. The two others fail, and the diagnosis names the
# volumetric energy. In the `random` state the cells have hundreds of different values of `J`,
# so the diagnosis can even recognise which bulk term was used, and with which coefficient.

# %%
outcome = {o.state: o for o in run.outcomes}
assert outcome["shear"].status == "passed"
random_cause = outcome["random"].diagnosis.causes[0]
assert random_cause.code == "volumetric"
assert "k/2 (J-1)^2 used for the bulk term instead of k/2 (ln J)^2" in random_cause.evidence
from common.cases import DEFAULT_MATERIALS

lam = DEFAULT_MATERIALS["NeoHookean"].lam
assert f"k = {lam:.6g} Pa" in random_cause.evidence  # the fitted coefficient is the engine's lam
assert random_cause.figures["residual"] <= 1e-10  # the correction explains the error to round-off
print(random_cause.text())

# %% [markdown]
# Why the `shear` state could not see it and the `random` state could: the two bulk terms
# have the same value, slope and curvature at `J = 1`, and part ways as `J` moves away from 1.
# The histogram shows the values of `J` the `random` state puts in the cells.

# %%
import matplotlib.pyplot as plt

import meshes
from common.states import apply_state

X, cells, _ = meshes.resolve("cube-small")
x = apply_state("random", X, cells)
J_cell = np.linalg.det(np.swapaxes(x[cells[:, 1:]] - x[cells[:, :1]], 1, 2)) / np.linalg.det(
    np.swapaxes(X[cells[:, 1:]] - X[cells[:, :1]], 1, 2)
)
J = np.linspace(0.35, 2.4, 300)
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 3.8))
ax0.plot(J, 0.5 * lam * (J - 1) ** 2, label="lam/2 (J-1)^2 (the engine)")
ax0.plot(J, 0.5 * lam * np.log(J) ** 2, label="lam/2 (ln J)^2 (the conventions)")
ax0.set_xlabel("J")
ax0.set_ylabel("U(J) (Pa)")
ax0.legend()
ax1.hist(J_cell, bins=40)
ax1.set_xlabel("J in the cells, random state")
ax1.set_ylabel("cells")
fig.tight_layout()
plt.show()
# Same value, slope and curvature at J = 1: they differ at third order only ...
h = 1e-2
near = np.abs(0.5 * lam * (h**2 - np.log1p(h) ** 2))
assert near < 1e-5 * lam
# ... while the random state spans J far from 1 (the shear state has J = 1 in every cell).
assert J_cell.min() < 0.6 and J_cell.max() > 1.5
print(f"J in the random state: {J_cell.min():.2f} to {J_cell.max():.2f}")

# %% [markdown]
# The engine's stiffness is the derivative of its own force (the probes say so): the engine
# is self-consistent, it simply implements another energy. That is the information a Taylor
# test alone could never give.

# %%
for o in run.outcomes:
    assert "consistent-stiffness" in [f.code for f in o.diagnosis.findings], o.diagnosis.text()

# %% [markdown]
# ## Two ways to fix it
#
# Either implement the bulk term of the conventions, and the engine matches the built-in
# material to round-off:

# %%
fixed = assert_matches_oracle(
    lambda case: my_engine(case, bulk="(ln J)^2"),
    material="NeoHookean",
    mesh="cube-small",
    states=("shear", "uniaxial", "random"),
)
print(fixed.summary())
assert fixed.exit_code == 0

# %% [markdown]
# or keep the engine and check it against the energy it really implements, written as an
# expression (the oracle differentiates it exactly):

# %%
from reference_fem.user_energy import UserEnergy

nh = DEFAULT_MATERIALS["NeoHookean"]
penalty = UserEnergy("mu/2*(I1-3) - mu*ln(J) + lam/2*(J-1)**2", {"mu": nh.mu, "lam": nh.lam})


def my_engine_for(case):
    # The engine reads mu and lam from the case's model, whatever its kind.
    class Params:
        mu, lam = penalty.params["mu"], penalty.params["lam"]

    return my_engine(type(case)(case.case_id, case.points, case.cells, case.positions, Params()))


as_written = assert_matches_oracle(
    my_engine_for, energy=penalty, mesh="cube-small", states=("uniaxial", "random")
)
print(as_written.summary())

# %% [markdown]
# ## Check it from the command line
#
# Any executable can be checked: `mjed-verify check --command 'my_engine {input} {output}'`
# runs it once per case, with `{input}` a directory holding `case.json`, `case.txt` and the
# raw arrays, and `{output}` the directory where it writes `force.f64`, the stiffness and
# optionally `energy.f64` (the format is in the conventions). Here the engine above is wrapped
# in a small script.

# %%
import inspect

workdir = tempfile.mkdtemp(prefix="check-tutorial-")
# The engine's functions in a module of their own, and a script around them (Python puts the
# script's directory on sys.path, so it finds the module).
with open(os.path.join(workdir, "engine_functions.py"), "w") as fh:
    fh.write("import numpy as np\nimport scipy.sparse as sp\n\n\n")
    fh.write(inspect.getsource(shape_gradients) + "\n\n" + inspect.getsource(my_engine))
script = os.path.join(workdir, "my_engine.py")
with open(script, "w") as fh:
    fh.write(
        textwrap.dedent("""\
        import sys
        from conformance import read_case_input, write_output
        from engine_functions import my_engine
        case = read_case_input(sys.argv[1])
        force, K, W = my_engine(case)
        write_output(sys.argv[2], force, K, W)
    """)
    )

cli = [
    sys.executable,
    "-m",
    "comparisons.cli",
    "check",
    "--command",
    f"{sys.executable} {script} {{input}} {{output}}",
    "--material",
    "NeoHookean",
    "--mesh",
    "cube-small",
    "--states",
    "random",
    "--out",
    os.path.join(workdir, "reports"),
]
done = subprocess.run(cli, capture_output=True, text=True)
print(done.stdout)

# %% [markdown]
# The exit code is 1 (a case failed; 0 would mean all passed, 2 bad input such as a missing
# file or a crash), and the report directory holds `index.html`, `results.json` and, for the
# failing case, the per-node error field `fields/<case>.vtu` to open in ParaView.

# %%
assert done.returncode == 1, done.stderr
assert "volumetric (J-only) energy differs from the oracle's [explains]" in done.stdout
(report_dir,) = os.listdir(os.path.join(workdir, "reports"))
assert os.path.isfile(
    os.path.join(workdir, "reports", report_dir, "fields", "NeoHookean.cube-small.random.vtu")
)
