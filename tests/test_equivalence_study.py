"""The equivalence study's typed result: checks that can fail, NOT RUN without dolfinx, quick
left-outs, and a reproduce line that parses back to the selection that ran. A stand-in oracle
(MJED itself, optionally scaled) keeps these tests independent of dolfinx.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import parse_reproduce

import meshes
import mjed
import reference_fem
from common.cases import DEFAULT_MATERIALS
from common.result import Status, exit_code
from common.states import state_names
from comparisons.cli import main
from comparisons.equivalence.study import equivalence_study


class _ScaledMJED:
    """An 'oracle' returning MJED's own force and stiffness times ``scale`` (1: exact agreement)."""

    scale = 1.0

    def __init__(self, points, cells, material):
        self.field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), material)

    def force(self, x):
        return self.scale * self.field.force(x)

    def stiffness(self, x):
        return self.scale * self.field.stiffness(x)


class _Off(_ScaledMJED):
    scale = 1.0 + 1e-6


def _single_tet():
    points, cells, label = meshes.resolve("single-tet")
    return [(label, points, cells)]


MATS = (DEFAULT_MATERIALS["NeoHookean"], DEFAULT_MATERIALS["Ogden"])


def test_agreement_passes_with_every_check_measured():
    r = equivalence_study(_single_tet(), MATS, ["rest", "random"], oracle_factory=_ScaledMJED)
    assert r.status is Status.PASSED and r.complete_pass and exit_code([r]) == 0
    assert [c.passed for c in r.checks] == [True] * 5
    assert set(r.data) == {"cases", "uniaxial_closed_form", "ogden_sofa_tangent_error"}
    assert len(r.data["cases"]) == 4 and r.data["uniaxial_closed_form"]  # closed form on cube-small
    assert set(r.data["ogden_sofa_tangent_error"]) == {"single-tet"}


def test_a_case_off_by_1e_6_fails_and_is_named():
    r = equivalence_study(_single_tet(), MATS, ["random"], oracle_factory=_Off)
    assert r.status is Status.FAILED and exit_code([r]) == 1
    assert (
        "2 of 2 cases outside the tolerances" in r.reason
        and "NeoHookean on single-tet, random" in r.reason
    )
    assert r.checks[0].passed is False and r.checks[1].measured == pytest.approx(1e-6, rel=1e-3)


def test_a_nan_error_fails_whatever_its_place(monkeypatch):
    from comparisons.equivalence import study as equivalence

    real = equivalence.compare_arrays
    monkeypatch.setattr(equivalence, "compare_arrays", lambda *a: (float("nan"),) + real(*a)[1:])
    r = equivalence_study(_single_tet(), MATS[:1], ["rest", "random"], oracle_factory=_ScaledMJED)
    assert r.status is Status.FAILED and r.checks[0].passed is False


def test_quick_meshes_are_not_covered():
    r = equivalence_study(_single_tet(), MATS[:1], ["rest"], quick=True, oracle_factory=_ScaledMJED)
    assert r.status is Status.PASSED and r.partial and exit_code([r]) == 3
    assert "cube-paper" in r.not_covered[0]


def test_without_dolfinx_the_study_is_not_run_and_the_command_exits_3(monkeypatch, capsys):
    monkeypatch.setattr(reference_fem, "dolfinx_available", lambda: False)
    r = equivalence_study(_single_tet(), MATS, ["rest"])
    assert r.status is Status.NOT_RUN and "dolfinx" in r.reason
    assert main(["equivalence", "--mesh", "single-tet"]) == 3
    assert "NOT RUN" in capsys.readouterr().out
    assert main(["equivalence", "--mesh", "single-tet", "--allow-incomplete"]) == 0


@pytest.mark.parametrize("oracle, code", [(_ScaledMJED, 0), (_Off, 1)])
def test_the_command_prints_writes_and_exits_by_the_policy(
    monkeypatch, tmp_path, capsys, oracle, code
):
    monkeypatch.setattr(reference_fem, "dolfinx_available", lambda: True)
    monkeypatch.setattr(reference_fem, "UFLOracle", oracle)
    out = tmp_path / "eq.json"
    assert (
        main(
            [
                "equivalence",
                "--material",
                "NeoHookean",
                "--mesh",
                "single-tet",
                "--states",
                "shear",
                "--json",
                str(out),
            ]
        )
        == code
    )
    written = json.loads(out.read_text())
    assert written["status"] == ("passed" if code == 0 else "failed")
    assert {"cases", "uniaxial_closed_form", "ogden_sofa_tangent_error"} <= set(written["data"])
    assert ("FAILED" in capsys.readouterr().out) == (code == 1)


def test_the_reproduce_line_parses_back_to_what_ran(tmp_path):
    path = tmp_path / "organ with space.vtu"
    points, cells = meshes.load("single-tet")
    meshes.write_mesh(str(path), points, cells)
    selection = _single_tet() + [(str(path), points, cells)]
    r = equivalence_study(selection, MATS, ["shear", "rest"], oracle_factory=_ScaledMJED)
    args = parse_reproduce(r.command)
    assert (args["command"], args["material"], args["mesh"], args["states"]) == (
        "equivalence",
        "NeoHookean,Ogden",
        f"single-tet,{path}",
        "shear,rest",
    )
    everything = equivalence_study(
        _single_tet(),
        tuple(DEFAULT_MATERIALS.values()),
        list(state_names()),
        oracle_factory=_ScaledMJED,
    )
    assert parse_reproduce(everything.command)["material"] == "all"
    assert parse_reproduce(everything.command)["states"] == "all"


def test_a_material_the_command_line_cannot_set_is_said_in_a_comment():
    custom = mjed.materials.NeoHookean(mu=1.0, lam=2.0)
    r = equivalence_study(_single_tet(), (custom,), ["rest"], oracle_factory=_ScaledMJED)
    assert "# custom parameters for NeoHookean" in r.command
    assert np.isfinite(r.checks[0].measured)


def test_sofa_ogden_tangent_table_has_an_exact_control_row_and_inexact_others():
    # alpha 2 makes the spectral power linear in C: the coaxial tangent is then exact, a row
    # that would catch a table comparing the wrong matrices; the others differ once deformed.
    from comparisons.equivalence.study import OGDEN_TANGENT_ALPHAS, _ogden_tangent
    from meshes import catalog

    points, cells, label = catalog.resolve("single-tet")
    ogden = mjed.materials.Ogden(mu=1e3, alpha=3.0, k0=1e4)
    table = _ogden_tangent(
        [(label, mjed.TetMesh(points, cells))], [ogden], ["rest", "shear", "random"]
    )[label]
    assert list(table) == ["alpha 3", *(f"alpha {a:g}" for a in OGDEN_TANGENT_ALPHAS)]
    assert max(table["alpha 2"].values()) <= 1e-14
    for alpha in ("alpha 3", "alpha -2", "alpha 6"):
        assert table[alpha]["rest"] <= 1e-14 and table[alpha]["random"] > 1e-6
