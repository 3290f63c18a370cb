"""A Voigt stress vector read through the wrong map (conformance.diagnosis.voigt_maps): an
engine written here whose force is r = V0 B^T s with s filled in one Voigt order and read in
another, or with its shears doubled or a sign flipped; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.elements import assemble, cell_piola
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.strain_differences import VOIGT
from conformance.diagnosis.voigt_maps import voigt_map_findings
from conformance.judge.compare import DOUBLE


def _case(material, seed):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.04 * rng.standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(default_material(material), points, cells, x)
    return split, f_o, K_o, s


def _misread_force(split, M):
    """The force of s' = M s: S's Voigt vector mapped, then read back as a symmetric S'."""
    P, A = cell_piola(split)
    S = cell_tensors(P, A, split.F).S
    v = np.stack([S[:, i, j] for i, j in VOIGT], axis=1) @ M.T
    S2 = np.zeros_like(S)
    for a, (i, j) in enumerate(VOIGT):
        S2[:, i, j] = S2[:, j, i] = v[:, a]
    fe = -split.V0[:, None, None] * np.einsum("mkI,mIJ,maJ->mak", split.F, S2, split.D)
    return assemble(split.cells, split.n, fe, None)[0]


def _order_swap():
    """The vector s filled as (11, 22, 33, 23, 13, 12), read as (11, 22, 33, 12, 23, 13)."""
    M = np.zeros((6, 6))
    for a, b in enumerate((0, 1, 2, 4, 5, 3)):
        M[a, b] = 1.0
    return M


@pytest.mark.parametrize(
    "material, M, words",
    [
        ("NeoHookean", _order_swap(), "s_12 holds S_23"),
        ("Gent", np.diag([1, 1, 1, 2, 2, 2.0]), "shear components doubled (s_12 holds 2 S_12"),
        ("Costa", np.diag([1, 1, 1, 1, -1, 1.0]), "s_23 holds -S_23"),
    ],
)
def test_a_misread_voigt_stress_is_named_with_its_map(material, M, words):
    split, f_o, K_o, s = _case(material, 2)
    f = _misread_force(split, M)
    found = voigt_map_findings(split, f, K_o, f_o, K_o, s, DOUBLE)
    assert [x.code for x in found] == ["voigt-map"], found
    assert words in found[0].title and np.array_equal(found[0].figures["map"], M), found


def test_a_stress_off_by_a_formula_is_no_voigt_map():
    """Another material's force (a formula mistake) and a small global factor: no map."""
    split, f_o, K_o, s = _case("MooneyRivlin", 3)
    other = _case("Yeoh", 3)[1]
    assert voigt_map_findings(split, other, K_o, f_o, K_o, s, DOUBLE) == []
    assert voigt_map_findings(split, f_o * (1 + 1e-3), K_o, f_o, K_o, s, DOUBLE) == []


@pytest.mark.parametrize("slip", ["order-12-23-13", "shear-rows-doubled", "no-mirror"])
def test_a_material_tangent_unpacked_with_a_slip_is_named(slip):
    from conformance.diagnosis.spatial_variants import VOIGT_SLIPS, slip_tensor
    from conformance.diagnosis.strain_differences import material_stiffness
    from conformance.diagnosis.voigt_maps import tangent_slip_findings

    split, f_o, K_o, s = _case("Costa", 4)
    P, A = cell_piola(split)
    CC = cell_tensors(P, A, split.F).CC
    (v,) = [v for v in VOIGT_SLIPS if v.code == slip]
    K = K_o + material_stiffness(split, slip_tensor(CC, v) - CC)
    found = tangent_slip_findings(split, f_o, K, f_o, K_o, s, DOUBLE)
    assert [x.code for x in found] == [f"voigt-tangent-{slip}"], [x.code for x in found]
    assert tangent_slip_findings(split, f_o, K_o * (1 + 1e-4), f_o, K_o, s, DOUBLE) == []


def test_a_wrong_energy_puts_the_mistake_upstream_of_the_voigt_vector():
    """A vector misread between the material routine and B leaves the energy right (corpus
    13's C packed as a strain doubles S's shears too, and the energy with them): with the
    engine's energy wrong the reading says nothing, before it looks at the mesh.
    """
    from types import SimpleNamespace

    from conformance.diagnosis.voigt_maps import voigt_map_reading

    diag = SimpleNamespace(
        errors=SimpleNamespace(energy=1e-3, force=1e-2), tolerances=SimpleNamespace(energy=1e-10)
    )
    assert voigt_map_reading(diag, None, None, None, None) is diag


def test_the_rows_of_b_read_through_a_map_carry_it_into_the_material_stiffness():
    """B's shear rows doubled (corpus 13): the force of s' = M s and the material stiffness
    B^T (M D M^T) B, the geometric part right, predicted together: named fully.
    """
    from conformance.diagnosis.strain_differences import (
        material_stiffness,
        voigt_matrix,
        voigt_tensor,
    )

    split, f_o, K_o, s = _case("MooneyRivlin", 5)
    M = np.diag([1, 1, 1, 2, 2, 2.0])
    P, A = cell_piola(split)
    CC = cell_tensors(P, A, split.F).CC
    K = K_o + material_stiffness(split, voigt_tensor(M @ voigt_matrix(CC) @ M.T) - CC)
    found = voigt_map_findings(split, _misread_force(split, M), K, f_o, K_o, s, DOUBLE)
    assert [x.code for x in found] == ["voigt-map"] and found[0].strength == "explains", found
    assert found[0].title.startswith("the rows of B"), found[0].title


def test_the_stress_of_the_geometric_stiffness_unpacked_with_its_shears_halved_is_named():
    from conformance.diagnosis.voigt_maps import (
        _mapped,
        geometric_stiffness,
        tangent_slip_findings,
    )

    split, f_o, K_o, s = _case("Yeoh", 6)
    P, A = cell_piola(split)
    S = cell_tensors(P, A, split.F).S
    K = K_o + geometric_stiffness(split, _mapped(S, np.diag([1, 1, 1, 0.5, 0.5, 0.5])) - S)
    found = tangent_slip_findings(split, f_o, K, f_o, K_o, s, DOUBLE)
    assert [x.code for x in found] == ["voigt-geometric-stress"], [x.title for x in found]
    assert "halved" in found[0].title


def _misread_cauchy_force(split, M):
    """An updated-Lagrangian engine's force, f_a = -v B^T s of the Cauchy stress's Voigt vector
    mapped by M (its spatial B rows in another order), computed here from F and S.
    """
    P, A = cell_piola(split)
    S = cell_tensors(P, A, split.F).S
    J = np.linalg.det(split.F)
    sigma = split.F @ S @ split.F.swapaxes(1, 2) / J[:, None, None]
    v = np.stack([sigma[:, i, j] for i, j in VOIGT], axis=1) @ M.T
    s2 = np.zeros_like(sigma)
    for a, (i, j) in enumerate(VOIGT):
        s2[:, i, j] = s2[:, j, i] = v[:, a]
    g = split.D @ np.linalg.inv(split.F)
    fe = -(J * split.V0)[:, None, None] * np.einsum("mkj,maj->mak", s2, g)
    return assemble(split.cells, split.n, fe, None)[0]


def test_a_spatial_b_matrix_with_two_shear_rows_exchanged_is_named_on_the_cauchy_stress():
    split, f_o, K_o, s = _case("ArrudaBoyce", 3)
    M = np.eye(6)[[0, 1, 2, 3, 5, 4]]  # s_23 and s_13 exchanged
    f = _misread_cauchy_force(split, M)
    (found,) = voigt_map_findings(split, f, K_o, f_o, K_o, s, DOUBLE)
    assert found.title.startswith("the Cauchy stress:"), found.title
    assert "s_23 holds S_13; s_13 holds S_23" in found.title
    # the second Piola stress read so is another force: not this one
    assert not voigt_map_findings(split, _misread_force(split, M), K_o, f_o, K_o, s, DOUBLE)[
        0
    ].title.startswith("the Cauchy stress")
