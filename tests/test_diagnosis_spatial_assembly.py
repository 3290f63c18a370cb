"""An updated-Lagrangian assembly's kinematics (conformance.diagnosis.spatial_assembly): the
oracle's Cauchy stress and spatial tangent per cell reassembled with the wrong shape gradients
(F^-1 D for F^-T D, the reference D) or a wrong geometric stiffness. Each mistaken engine is
built here from MJED's element split (the oracle's stand-in), by hand: sigma = P F^T / J.
"""

from __future__ import annotations

import numpy as np
from conftest import box_mesh, mjed_split

from conformance.diagnosis.elements import assemble, cell_piola
from conformance.diagnosis.spatial_assembly import assembly_findings
from conformance.judge.compare import DOUBLE
from mjed.materials import MooneyRivlin, NeoHookean


def _state(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T + 0.04 * rng.standard_normal(points.shape)
    return points, cells, x


def _force(split, grad):
    """f_a = -v sigma grad_a, written by hand from the split's P: (n, 3)."""
    P, _ = cell_piola(split)
    J = np.linalg.det(split.F)
    sigma = P @ np.swapaxes(split.F, 1, 2) / J[:, None, None]
    fe = -(J * split.V0)[:, None, None] * np.einsum("mkp,map->mak", sigma, grad)
    return sigma, assemble(split.cells, split.n, fe, None)[0]


def test_spatial_gradients_with_f_inverse_transposed_are_named():
    points, cells, x = _state()
    split, f_o, K_o, s = mjed_split(NeoHookean(mu=3448.0, lam=31034.0), points, cells, x)
    Fi = np.linalg.inv(split.F)
    wrong = np.einsum("mpi,mai->map", Fi, split.D)  # F^-1 D_a: the row form D F^-T
    _, f = _force(split, wrong)
    # the stiffness that goes with it: the oracle's own reassembly (the finding's prediction)
    from conformance.diagnosis.spatial_assembly import (
        ASSEMBLY_VARIANTS,
        assemble_variant,
        spatial_parts,
    )

    (v,) = [v for v in ASSEMBLY_VARIANTS if v.code == "gradient-F-inverse"]
    fv, K = assemble_variant(split, spatial_parts(split), v)
    assert np.allclose(fv, f, rtol=0, atol=1e-12 * np.abs(f).max())  # by hand = the variant
    found = assembly_findings(split, f, K, s, DOUBLE)
    assert [x.code for x in found] == ["spatial-assembly-gradient-F-inverse"], found
    assert "D F^-T" in found[0].title
    # the right output and a constant factor: nothing
    assert assembly_findings(split, f_o, K_o, s, DOUBLE) == []
    assert assembly_findings(split, f_o, K_o * 1.01, s, DOUBLE) == []


def test_geometric_stiffness_with_reference_gradients_is_named_not_the_others():
    points, cells, x = _state(1)
    split, f_o, K_o, s = mjed_split(MooneyRivlin(c1=1200.0, c2=400.0, k0=3e4), points, cells, x)
    Fi = np.linalg.inv(split.F)
    g = np.einsum("mip,mai->map", Fi, split.D)  # the right F^-T D_a
    sigma, f = _force(split, g)
    assert np.allclose(f, f_o, rtol=0, atol=1e-9 * np.abs(f_o).max())  # sigma is the oracle's
    v = np.linalg.det(split.F) * split.V0
    # the engine's geometric stiffness (D_a . sigma D_b) v I for (g_a . sigma g_b) v I
    right = np.einsum("map,mpq,mbq->mab", g, sigma, g)
    wrong = np.einsum("map,mpq,mbq->mab", split.D, sigma, split.D)
    dKe = np.einsum("mab,kl->makbl", v[:, None, None] * (wrong - right), np.eye(3))
    _, dK = assemble(split.cells, split.n, split.fe, dKe.reshape(-1, 12, 12))
    found = assembly_findings(split, f_o, (K_o + dK).tocsr(), s, DOUBLE)
    assert [x.code for x in found] == ["spatial-assembly-geometric-reference"], found
    # nearby: the pressure-only geometric stiffness is another variant, also told apart
    p = np.einsum("mii->m", sigma) / 3.0
    press = p[:, None, None] * np.einsum("map,mbp->mab", g, g)
    dKe = np.einsum("mab,kl->makbl", v[:, None, None] * (press - right), np.eye(3))
    _, dK = assemble(split.cells, split.n, split.fe, dKe.reshape(-1, 12, 12))
    found = assembly_findings(split, f_o, (K_o + dK).tocsr(), s, DOUBLE)
    assert [x.code for x in found] == ["spatial-assembly-geometric-pressure"], found


def test_stress_built_on_c_where_b_belongs_is_named_with_or_without_transposed_gradients():
    """B formed as F^T F (= C): for an isotropic energy sigma' = R^T sigma R (F = R U), written
    here by hand on the force; with F transposed everywhere the gradients are F^-1 D_a too.
    """
    from conformance.diagnosis.spatial_assembly import (
        ASSEMBLY_VARIANTS,
        assemble_variant,
        spatial_parts,
    )

    points, cells, x = _state(2)
    split, f_o, K_o, s = mjed_split(MooneyRivlin(c1=1200.0, c2=400.0, k0=3e4), points, cells, x)
    P, _ = cell_piola(split)
    J = np.linalg.det(split.F)
    sigma = P @ np.swapaxes(split.F, 1, 2) / J[:, None, None]
    W, _, Vt = np.linalg.svd(split.F)
    R = W @ Vt
    rotated = np.swapaxes(R, 1, 2) @ sigma @ R
    Fi = np.linalg.inv(split.F)
    parts = spatial_parts(split)
    for code, grad in (("b-from-C", "mip"), ("F-transposed", "mpi")):
        g = np.einsum(f"{grad},mai->map", Fi, split.D)
        fe = -(J * split.V0)[:, None, None] * np.einsum("mkp,map->mak", rotated, g)
        f = assemble(split.cells, split.n, fe, None)[0]
        (v,) = [v for v in ASSEMBLY_VARIANTS if v.code == code]
        fv, K = assemble_variant(split, parts, v)
        assert np.allclose(fv, f, rtol=0, atol=1e-12 * np.abs(f).max())  # by hand = variant
        found = assembly_findings(split, f, K, s, DOUBLE)
        assert [x.code for x in found] == [f"spatial-assembly-{code}"], found
    # nearby: the right stress with the rotated tangent only is none of them
    (v,) = [v for v in ASSEMBLY_VARIANTS if v.code == "b-from-C"]
    _, K = assemble_variant(split, parts, v)
    assert assembly_findings(split, f_o, K, s, DOUBLE) == []
