"""MJED against the UFL Galerkin oracle: per element on random single tetrahedra, and
assembled on the small cube in every state, for every declared material.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx (Debian: python3-dolfinx)")
pytestmark = pytest.mark.oracle

from conftest import perturbed, random_tetrahedron  # noqa: E402

import mjed  # noqa: E402
from common.cases import DEFAULT_MATERIALS  # noqa: E402
from common.states import state_names  # noqa: E402
from common.tolerances import FORCE_TOL, STIFFNESS_TOL  # noqa: E402
from comparisons.equivalence.study import compare_arrays, run_cases  # noqa: E402
from reference_fem import UFLOracle  # noqa: E402


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_per_element_agreement_on_random_tetrahedra(material, seed):
    rng = np.random.default_rng(seed)
    P, cells = random_tetrahedron(rng)
    field = mjed.HyperelasticForceField(mjed.TetMesh(P, cells), material)
    oracle = UFLOracle(P, cells, material)
    x = perturbed(P, rng, 0.1)
    Ke = field.element_stiffness(x)[0]  # local order: the cell's nodes
    dofs = (3 * cells[0][:, None] + np.arange(3)).ravel()
    K_o = oracle.stiffness(x).toarray()[np.ix_(dofs, dofs)]
    f_o = oracle.force(x)
    assert np.linalg.norm(Ke - K_o) <= STIFFNESS_TOL * np.linalg.norm(K_o)
    assert np.linalg.norm(field.force(x) - f_o) <= FORCE_TOL * np.linalg.norm(f_o)
    assert np.isclose(
        field.energy(x), oracle.energy(x), rtol=1e-12, atol=1e-14 * abs(oracle.energy(x))
    )


def test_assembled_agreement_on_the_small_cube_in_every_state():
    pytest.importorskip("meshio", reason="cube-small is stored as a gmsh file")
    import meshes

    points, cells = meshes.load("cube-small")
    results = list(
        run_cases(
            [("cube-small", points, cells)], list(DEFAULT_MATERIALS.values()), list(state_names())
        )
    )
    assert len(results) == len(DEFAULT_MATERIALS) * len(state_names())
    bad = [r for r in results if not r.passed]
    assert not bad, bad
    # The check is not vacuous: a 1e-6 change of a parameter is visible.
    mat = DEFAULT_MATERIALS["NeoHookean"]
    shifted = type(mat)(mu=mat.mu * (1 + 1e-6), lam=mat.lam)
    x = perturbed(points, np.random.default_rng(0), 0.01)
    f_m, K_m = mjed.HyperelasticForceField(
        mjed.TetMesh(points, cells), shifted
    ).force_and_stiffness(x)
    oracle = UFLOracle(points, cells, mat)
    fe, ke, _ = compare_arrays(f_m, K_m, oracle.force(x), oracle.stiffness(x), 0.1)
    assert fe > FORCE_TOL and ke > STIFFNESS_TOL


def test_ogden_alpha_four_against_invariant_oracle(rng):
    """Alpha = 4: mu/16 (I1b^2 - 2 I2b - 3); I1b^2 - 2 I2b = sum of squared isochoric
    eigenvalues.
    """
    P, cells = random_tetrahedron(rng)
    x = perturbed(P, rng, 0.1)
    field = mjed.HyperelasticForceField(
        mjed.TetMesh(P, cells), mjed.materials.Ogden(mu=2.0, alpha=4.0, k0=3.0)
    )
    F = np.einsum("mai,maj->mij", x[cells], field.mesh.D)[0]
    C = F.T @ F
    J = np.linalg.det(F)
    I1b = J ** (-2 / 3) * np.trace(C)
    I2b = J ** (-4 / 3) * 0.5 * (np.trace(C) ** 2 - np.trace(C @ C))
    W = 2.0 / 16 * (I1b**2 - 2 * I2b - 3) + 1.5 * np.log(J) ** 2
    assert np.isclose(field.energy(x), W * field.mesh.volumes[0], rtol=1e-12)
    oracle = UFLOracle(P, cells, mjed.materials.Ogden(mu=2.0, alpha=4.0, k0=3.0))
    assert np.linalg.norm(field.force(x) - oracle.force(x)) <= 1e-10 * np.linalg.norm(
        oracle.force(x)
    )


def test_cli_equivalence_writes_json_and_exits_zero(tmp_path, capsys):
    from comparisons.cli import main

    out = tmp_path / "eq.json"
    code = main(
        [
            "equivalence",
            "--material",
            "NeoHookean,Ogden",
            "--mesh",
            "single-tet",
            "--json",
            str(out),
        ]
    )
    assert code == 0
    written = json.loads(out.read_text())
    assert written["status"] == "passed" and written["key"] == "equivalence"
    data = written["data"]
    keys = {
        "material",
        "mesh",
        "state",
        "n_cells",
        "n_nodes",
        "force_rel_err",
        "stiffness_rel_err",
        "passed",
    }
    assert data["cases"] and all(keys <= set(c) for c in data["cases"])
    assert all(c["passed"] for c in data["cases"])
    assert len(data["cases"]) == 2 * len(state_names())
    assert set(data["ogden_sofa_tangent_error"]) == {"single-tet"}
    n = 2 * len(state_names())
    assert f"{n}/{n} cases pass" in capsys.readouterr().out


def test_cli_refuses_bad_input_before_work(tmp_path, capsys):
    from comparisons.cli import main

    assert main(["equivalence", "--material", "Rubber"]) == 2
    assert "unknown material 'Rubber'" in capsys.readouterr().err
    assert main(["equivalence", "--mesh", str(tmp_path / "missing.msh")]) == 2
    assert "missing.msh" in capsys.readouterr().err
    assert main(["equivalence", "--states", "twisted"]) == 2
    assert "unknown state" in capsys.readouterr().err
