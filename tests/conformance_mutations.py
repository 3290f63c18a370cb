"""A deliberately broken reference implementation: mjed.HyperelasticForceField with one classic
mistake.

Each mutation is a function (case, field, f, K, W) -> (f, K, W) applied to the exact MJED output
of the case, written independently of the diagnosis: the tangent-part mutations build their
parts with the classical Total Lagrangian formulas (reference_fem.classical: B^T CC B and the
geometric term), the energy variant with its own MJED term. ``EXPECTED`` says which finding
code the diagnosis must name for each one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Dict, Tuple

import numpy as np
import scipy.sparse as sp

import mjed
from common.cases import DEFAULT_MATERIALS
from mjed.materials import MooneyRivlin
from mjed.terms import JFunction, LogPolynomial, Term, TermGroup, Unity
from reference_fem.classical import strain_displacement
from reference_fem.classical_materials import classical_law

__all__ = [
    "MUTATIONS",
    "EXPECTED",
    "broken_engine",
    "MATERIAL",
    "FRAME_MUTATIONS",
    "FRAME_EXPECTED",
    "FRAME_MATERIAL",
    "broken_frame_engine",
]

#: The material every mutation is checked with (both volumetric and isochoric terms matter).
MATERIAL = MooneyRivlin(c1=1200.0, c2=400.0, k0=3.0e4)


def _assemble(cells: np.ndarray, n: int, Ke: np.ndarray) -> sp.csr_matrix:
    """Sum element matrices (m, 12, 12) (node-major local dofs) into (3n, 3n)."""
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    return sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(3 * n, 3 * n))


def _classical_blocks(case):
    """Per cell: V0 (m,), B (m, 6, 12), CC (m, 6, 6) (engineering Voigt), S (m, 3, 3), D (m, 4,
    3).
    """
    mesh = mjed.TetMesh(case.points, case.cells)
    F = np.swapaxes(case.positions[mesh.cells], 1, 2) @ mesh.D
    S, CC = classical_law(case.model).stress_and_tangent(np.swapaxes(F, 1, 2) @ F)
    return mesh.volumes, strain_displacement(F, mesh.D), CC, S, mesh.D


def _voigt_shear_doubled(case, field, f, K, W):
    V0, B, CC, S, D = _classical_blocks(case)
    Bs = B[:, 3:, :]
    extra = (
        V0[:, None, None] * np.swapaxes(Bs, 1, 2) @ CC[:, 3:, 3:] @ Bs
    )  # the shear-shear block once more
    return f, (K + _assemble(case.cells, case.n_nodes, extra)).tocsr(), W


def _geometric_missing(case, field, f, K, W):
    V0, B, CC, S, D = _classical_blocks(case)
    g = V0[:, None, None] * np.einsum("mai,mij,mbj->mab", D, S, D)  # (D_a . S D_b) per node pair
    geo = np.einsum("mab,kl->makbl", g, np.eye(3)).reshape(-1, 12, 12)
    return f, (K - _assemble(case.cells, case.n_nodes, geo)).tocsr(), W


class _Bulk(mjed.materials.base.Material):
    """Only the volumetric term k0/2 (ln J)^2 (a material for the 'volumetric tangent doubled'
    mutation).
    """

    def __init__(self, k0: float):
        self.k0 = k0

    def decomposition(self):
        return (TermGroup((Term(LogPolynomial(0.5 * self.k0), Unity()),)),)


def _volumetric_tangent_doubled(case, field, f, K, W):
    bulk = mjed.HyperelasticForceField(field.mesh, _Bulk(case.model.k0))
    return f, (K + bulk.stiffness(case.positions)).tocsr(), W


@dataclass(frozen=True)
class _JMinusOneSquared(JFunction):
    """k/2 (J - 1)^2 + a0: the common penalty bulk term."""

    k: float
    a0: float

    def __call__(self, J):
        return 0.5 * self.k * (J - 1.0) ** 2 + self.a0, self.k * (J - 1.0), self.k + 0.0 * J


class _MooneyRivlinJMinusOne(mjed.materials.base.Material):
    """MooneyRivlin's isochoric terms with k0/2 (J-1)^2 in place of k0/2 (ln J)^2."""

    def __init__(self, m: MooneyRivlin):
        self.m = m

    def decomposition(self):
        out = []
        for group in self.m.decomposition():
            terms = tuple(
                Term(_JMinusOneSquared(2 * t.f.a2, t.f.a0), t.g)
                if isinstance(t.f, LogPolynomial)
                else t
                for t in group.terms
            )
            out.append(replace(group, terms=terms))
        return tuple(out)


def _energy_variant(case, field, f, K, W):
    variant = mjed.HyperelasticForceField(field.mesh, _MooneyRivlinJMinusOne(case.model))
    f2, K2 = variant.force_and_stiffness(case.positions)
    return f2, K2, variant.energy(case.positions)


def _tangent_at_rest(case, field, f, K, W):
    return f, field.stiffness(case.points), W  # the stiffness of the undeformed mesh: not d f / dx


def _one_cell_wrong(case, field, f, K, W):
    c = len(case.cells) // 2  # an interior-ish cell, the same every time
    fe = field.element_forces(case.positions)[c]
    Ke = field.element_stiffness(case.positions)[c]
    f = f.copy()
    np.add.at(f, case.cells[c], 0.5 * fe)
    return f, (K + _assemble(case.cells[c : c + 1], case.n_nodes, 0.5 * Ke[None])).tocsr(), W


def _component_major(case, field, f, K, W):
    n = case.n_nodes
    order = (
        3 * np.arange(n)[None, :] + np.arange(3)[:, None]
    ).ravel()  # engine index c*n+a holds dof 3a+c
    Kc = sp.csr_matrix(K)[order][:, order]
    return f.ravel()[order].reshape(n, 3), Kc.tocsr(), W


def _permute(case, f, K, q):
    """Engine writes node a's values at position q[a]."""
    n = case.n_nodes
    inv = np.empty(n, dtype=np.int64)
    inv[q] = np.arange(n)
    p = (3 * inv[:, None] + np.arange(3)).ravel()
    return f[inv], sp.csr_matrix(K)[p][:, p].tocsr()


def _nodes_permuted(case, field, f, K, W):
    q = np.random.default_rng(5).permutation(case.n_nodes)
    return (*_permute(case, f, K, q), W)


def _one_based(case, field, f, K, W):
    q = (
        np.arange(case.n_nodes) + 1
    ) % case.n_nodes  # node a written at a + 1 (wrapping the last one)
    return (*_permute(case, f, K, q), W)


def _blocks_transposed(case, field, f, K, W):
    C = sp.coo_matrix(K)
    r, ci = np.divmod(C.row, 3)
    c, cj = np.divmod(C.col, 3)
    return f, sp.csr_matrix((C.data, (3 * r + cj, 3 * c + ci)), shape=K.shape), W


def _unsymmetric(case, field, f, K, W):
    C = sp.coo_matrix(K)
    rng = np.random.default_rng(3)
    A = sp.csr_matrix((rng.standard_normal(C.nnz), (C.row, C.col)), shape=K.shape)
    skew = (A - A.T) * (1e-3 * abs(K).max())
    return f, (K + skew).tocsr(), W


Mutation = Callable[..., Tuple[np.ndarray, sp.csr_matrix, float]]

MUTATIONS: Dict[str, Mutation] = {
    "none": lambda case, field, f, K, W: (f, K, W),
    "force sign": lambda case, field, f, K, W: (-f, K, W),
    "stiffness sign": lambda case, field, f, K, W: (f, -K, W),
    "both signs": lambda case, field, f, K, W: (-f, -K, -W),
    "component-major dofs": _component_major,
    "nodes permuted": _nodes_permuted,
    "1-based node index": _one_based,
    "factor 2": lambda case, field, f, K, W: (2 * f, 2 * K, 2 * W),
    "component-major dofs and the residual's sign": lambda case, field, f, K, W: _component_major(
        case, field, -f, K, W
    ),
    "3x3 blocks transposed": _blocks_transposed,
    "unsymmetric K": _unsymmetric,
    "Voigt shear doubled": _voigt_shear_doubled,
    "geometric stiffness missing": _geometric_missing,
    "volumetric tangent doubled": _volumetric_tangent_doubled,
    "stiffness not the derivative of the force": _tangent_at_rest,
    "one cell wrong": _one_cell_wrong,
    "(J-1)^2 bulk term": _energy_variant,
}

#: Mutation -> the finding code the diagnosis must name (None: the case must pass).
EXPECTED: Dict[str, object] = {
    "none": None,
    "force sign": "force-sign",
    "stiffness sign": "stiffness-sign",
    "both signs": "both-signs",
    "component-major dofs": "dof-order",
    "nodes permuted": "node-permutation",
    "1-based node index": "node-offset+1",
    "factor 2": "scale",
    "component-major dofs and the residual's sign": "dof-order+force-sign",
    "3x3 blocks transposed": "block-transpose",
    "unsymmetric K": "unsymmetric",
    "Voigt shear doubled": "tangent-part",
    "geometric stiffness missing": "tangent-part",
    "volumetric tangent doubled": "tangent-part",
    # the tangent is the rest state's: named as such, the probes' inconsistency still shown
    "stiffness not the derivative of the force": "stiffness-other-state",
    # one cell's contribution 1.5 times: the cell and its factor, the localisation observed
    "one cell wrong": "cell-contribution",
    "(J-1)^2 bulk term": "volumetric",
}


def broken_engine(mutation: str):
    """An implementation (CaseInput -> (f, K, W)) with the named mistake."""
    mutate = MUTATIONS[mutation]

    def engine(case):
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
        f, K = field.force_and_stiffness(case.positions)
        return mutate(case, field, f, K, field.energy(case.positions))

    return engine


# ---------------------------------------------------------------- issue 21: kinematics and storage
class _MooneyRivlinPowers(mjed.materials.base.Material):
    """MooneyRivlin whose I1 term carries J^p instead of J^(-2/3) (p = 0: no isochoric factor)."""

    def __init__(self, m: MooneyRivlin, p: float):
        self.m, self.p = m, p

    def decomposition(self):
        from mjed.terms import I1Power, JPower

        out = []
        for group in self.m.decomposition():
            terms = tuple(
                Term(JPower(self.p), t.g) if isinstance(t.g, I1Power) else t for t in group.terms
            )
            out.append(TermGroup(terms, group.exponential, group.coefficient))
        return tuple(out)


def _with_material(material):
    def mutate(case, field, f, K, W):
        variant = mjed.HyperelasticForceField(field.mesh, material(case.model))
        f2, K2 = variant.force_and_stiffness(case.positions)
        return f2, K2.copy(), variant.energy(case.positions)

    return mutate


MUTATIONS.update(
    {
        "I1 without its isochoric factor": _with_material(lambda m: _MooneyRivlinPowers(m, 0.0)),
        "J^(-1/3) on I1": _with_material(lambda m: _MooneyRivlinPowers(m, -1.0 / 3.0)),
        "one triangle of K": lambda case, field, f, K, W: (f, sp.triu(K).tocsr(), W),
        "both triangles summed": lambda case, field, f, K, W: (
            f,
            (2 * K - sp.diags(K.diagonal())).tocsr(),
            W,
        ),
        "node blocks on one side": lambda case, field, f, K, W: (f, _node_blocks_one_side(K), W),
    }
)
EXPECTED.update(
    {
        "I1 without its isochoric factor": "energy-variant",
        "J^(-1/3) on I1": "energy-variant",
        "one triangle of K": "one-triangle",
        "both triangles summed": "both-triangles",
        "node blocks on one side": "mirror-blocks",
    }
)


def _node_blocks_one_side(K):
    """K's 3x3 node blocks (a, b) with a <= b only: an edge loop that never writes the mirror
    K_ba = K_ab^T (the node-diagonal blocks whole, so neither scalar triangle is empty).
    """
    K = sp.coo_matrix(K)
    keep = (K.row // 3) <= (K.col // 3)
    return sp.csr_matrix((K.data[keep], (K.row[keep], K.col[keep])), shape=K.shape)


def _finite_difference_tangent(case, field, f, K, W):
    """K column by column from forward differences of the force, step 1e-6 of the mean edge."""
    from common.tolerances import mean_edge_length

    h = 1e-6 * mean_edge_length(case.points, case.cells)
    x = case.positions.ravel()
    cols = []
    for j in range(x.size):
        y = x.copy()
        y[j] += h
        cols.append(sp.csc_matrix(-(field.force(y.reshape(-1, 3)).ravel() - f.ravel()) / h).T)
    return f, sp.hstack(cols).tocsr(), W


MUTATIONS["finite-difference tangent"] = _finite_difference_tangent
EXPECTED["finite-difference tangent"] = "finite-difference"
# -- Fibre-frame mistakes (issue 25) ---------------------------------------------------------------
# Checked on Costa, whose energy depends on the frame, with the helical per-cell field the kit gives
# it (common.frames). Each engine is MJED run with a frame other than the case's: the mistake sits
# inside the energy, so force and stiffness are both wrong in every deformed state.

#: The material of the frame mutations (no frame: the kit gives it the mesh's helical field).
FRAME_MATERIAL = DEFAULT_MATERIALS["Costa"]

#: Mutation -> the frame the engine uses, from the case's frame R (m, 3, 3).
FRAME_MUTATIONS: Dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "frame-blind engine (identity frame)": lambda R: np.eye(3),
    "transposed rotation": lambda R: np.swapaxes(R, -1, -2).copy(),
    "global axes (one frame for the mesh)": lambda R: R.reshape(-1, 3, 3)[0].copy(),
    "fibre and sheet columns swapped": lambda R: R[..., [1, 0, 2]].copy(),
}

FRAME_EXPECTED: Dict[str, str] = {
    "frame-blind engine (identity frame)": "frame-ignored",
    "transposed rotation": "frame-transposed",
    "global axes (one frame for the mesh)": "frame-global",
    "fibre and sheet columns swapped": "frame-columns",
}


def broken_frame_engine(mutation: str):
    """An implementation (CaseInput -> (f, K, W)): MJED with the case's frame replaced as named."""
    frame_of = FRAME_MUTATIONS[mutation]
    exact = broken_engine("none")

    def engine(case):
        wrong = replace(case.model, frame=frame_of(np.asarray(case.model.frame)))
        return exact(replace(case, model=wrong))

    return engine


# -- Families of mistakes (issue 29) ---------------------------------------------------------------
# Engines written without the diagnosis: MJED run with parameters read wrongly, MJED terms with
# another power, or the project's declared energy handed to UFL with a mistaken kinematic (a type
# registered here, its formula rewritten by hand). Each is checked on its own material; FAMILY
# says the material, the engine and the finding code the diagnosis must name first.


def _mjed_with(material_of):
    """An engine (CaseInput -> (f, K, W)): MJED on the material ``material_of(case.model)``."""

    def engine(case):
        field = mjed.HyperelasticForceField(
            mjed.TetMesh(case.points, case.cells), material_of(case.model)
        )
        f, K = field.force_and_stiffness(case.positions)
        return f, K, field.energy(case.positions)

    return engine


class _OgdenTerms(mjed.materials.base.Material):
    """Ogden's MJED terms with the power of J and of the eigenvalues of C chosen: J^(p) sum
    lambda_i^(q) (Ogden: p = -alpha/3, q = alpha/2).
    """

    def __init__(self, m, p: float, q: float):
        self.m, self.p, self.q = m, p, q

    def decomposition(self):
        from mjed.spectral import EigenPowerSum
        from mjed.terms import JPower

        c = self.m.mu / self.m.alpha**2
        return (
            TermGroup(
                (
                    Term(JPower(self.p), EigenPowerSum(c, self.q)),
                    Term(LogPolynomial(0.5 * self.m.k0, 0.0, -3.0 * c), Unity()),
                )
            ),
        )


def _costa_rewritten(kind: str):
    """An engine computing Costa's declared energy with F^T for F ("transposed") or with the
    frame pushed forward, each column normalised ("deformed frame"); differentiated by
    hyper-dual numbers (tests/hyperdual_engine.py), so that it costs no compiled form.
    """
    from hyperdual_engine import Namespace, density_engine, pushed_frame

    from mjed.materials import Costa
    from mjed.materials.declaration import declaration_of

    formula = declaration_of(Costa).energy

    def density(model, k, F, R):
        p = lambda name: float(getattr(model, name))  # noqa: E731
        if kind == "transposed":
            return formula(p, Namespace(F.T, R))
        return formula(p, Namespace(F, pushed_frame(F, R)))

    return density_engine(density, frame_of=lambda model: model.frame)


def _mooney_over_deformed_volume():
    """An engine computing Mooney-Rivlin's energy per unit deformed volume,
    J (c1 (I1b - 3) + c2 (I2b - 3) + k0/2 (ln J)^2), by hyper-dual numbers.
    """
    from hyperdual_engine import density_engine

    def density(m, k, F, R):
        return k.J * (m.c1 * (k.I1b - 3.0) + m.c2 * (k.I2b - 3.0) + 0.5 * m.k0 * k.lnJ * k.lnJ)

    return density_engine(density)


#: name -> (material name, engine, finding code named first).
FAMILY: Dict[str, Tuple[str, Callable, str]] = {
    "Mooney-Rivlin c1 and c2 exchanged": (
        "MooneyRivlin",
        _mjed_with(lambda m: replace(m, c1=m.c2, c2=m.c1)),
        "parameters-exchanged",
    ),
    "St Venant-Kirchhoff lam and mu exchanged": (
        "StVenantKirchhoff",
        _mjed_with(lambda m: replace(m, lam=m.mu, mu=m.lam)),
        "parameters-exchanged",
    ),
    "Neo-Hookean mu read in kPa": (
        "NeoHookean",
        _mjed_with(lambda m: replace(m, mu=1e3 * m.mu)),
        "term-coefficients",
    ),
    "Mooney-Rivlin c2 term with the wrong sign": (
        "MooneyRivlin",
        _mjed_with(lambda m: replace(m, c2=-m.c2)),
        "term-coefficients",
    ),
    "Yeoh c20 term dropped": (
        "Yeoh",
        _mjed_with(lambda m: replace(m, c20=0.0)),
        "term-coefficients",
    ),
    # float64, an error of 6e-6: small enough for float32, and not float32
    "Mooney-Rivlin c1 off by 6e-6 (float64)": (
        "MooneyRivlin",
        _mjed_with(lambda m: replace(m, c1=m.c1 * (1 + 6e-6))),
        "term-coefficients",
    ),
    "Ogden with J^(-alpha/6)": (
        "Ogden",
        _mjed_with(lambda m: _OgdenTerms(m, -m.alpha / 6.0, m.alpha / 2.0)),
        "kinematic-isochoric-power",
    ),
    "Ogden with the eigenvalues of C as stretches": (
        "Ogden",
        _mjed_with(lambda m: _OgdenTerms(m, -m.alpha / 3.0, m.alpha)),
        "kinematic-stretch-squares",
    ),
    "Costa with F transposed": (
        "Costa",
        _costa_rewritten("transposed"),
        "kinematic-C-B-confused",
    ),
    "Costa with the frame in the deformed configuration": (
        "Costa",
        _costa_rewritten("deformed frame"),
        "kinematic-frame-deformed",
    ),
    "Mooney-Rivlin over the deformed volume": (
        "MooneyRivlin",
        _mooney_over_deformed_volume(),
        "kinematic-deformed-volume",
    ),
    # float64, 2/3 written as 0.666667: small and systematic, never float32; the exponent of J
    # refitted through the oracle names it (issue 29)
    "Mooney-Rivlin J^(-0.666667) (float64)": (
        "MooneyRivlin",
        _mjed_with(lambda m: _MooneyRivlinPowers(m, -0.666667)),
        "formula-constant",
    ),
}


def _difference_tangent(scheme: str, eps: float):
    """MJED's force, and K from differences of it: "central" with a step h = eps [m],
    "forward" with a relative step h_j = eps |x_j| (eps where x_j = 0).
    """

    def engine(case):
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
        f = field.force(case.positions)
        x = case.positions.ravel()
        cols = []
        for j in range(x.size):
            h = eps if scheme == "central" or x[j] == 0 else eps * abs(x[j])
            y = x.copy()
            y[j] += h
            fp = field.force(y.reshape(-1, 3)).ravel()
            if scheme == "central":
                y[j] -= 2 * h
                fm = field.force(y.reshape(-1, 3)).ravel()
                col = -(fp - fm) / (2 * h)
            else:
                col = -(fp - f.ravel()) / h
            cols.append(sp.csc_matrix(col).T)
        return f, sp.hstack(cols).tocsr(), field.energy(case.positions)

    return engine


FAMILY.update(
    {
        "central differences, absolute step": (
            "NeoHookean",
            _difference_tangent("central", 1e-4),
            "finite-difference",
        ),
        "forward differences, relative step": (
            "Ogden",
            _difference_tangent("forward", 1e-6),
            "finite-difference",
        ),
    }
)
