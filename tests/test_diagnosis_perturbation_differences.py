"""A numerical spatial tangent whose perturbation of F is wrong
(conformance.diagnosis.perturbation_differences: SCHEMES, scheme_findings, read by
conformance.diagnosis.strain_differences.strain_difference_reading). The
engine is built here as a ported UMAT's driver does it: per cell the Kirchhoff stress of the
project's classical law, its DDSDDE column kl by forward differences under a perturbation of F
(Miehe's F + eps sym(e_k e_l) F, or a wrong one), over J eps, mirrored in (k, l), the Jaumann
terms removed, and K = v (grad N . c . grad N + grad N . sigma grad N I).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh
from diagnosis_stubs import CaseStub, OutputStub, classical_cells

from common.cases import default_material
from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.elements import assemble, cell_piola, element_split
from conformance.diagnosis.findings import FULL, OBSERVED, Finding
from conformance.diagnosis.invariant_pieces import cell_tensors
from conformance.diagnosis.perturbation_differences import scheme_tangent
from conformance.diagnosis.spatial_tangent import spatial_cells
from conformance.diagnosis.strain_differences import strain_difference_reading
from conformance.judge.compare import DOUBLE, errors, scales
from conformance.judge.oracle import Reference

PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))


def _sym(k, ll):
    E = np.zeros((3, 3))
    E[k, ll] += 0.5
    E[ll, k] += 0.5
    return E


def _unit(k, ll):
    E = np.zeros((3, 3))
    E[k, ll] = 1.0
    return E


#: the engine's perturbation of F for pair (k, l): a function of (k, l, F) -> (m, 3, 3)
PERTURB = {
    "miehe": lambda k, ll, F: _sym(k, ll) @ F,
    "unsymmetrised": lambda k, ll, F: _unit(k, ll) @ F,
    "shear-doubled": lambda k, ll, F: (1.0 + (k != ll)) * _sym(k, ll) @ F,
    "shear-1.9": lambda k, ll, F: (1.0 + 0.9 * (k != ll)) * _sym(k, ll) @ F,
    "not-times-F": lambda k, ll, F: np.broadcast_to(_sym(k, ll), F.shape),
}


def _mesh():
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    x = points + 0.06 * np.random.default_rng(5).standard_normal(points.shape)
    return points, cells, x


def _engine(points, cells, x, model, eps: float, perturb: str):
    """(f, K, f_o, K_o): MJED's force, and K with the numerical DDSDDE of ``perturb``."""
    f_o, K_o, V0, D, F, J, tau_of = classical_cells(points, cells, x, model)
    tau = tau_of(F)
    sig = tau / J[:, None, None]
    Dj = np.zeros((len(cells), 3, 3, 3, 3))
    for k, ll in PAIRS:
        col = (tau_of(F + eps * PERTURB[perturb](k, ll, F)) - tau) / (eps * J[:, None, None])
        Dj[:, :, :, k, ll] = Dj[:, :, :, ll, k] = col
    d = np.eye(3)
    jaumann = 0.5 * (
        np.einsum("ik,mjl->mijkl", d, sig)
        + np.einsum("il,mjk->mijkl", d, sig)
        + np.einsum("jk,mil->mijkl", d, sig)
        + np.einsum("jl,mik->mijkl", d, sig)
    )
    c = Dj - jaumann
    gN = D @ np.linalg.inv(F)
    v = J * np.abs(V0)
    Km = np.einsum("maj,mijkl,mbl->maibk", gN, c, gN)
    Kg = np.einsum("maj,mjl,mbl->mab", gN, sig, gN)
    Ke = v[:, None, None, None, None] * (Km + np.einsum("mab,ik->maibk", Kg, d))
    K = assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke.reshape(-1, 12, 12))[1]
    return np.asarray(f_o), K, np.asarray(f_o), sp.csr_matrix(K_o)


def _reading(points, cells, x, model, f, K, f_o, K_o):
    """strain_difference_reading's diagnosis of an engine's (f, K) against MJED's (f_o, K_o)."""
    s = scales(0.5, 1.0, f_o, K_o)
    e = errors(f, K, None, f_o, K_o, 0.0, s)
    diag = Diagnosis("c", "failed", e, [Finding("unexplained", "unexplained", OBSERVED, "", {})])
    ref = Reference(0.0, f_o, K_o)
    case = CaseStub(points, cells, x, model)
    return strain_difference_reading(diag, case, OutputStub(f, K), ref, s)


def _read(perturb: str, eps: float = 1e-7, material: str = "MooneyRivlin"):
    points, cells, x = _mesh()
    model = default_material(material)
    return _reading(points, cells, x, model, *_engine(points, cells, x, model, eps, perturb))


def test_the_right_scheme_in_the_limit_is_the_oracle_spatial_tangent():
    import mjed

    points, cells, x = _mesh()
    model = default_material("NeoHookean")
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    f_o, K_o = field.force_and_stiffness(x)
    s = scales(0.5, 1.0, np.asarray(f_o), K_o)
    split = element_split(model, points, cells, x, np.asarray(f_o), K_o, s, DOUBLE)
    P, A = cell_piola(split)
    t = cell_tensors(P, A, split.F)
    c = spatial_cells(split, t.S, t.CC).c
    assert np.abs(scheme_tangent("miehe", P, A, split.F) - c).max() <= 1e-9 * np.abs(c).max()
    assert np.abs(scheme_tangent("unsymmetrised", P, A, split.F) - c).max() > 1e-3 * np.abs(c).max()


@pytest.mark.parametrize(
    "perturb, material",
    [("unsymmetrised", "MooneyRivlin"), ("shear-doubled", "NeoHookean"), ("not-times-F", "Yeoh")],
)
def test_a_wrong_perturbation_is_named_with_its_step(perturb, material):
    d = _read(perturb, material=material)
    top = d.findings[0]
    assert top.code == f"perturbation-scheme-{perturb}", [f.title for f in d.findings]
    assert "numerical (finite-difference) spatial tangent" in top.title
    assert abs(top.figures["step"] / 1e-7 - 1) < 0.05


def test_the_right_perturbation_with_a_coarse_step_is_not_named_a_wrong_one():
    d = _read("miehe", eps=1e-4)
    assert d.errors.stiffness > 1e-8
    codes = [f.code for f in d.findings]
    assert codes[0] == "perturbation-finite-difference", [f.title for f in d.findings]
    assert not any(c.startswith("perturbation-scheme") for c in codes)


def test_shear_columns_off_by_another_factor_are_not_the_doubled_step():
    d = _read("shear-1.9")
    assert d.errors.stiffness > 1e-3
    assert d.findings[0].code == "unexplained", [f.title for f in d.findings]


def _piola_engine(points, cells, x, model, h: float, central: bool):
    """(f, K, f_o, K_o): MJED's force, and K = V0 D A D with A = dP/dF by differences of
    P = tau F^-T in each component of F (a total-Lagrangian engine's numerical tangent).
    """
    f_o, K_o, V0, D, F, J, tau_of = classical_cells(points, cells, x, model)

    def P_of(Fs):
        return tau_of(Fs) @ np.linalg.inv(Fs).swapaxes(1, 2)

    P = P_of(F)
    A = np.empty((len(cells), 3, 3, 3, 3))
    for ll in range(3):
        for L in range(3):
            dF = np.zeros((3, 3))
            dF[ll, L] = h
            up = P_of(F + dF)
            A[:, :, :, ll, L] = (up - P_of(F - dF)) / (2 * h) if central else (up - P) / h
    Ke = np.abs(V0)[:, None, None, None, None] * np.einsum("maI,mkIlL,mbL->makbl", D, A, D)
    K = assemble(cells, points.shape[0], np.zeros((len(cells), 4, 3)), Ke.reshape(-1, 12, 12))[1]
    return np.asarray(f_o), K, np.asarray(f_o), sp.csr_matrix(K_o)


def test_differences_of_p_in_the_components_of_f_are_named_with_their_step():
    points, cells, x = _mesh()
    model = default_material("MooneyRivlin")
    for h, central, named in ((1e-4, False, True), (1e-2, True, False)):
        d = _reading(points, cells, x, model, *_piola_engine(points, cells, x, model, h, central))
        assert d.errors.stiffness > 1e-8
        codes = [f.code for f in d.findings]
        if named:
            assert codes[0] == "first-elasticity-finite-difference", [f.title for f in d.findings]
            assert abs(d.findings[0].figures["step"] / h - 1) < 1e-2
        else:
            assert "first-elasticity-finite-difference" not in codes


def test_a_step_so_small_that_its_round_off_shows_is_named_and_a_slip_beside_it_is_not():
    """P differenced in F with h = 3e-8: the quotient's cancellation is a visible part of the
    error (the fit explains less than 99 %), and what is left is the round-off predicted for
    that step; the same engine with a structured slip of that size added is not named.
    """
    points, cells, x = _mesh()
    model = default_material("MooneyRivlin")
    f, K, f_o, K_o = _piola_engine(points, cells, x, model, 6e-8, False)
    d = _reading(points, cells, x, model, f, K, f_o, K_o)
    lead = d.findings[0]
    assert lead.code == "first-elasticity-finite-difference", [f.title for f in d.findings]
    assert lead.figures["explained"] < 0.99  # named through the predicted round-off
    assert "round-off of P differenced" in lead.evidence
    assert abs(lead.figures["step"] / 6e-8 - 1) < 0.1
    D = K - K_o
    slipped = K + 0.3 * sp.linalg.norm(D) / sp.linalg.norm(K_o) * K_o  # a scaled tangent too
    d = _reading(points, cells, x, model, f, slipped, f_o, K_o)
    assert "first-elasticity-finite-difference" not in [f.code for f in d.findings]


def test_differences_are_read_where_the_only_cause_named_is_a_place():
    """A numerical tangent whose error a localisation has already claimed (a few stiff cells
    carry it): the difference readings still run, name the scheme first, and keep the
    localisation as an observation; where no scheme fits, the diagnosis is unchanged.
    """
    from types import SimpleNamespace

    from conformance.run import _differences_past_localisation, _localised_only

    points, cells, x = _mesh()
    model = default_material("MooneyRivlin")
    f, K, f_o, K_o = _piola_engine(points, cells, x, model, 1e-4, False)
    s = scales(0.5, 1.0, f_o, K_o)
    e = errors(f, K, None, f_o, K_o, 0.0, s)
    place = Finding("localised", "error localised to 8 node(s) / 2 cell(s)", FULL, "", {})
    diag = Diagnosis("c", "failed", e, [place])
    c = SimpleNamespace(
        read_causes=True,
        ci=CaseStub(points, cells, x, model),
        out=OutputStub(f, K),
        ref=Reference(0.0, f_o, K_o),
        s=s,
    )
    assert _localised_only(diag, c)
    d = _differences_past_localisation(diag, c)
    assert d.findings[0].code == "first-elasticity-finite-difference", d.text()
    assert [(f.code, f.strength) for f in d.findings[1:2]] == [("localised", OBSERVED)]
    c.out = OutputStub(f, K_o * (1 + 1e-6))  # not a scheme's error
    assert _differences_past_localisation(diag, c) is diag
