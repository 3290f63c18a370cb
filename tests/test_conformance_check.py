"""mjed-verify check end to end: files, --command (time limit, crash), the Python helper, exit
codes.
"""

from __future__ import annotations

import json
import logging
import os
import sys

import numpy as np
import pytest

import mjed
from comparisons.cli import main
from mjed.materials import declaration_of, declarations
from reference_fem import dolfinx_available

pytestmark = [
    pytest.mark.oracle,
    pytest.mark.skipif(
        not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
    ),
]

logging.disable(logging.INFO)
ENGINE = os.path.join(os.path.dirname(__file__), "engines", "mjed_engine.py")


def mjed_impl(case):
    field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
    f, K = field.force_and_stiffness(case.positions)
    return f, K, field.energy(case.positions)


def _compute_kit(folder):
    """Play the user's engine on a kit: write every case's output (COO) with MJED."""
    from conformance.kit.exchange import write_output
    from conformance.kit.read import read_kit

    for c in read_kit(folder).cases:
        f, K, W = mjed_impl(c.input)
        write_output(os.path.join(folder, "cases", c.case_id, "output"), f, K, W)


def _report(out_dir):
    (run,) = os.listdir(out_dir)
    return os.path.join(out_dir, run), json.load(open(os.path.join(out_dir, run, "results.json")))


def test_files_mode_passes_then_reports_bad_cases(tmp_path, capsys):
    kit = str(tmp_path / "kit")
    assert (
        main(["export", kit, "--material", "NeoHookean,Costa", "--states", "uniaxial,random"]) == 0
    )
    _compute_kit(kit)
    assert main(["check", kit, "--out", str(tmp_path / "r1"), "--quiet"]) == 0
    folder, res = _report(tmp_path / "r1")
    assert res["exit_code"] == 0 and len(res["cases"]) == 4
    assert os.path.isfile(os.path.join(folder, "index.html"))

    # One NaN, one missing output, one wrong node count: exit 2, each named; the fourth still
    # passes.
    outs = os.path.join(kit, "cases")
    f = np.fromfile(os.path.join(outs, "NeoHookean.single-tet.uniaxial", "output", "force.f64"))
    f[2] = np.nan
    f.tofile(os.path.join(outs, "NeoHookean.single-tet.uniaxial", "output", "force.f64"))
    os.remove(os.path.join(outs, "NeoHookean.single-tet.random", "output", "force.f64"))
    np.zeros(9).tofile(os.path.join(outs, "Costa.single-tet.uniaxial", "output", "force.f64"))
    json_path = str(tmp_path / "res.json")
    assert main(["check", kit, "--out", str(tmp_path / "r2"), "--json", json_path]) == 2
    text = capsys.readouterr().out
    assert (
        "case NeoHookean.single-tet.uniaxial: BAD INPUT: case NeoHookean.single-tet.uniaxial: "
        in text
    )
    assert "NeoHookean.single-tet.uniaxial/output/force.f64: 1 non-finite value(s)" in text
    assert "NeoHookean.single-tet.random/output/force.f64: file missing" in text
    assert (
        "Costa.single-tet.uniaxial/output/force.f64: 9 values (3 nodes), expected 3n = 12 for 4 "
        "nodes" in text
    )
    res = json.load(open(json_path))
    status = {c["case"]: c["status"] for c in res["cases"]}
    assert status["Costa.single-tet.random"] == "passed"
    assert sorted(status.values()).count("bad input") == 3
    # Nothing of the user's kit was touched.
    assert os.path.isfile(os.path.join(outs, "Costa.single-tet.random", "output", "force.f64"))


def test_files_mode_failure_exit_1_with_diagnosis_and_vtu(tmp_path, capsys):
    import meshio

    kit = str(tmp_path / "kit")
    assert (
        main(
            [
                "export",
                kit,
                "--material",
                "MooneyRivlin",
                "--mesh",
                "cube-small",
                "--states",
                "shear",
            ]
        )
        == 0
    )
    _compute_kit(kit)
    from conformance.kit.exchange import read_output, write_output

    out = os.path.join(kit, "cases", "MooneyRivlin.cube-small.shear", "output")
    o = read_output(out, 186, "x")
    for name in os.listdir(out):
        os.remove(os.path.join(out, name))
    write_output(
        out, o.force, 2 * o.stiffness, o.energy, layout="csr"
    )  # a factor 2 on the stiffness only
    assert main(["check", kit, "--out", str(tmp_path / "r")]) == 1
    assert "stiffness only scaled: factor 2" in capsys.readouterr().out
    folder, res = _report(tmp_path / "r")
    vtu = os.path.join(folder, res["fields"]["MooneyRivlin.cube-small.shear"])
    m = meshio.read(vtu)
    assert m.point_data["node_error"].shape == (186,) and m.point_data["node_error"].max() > 1e-3
    html = open(os.path.join(folder, "index.html")).read()
    assert "fields/MooneyRivlin.cube-small.shear.vtu" in html and "factor 2" in html


def test_command_mode_time_limit_and_crash(tmp_path, capsys):
    py = sys.executable
    args = ["--material", "NeoHookean", "--states", "rest", "--timeout", "3", "--quiet"]
    assert (
        main(
            [
                "check",
                "--command",
                f"{py} {ENGINE} {{input}} {{output}}",
                "--out",
                str(tmp_path / "ok"),
            ]
            + args
        )
        == 0
    )
    assert (
        main(
            [
                "check",
                "--command",
                f"{py} {ENGINE} {{input}} {{output}} --mistake hang",
                "--out",
                str(tmp_path / "hang"),
            ]
            + args
        )
        == 2
    )
    _, res = _report(tmp_path / "hang")
    assert "ran past the time limit of 3 s and was killed" in res["cases"][0]["message"]
    assert (
        main(
            [
                "check",
                "--command",
                f"{py} {ENGINE} {{input}} {{output}} --mistake crash",
                "--out",
                str(tmp_path / "crash"),
            ]
            + args
        )
        == 2
    )
    _, res = _report(tmp_path / "crash")
    msg = res["cases"][0]["message"]
    assert "failed (exit code 139)" in msg and "segmentation fault in assemble() (simulated)" in msg
    assert (
        main(
            [
                "check",
                "--command",
                f"{py} {ENGINE} {{input}} {{output}} --mistake force-sign",
                "--out",
                str(tmp_path / "sign"),
            ]
            + args[:-1]
        )
        == 1
    )
    # At rest f = 0 equals -0: only the probes can see the flipped sign, and they do.
    _, res = _report(tmp_path / "sign")
    assert res["cases"][0]["errors"]["force"] == 0.0
    codes = [f["code"] for f in res["cases"][0]["findings"]]
    assert codes == ["force-wrong-nearby", "inconsistent-stiffness"]


def test_command_mode_names_the_sign(tmp_path, capsys):
    py = sys.executable
    assert (
        main(
            [
                "check",
                "--command",
                f"{py} {ENGINE} {{input}} {{output}} --mistake force-sign",
                "--material",
                "NeoHookean",
                "--states",
                "uniaxial",
                "--out",
                str(tmp_path / "r"),
            ]
        )
        == 1
    )
    assert "force sign flipped" in capsys.readouterr().out


def test_bad_command_template_is_input_error(tmp_path, capsys):
    assert main(["check", "--command", "my_engine {input}", "--out", str(tmp_path)]) == 2
    assert "must contain {output}" in capsys.readouterr().err
    assert not os.listdir(tmp_path)
    assert (
        main(
            [
                "check",
                "--command",
                "/nonexistent/engine {input} {output}",
                "--states",
                "rest",
                "--material",
                "NeoHookean",
                "--out",
                str(tmp_path / "r"),
                "--quiet",
            ]
        )
        == 2
    )
    _, res = _report(tmp_path / "r")
    assert "cannot start '/nonexistent/engine'" in res["cases"][0]["message"]


def test_python_helper_passes_and_raises_with_the_diagnosis():
    from conformance import assert_matches_oracle

    run = assert_matches_oracle(
        mjed_impl, material="all", mesh="single-tet", states=("uniaxial", "random")
    )
    assert run.n_passed == 2 * len(declarations())

    def transposed_blocks(case):
        f, K, W = mjed_impl(case)
        return {
            "force": f,
            "stiffness": K.toarray().reshape(4, 3, 4, 3).transpose(0, 3, 2, 1).reshape(12, 12),
        }

    with pytest.raises(
        AssertionError,
        match=r"each 3x3 node block of K transposed \(K_ab\^T written for K_ab\) \[explains\]",
    ):
        assert_matches_oracle(transposed_blocks, material="Ogden", states=("triaxial",))


def test_python_helper_bad_results_are_named():
    from conformance.protocol import check_implementation

    def wrong_shape(case):
        f, K, W = mjed_impl(case)
        return f[:2], K

    run = check_implementation(wrong_shape, material="NeoHookean", states=("rest",), probes=False)
    assert run.exit_code == 2
    assert "force has 6 values (shape (2, 3)), expected (n, 3) = (4, 3)" in run.outcomes[0].message

    def raises(case):
        raise RuntimeError("engine blew up")

    run = check_implementation(raises, material="NeoHookean", states=("rest",), probes=False)
    assert "implementation raised RuntimeError: engine blew up" in run.outcomes[0].message


def test_user_energy_checked_through_the_helper():
    """An engine written for 'mu/2 (I1b - 3) + K/2 (J - 1)^2' (the common penalty form) passes
    against the
    same user energy, and fails against MooneyRivlin's (ln J)^2 bulk term, named as a volumetric
    difference.
    """
    from conformance_mutations import MATERIAL, broken_engine

    from conformance import assert_matches_oracle, check_implementation
    from reference_fem.user_energy import UserEnergy

    c1, c2, k0 = MATERIAL.c1, MATERIAL.c2, MATERIAL.k0
    energy = UserEnergy("c1*(I1b-3) + c2*(I2b-3) + k/2*(J-1)**2", {"c1": c1, "c2": c2, "k": k0})
    engine = broken_engine("(J-1)^2 bulk term")
    assert_matches_oracle(
        lambda case: _as(engine, case, MATERIAL),
        energy=energy,
        mesh="cube-small",
        states=("random",),
    )
    run = check_implementation(engine, material=MATERIAL, mesh="cube-small", states=("random",))
    assert run.outcomes[0].diagnosis.causes[0].code == "volumetric"


def _as(engine, case, model):
    from conformance.kit.spec import CaseInput

    return engine(CaseInput(case.case_id, case.points, case.cells, case.positions, model))


@pytest.mark.parametrize("name", [d.name for d in declarations()])
def test_stiffness_parts_sum_to_the_oracle(name):
    from scipy.sparse.linalg import norm

    import meshes
    from common.cases import DEFAULT_MATERIALS
    from common.states import apply_state
    from conformance.judge.oracle import OracleCache
    from conformance.kit.spec import CaseInput

    pts, cells, _ = meshes.resolve("single-tet")
    case = CaseInput("x", pts, cells, apply_state("random", pts, cells), DEFAULT_MATERIALS[name])
    cache = OracleCache()
    K = cache.reference(case).stiffness
    parts = cache.parts(case)
    assert norm(parts.total() - K) <= 1e-13 * norm(K)
    if declaration_of(type(case.model)).volumetric is not None:
        assert parts["geometric_volumetric"] is not None and norm(parts["material_volumetric"]) > 0


def test_user_energy_tangent_split_names_the_volumetric_part():
    """The J-only terms of a user energy are found in its expression; a doubled volumetric
    tangent is named.
    """
    from scipy.sparse.linalg import norm

    import meshes
    from common.states import apply_state
    from conformance.judge.oracle import OracleCache
    from conformance.judge.parts import volumetric_user_energy
    from conformance.kit.spec import CaseInput
    from conformance.protocol import check_implementation
    from reference_fem.user_energy import UserEnergy

    energy = UserEnergy("mu/2*(I1b-3) + K/2*(J-1)**2", {"mu": 1e3, "K": 1e4})
    assert volumetric_user_energy(energy).expression == "+(K / 2 * (J - 1) ** 2)"
    pts, cells, _ = meshes.resolve("cube-small")
    cache = OracleCache()
    x = apply_state("random", pts, cells)
    ref = cache.reference(CaseInput("x", pts, cells, x, energy))
    vol = UserEnergy("K/2*(J-1)**2", {"K": 1e4})

    def doubled_volumetric(case):
        K_vol = cache.reference(
            CaseInput("v", case.points, case.cells, case.positions, vol)
        ).stiffness
        r = cache.reference(case)
        return r.force, r.stiffness + K_vol

    run = check_implementation(
        doubled_volumetric, energy=energy, mesh="cube-small", states=("random",), probes=False
    )
    cause = run.outcomes[0].diagnosis.causes[0]
    assert cause.code == "tangent-part" and cause.figures["parts"] == [
        "volumetric tangent (J-only terms)"
    ], cause.text()
    parts = cache.parts(CaseInput("x", pts, cells, x, energy))
    assert norm(parts.total() - ref.stiffness) <= 1e-13 * norm(ref.stiffness)


def test_kit_run_through_a_command_leaves_the_kit_untouched(tmp_path):
    kit = tmp_path / "kit"
    assert (
        main(["export", str(kit), "--material", "VerondaWestmann", "--states", "compression"]) == 0
    )
    before = sorted(p for p in kit.rglob("*"))
    assert (
        main(
            [
                "check",
                str(kit),
                "--command",
                f"{sys.executable} {ENGINE} {{input}} {{output}}",
                "--out",
                str(tmp_path / "r"),
                "--quiet",
            ]
        )
        == 0
    )
    assert sorted(p for p in kit.rglob("*")) == before  # outputs went to the report directory
    folder, _ = _report(tmp_path / "r")
    assert os.path.isfile(
        os.path.join(folder, "outputs", "VerondaWestmann.single-tet.compression", "force.f64")
    )


def test_costa_with_a_frame_per_cell():
    import meshes
    from conformance import assert_matches_oracle
    from mjed.materials import Costa

    pts, cells, _ = meshes.resolve("cube-small")
    rng = np.random.default_rng(4)
    Q = np.linalg.qr(rng.standard_normal((len(cells), 3, 3)))[0]
    Q *= np.sign(np.linalg.det(Q))[:, None, None]
    costa = Costa(
        a=800.0, k0=3.0e4, b_ff=18.5, b_fs=2.8, b_ss=3.6, b_fn=2.0, b_sn=1.6, b_nn=3.6, frame=Q
    )
    assert_matches_oracle(
        mjed_impl, material=costa, mesh="cube-small", states=("triaxial", "random")
    )


def test_volume_weighting_missing_is_named():
    from conformance.protocol import check_implementation

    def per_volume(case):
        f, K, W = mjed_impl(case)
        V0 = abs(np.linalg.det(case.points[case.cells[0, 1:]] - case.points[case.cells[0, 0]])) / 6
        return f / V0, K / V0

    import meshes

    pts, cells, _ = meshes.resolve("single-tet")  # the unit tetrahedron: V0 = 1/6, so 1/V0 = 6
    run = check_implementation(
        per_volume, material="ArrudaBoyce", mesh=(pts, cells), states=("shear",), probes=False
    )
    title = run.outcomes[0].diagnosis.causes[0].title
    assert (
        "factor 6 (the 1/6 of the tetrahedron volume missing) or volume weighting missing" in title
    )
    run = check_implementation(
        per_volume, material="ArrudaBoyce", mesh=(2 * pts, cells), states=("shear",), probes=False
    )
    cause = run.outcomes[0].diagnosis.causes[0]
    assert (
        cause.code == "scale"
        and "volume weighting missing (engine = oracle / V0, V0 = 1.333e+00" in cause.title
    )


def test_energy_offset_is_reported_as_a_density():
    """W without its '- 3': force and stiffness match, the energy is off by 3 mu/2 per unit
    volume.
    """
    from conformance.protocol import check_implementation

    def no_minus_three(case):
        f, K, W = mjed_impl(case)
        V = (
            abs(
                np.linalg.det(case.points[case.cells[:, 1:]] - case.points[case.cells[:, :1]])
            ).sum()
            / 6
        )
        return f, K, W + 1.5 * case.model.mu * V

    run = check_implementation(
        no_minus_three, material="NeoHookean", states=("uniaxial",), probes=False
    )
    d = run.outcomes[0].diagnosis
    assert d.verdict == "failed" and d.findings[0].code == "energy"
    assert d.findings[0].figures["offset_density"] == pytest.approx(1.5 * 3448.2759, rel=1e-9)


def test_oracle_refusal_is_reported_for_that_case():
    """A user energy that is not finite in one state: that case is bad input, named; the other
    still runs.
    """
    from conformance.protocol import check_implementation
    from reference_fem.user_energy import PrestressWarning, UserEnergy

    with pytest.warns(PrestressWarning):  # sqrt(1.25 - J) has a slope at rest; NaN for J > 1.25
        energy = UserEnergy(
            "mu/2*(I1-3) - mu*ln(J) + k*sqrt(1.25-J)", {"mu": 1e3, "k": 1.0}, None, "sqrt"
        )

    def engine(case):
        n = len(case.points)
        return np.zeros((n, 3)), np.zeros((3 * n, 3 * n))

    run = check_implementation(
        engine, energy=energy, mesh="single-tet", states=("rest", "uniaxial"), probes=False
    )
    rest, uniaxial = run.outcomes
    assert rest.status == "failed" and rest.diagnosis is not None
    assert uniaxial.status == "bad input" and run.exit_code == 2
    assert uniaxial.message.startswith(
        "case sqrt.single-tet.uniaxial: the oracle cannot evaluate this case: UFL oracle: "
        "non-finite"
    )
