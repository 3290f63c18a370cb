"""A total-Lagrangian assembly on the first Piola stress with one mistake
(conformance.diagnosis.piola_assembly), and an element matrix laid out in another index order
(conformance.diagnosis.elements.order_findings). Each mistaken engine is a small St Venant-
Kirchhoff engine of this module's own (S and CC in closed form, P = F S, A = delta S + F CC F,
f_a = -V P G_a, K_ab = V G_a A G_b), checked against MJED as the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import mjed_split, stretched_state

from conformance.diagnosis.elements import assemble, cell_kinematics, order_findings
from conformance.diagnosis.piola_assembly import piola_findings
from conformance.judge.compare import DOUBLE
from mjed.materials import StVenantKirchhoff

MU, LAM = 3448.0, 31034.0
EYE = np.eye(3)

#: The right engine's pieces, each replaceable by a mistake.
RIGHT = {
    "P": lambda F, S: F @ S,
    "geo": lambda F, S: np.einsum("ik,mJL->miJkL", EYE, S),
    "mat": lambda F, CC: np.einsum("miI,mIJKL,mkK->miJkL", F, CC, F),
    "Ke": "maJ,miJkL,mbL->maibk",
}


def _engine(points, cells, x, **mistake):
    """Force (n, 3) and stiffness of this module's total-Lagrangian SVK engine, with the pieces
    in ``mistake`` (keys of RIGHT) replaced.
    """
    parts = {**RIGHT, **mistake}
    V, G, F = cell_kinematics(points, cells, x)
    E = 0.5 * (np.swapaxes(F, 1, 2) @ F - EYE)
    S = LAM * np.trace(E, axis1=1, axis2=2)[:, None, None] * EYE + 2.0 * MU * E
    CC = LAM * np.einsum("IJ,KL->IJKL", EYE, EYE) + MU * (
        np.einsum("IK,JL->IJKL", EYE, EYE) + np.einsum("IL,JK->IJKL", EYE, EYE)
    )
    CC = np.broadcast_to(CC, (len(cells), 3, 3, 3, 3))
    P = parts["P"](F, S)
    A = parts["geo"](F, S) + parts["mat"](F, CC)
    fe = -V[:, None, None] * np.einsum("miJ,maJ->mai", P, G)
    Ke = V[:, None, None, None, None] * np.einsum(parts["Ke"], G, A, G)
    return assemble(cells, len(points), fe, Ke.reshape(-1, 12, 12))


def _case(seed=0, uniaxial=False, **mistake):
    """(split, the mistaken engine's f and K, the oracle's f_o, K_o, scales)."""
    points, cells, x = stretched_state(seed, uniaxial)
    split, f_o, K_o, s = mjed_split(StVenantKirchhoff(mu=MU, lam=LAM), points, cells, x)
    f, K = _engine(points, cells, x, **mistake)
    return split, f, K, f_o, K_o, s


def _codes(found):
    return [x.code for x in found]


def test_the_right_engine_is_the_oracle_and_nothing_is_named():
    split, f, K, f_o, K_o, s = _case()
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max()
    assert abs(K - K_o).max() <= 1e-9 * abs(K_o).max()
    assert piola_findings(split, f, K, s, DOUBLE) == []
    assert piola_findings(split, f_o, K_o * 1.01, s, DOUBLE) == []  # a factor: none of these


def test_piola_stress_as_s_f_is_named_and_s_f_transposed_is_not_it():
    split, f, K, *_, s = _case(P=lambda F, S: S @ F)
    found = piola_findings(split, f, K, s, DOUBLE)
    assert _codes(found) == ["piola-assembly-piola-SF"], found
    assert "S F instead of F S" in found[0].title
    # nearby: S F^T in the force is another variant, never S F
    split, f, K, *_, s = _case(P=lambda F, S: S @ np.swapaxes(F, 1, 2))
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == ["piola-assembly-piola-SFt"]


def test_piola_stress_as_s_f_with_its_geometric_part_is_told_from_the_force_only_one():
    """S F in the force and its derivative at fixed S, S_ik delta_JL, as the geometric part."""
    split, f, K, *_, s = _case(
        P=lambda F, S: S @ F, geo=lambda F, S: np.einsum("mik,JL->miJkL", S, EYE)
    )
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == ["piola-assembly-piola-SF-geometric"]
    # nearby: the swapped geometric part with the force right is its own variant
    split, f, K, *_, s = _case(geo=lambda F, S: np.einsum("mik,JL->miJkL", S, EYE))
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == ["piola-assembly-geometric-swapped"]


def test_uniaxial_state_s_f_equals_f_s_and_nothing_is_claimed():
    """F and S diagonal: S F = F S, the variant predicts the oracle and explains nothing."""
    split, f, K, f_o, K_o, s = _case(uniaxial=True, P=lambda F, S: S @ F)
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max()
    assert piola_findings(split, f, K, s, DOUBLE) == []


def test_geometric_part_with_p_for_s_is_named_and_doubled_is_not_it():
    split, f, K, *_, s = _case(geo=lambda F, S: np.einsum("ik,mJL->miJkL", EYE, F @ S))
    found = piola_findings(split, f, K, s, DOUBLE)
    assert _codes(found) == ["piola-assembly-geometric-piola"], found
    assert "with the first Piola stress P = F S instead of S" in found[0].title
    split, f, K, *_, s = _case(geo=lambda F, S: 2.0 * np.einsum("ik,mJL->miJkL", EYE, S))
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == ["piola-assembly-geometric-doubled"]


@pytest.mark.parametrize(
    "left, right, code",
    [
        ("mIi", "mKk", "material-F-transposed"),
        ("mIi", "mkK", "material-F-transposed-left"),
        ("miI", "mKk", "material-F-transposed-right"),
    ],
)
def test_material_part_contracted_with_f_transposed_names_the_sides(left, right, code):
    split, f, K, *_, s = _case(
        seed=1, mat=lambda F, CC: np.einsum(f"{left},mIJKL,{right}->miJkL", F, CC, F)
    )
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == [f"piola-assembly-{code}"]


def test_gradients_swapped_in_the_element_is_named_and_cc_pairs_are_not_it():
    split, f, K, *_, s = _case(Ke="maL,miJkL,mbJ->maibk")
    found = piola_findings(split, f, K, s, DOUBLE)
    assert _codes(found) == ["piola-assembly-gradients-swapped"], found
    split, f, K, *_, s = _case(mat=lambda F, CC: np.einsum("miI,mIKJL,mkK->miJkL", F, CC, F))
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == ["piola-assembly-material-CC-pairs"]


def test_element_matrix_reshaped_from_another_einsum_layout_is_a_local_order_finding():
    """'mabik' reshaped as if 'maibk': the element layout, said by the local-order family."""
    split, f, K, *_, s = _case(Ke="maJ,miJkL,mbL->mabik")
    found = order_findings(split, f, K, s, DOUBLE)
    assert _codes(found) == ["element-layout"], found
    assert "'mabik'" in found[0].title and found[0].figures["layout"] == "abik"
    assert piola_findings(split, f, K, s, DOUBLE) == []  # not a mistake of P or A
    # nearby: another layout ('mbaik', the same as 'mabki' for a symmetric matrix) is that one
    split, f, K, *_, s = _case(Ke="maJ,miJkL,mbL->mbaik")
    found = order_findings(split, f, K, s, DOUBLE)
    assert [x.figures.get("layout") for x in found] == ["abki"], found
    # component-major stays a local order (elements' own), not a layout
    split, f, K, *_, s = _case(Ke="maJ,miJkL,mbL->miakb")
    assert _codes(order_findings(split, f, K, s, DOUBLE)) == ["element-order"]


def test_at_probes_the_force_alone_names_the_product():
    """A state where the force is right (uniaxial) and its probes, which give forces only: the
    S F engine's force at a probe is told from F^T S and S F^T by the force alone.
    """
    from conformance.diagnosis.elements import cell_piola
    from conformance.diagnosis.invariant_pieces import cell_tensors
    from conformance.diagnosis.piola_assembly import piola_force_findings
    from conformance.judge.compare import errors

    split, f, _, f_o, K_o, s = _case(seed=2, P=lambda F, S: S @ F)
    t = cell_tensors(*cell_piola(split), split.F)

    def matches(fp, K):
        if errors(fp, K_o, None, f_o, K_o, 0.0, s).force <= DOUBLE.force:
            return float("inf")
        e = errors(f, K_o, None, fp, K_o, 0.0, s).force
        return e if e <= DOUBLE.force else float("inf")

    found = piola_force_findings(split, t.S, matches)
    assert _codes(found) == ["piola-assembly-piola-SF"], found
    # S F^T: for an isotropic material the force of F transposed too, so both are said
    f = _engine(*stretched_state(2), P=lambda F, S: S @ np.swapaxes(F, 1, 2))[0]
    found = piola_force_findings(split, t.S, matches)
    assert sorted(_codes(found)) == ["piola-assembly-F-transposed", "piola-assembly-piola-SFt"]

    # S on the eigenvectors of b (R S R^T, F = R U): a spectral engine's frame slip
    def b_frame(F, S):
        W, _, Vt = np.linalg.svd(F)
        R = W @ Vt
        return F @ R @ S @ np.swapaxes(R, 1, 2)

    f = _engine(*stretched_state(2), P=b_frame)[0]
    assert _codes(piola_force_findings(split, t.S, matches)) == ["spectral-frame-b"]
    # nearby: the right force is none of them
    f = f_o
    assert piola_force_findings(split, t.S, matches) == []


def _b_engine(G):
    """The pieces of a Voigt engine whose strain-displacement matrix is built from G(F)."""
    return {
        "P": lambda F, S: G(F) @ S,
        "mat": lambda F, CC: np.einsum("miI,mIJKL,mkK->miJkL", G(F), CC, G(F)),
    }


def _linear(F):
    return np.broadcast_to(EYE, F.shape)


def test_b_matrix_without_its_initial_displacement_part_is_named_where_it_enters():
    """B = B_L0 (G = I) in the force and in B^T D B; in B^T D B alone the force is right."""
    split, f, K, *_, s = _case(**_b_engine(_linear))
    found = piola_findings(split, f, K, s, DOUBLE)
    assert _codes(found) == ["piola-assembly-b-matrix-linear"], found
    assert "strain-displacement" in found[0].title and "B_L0 alone" in found[0].title
    split, f, K, *_, s = _case(mat=_b_engine(_linear)["mat"])
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == [
        "piola-assembly-b-matrix-linear-stiffness"
    ]


@pytest.mark.parametrize(
    "G, code",
    [
        (lambda F: np.swapaxes(F, 1, 2), "transposed"),
        (lambda F: 2.0 * EYE - F, "reversed"),
        (lambda F: 0.5 * (EYE + F), "half"),
    ],
)
def test_b_matrix_built_from_another_displacement_gradient_names_which(G, code):
    split, f, K, *_, s = _case(seed=2, **_b_engine(G))
    assert _codes(piola_findings(split, f, K, s, DOUBLE)) == [f"piola-assembly-b-matrix-{code}"]


def test_uniaxial_state_b_l1_transposed_is_the_oracle_and_nothing_is_claimed():
    """H symmetric: B_L1 from H^T is B_L1, the variant predicts the oracle."""
    split, f, K, f_o, K_o, s = _case(uniaxial=True, **_b_engine(lambda F: np.swapaxes(F, 1, 2)))
    assert np.abs(f - f_o).max() <= 1e-9 * np.abs(f_o).max()
    assert piola_findings(split, f, K, s, DOUBLE) == []
