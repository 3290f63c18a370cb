"""Fibre frames in the kit (issue 25): a helical per-cell field for Costa, exported, read back,
used by the oracle and by the equivalence study, and the frame mistakes named by the diagnosis.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os

import numpy as np
import pytest

import meshes
import mjed
from common.cases import DEFAULT_MATERIALS
from common.frames import (
    HELIX,
    helix_frames,
    mid_wall_frame,
    permutation_distance,
    signed_permutations,
    with_default_frame,
)
from reference_fem import dolfinx_available

logging.disable(logging.INFO)  # FFCx logs every compilation

needs_oracle = pytest.mark.skipif(
    not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
)
COSTA = DEFAULT_MATERIALS["Costa"]


@pytest.fixture(scope="module")
def cube():
    points, cells, _ = meshes.resolve("cube-small")
    return points, cells


def test_helix_frames_are_right_handed_rotations_that_vary_through_the_wall(cube):
    points, cells = cube
    R = helix_frames(points, cells)
    assert R.shape == (len(cells), 3, 3)
    RtR = np.einsum("mki,mkj->mij", R, R)
    np.testing.assert_allclose(RtR, np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)
    # The fibre's angle in the wall plane (y, z) follows the depth along x, over most of -60..60.
    f = R[:, :, 0]
    depth = points[cells].mean(axis=1)[:, 0]
    angle = np.degrees(np.arctan2(f[:, 2], f[:, 1]))
    assert np.ptp(angle) > 100.0
    assert np.corrcoef(depth, angle)[0, 1] > 0.99
    assert len(np.unique(np.round(R.reshape(-1, 9), 12), axis=0)) > 10


def test_every_frame_is_far_from_the_identity_and_from_any_axis_permutation(cube):
    R = helix_frames(*cube)
    d = permutation_distance(R)
    assert d.min() > 0.8, d.min()  # 0.86 on cube-small: no relabelling of x, y, z comes near
    assert permutation_distance(mid_wall_frame())[0] > 0.8


def test_the_permutation_distance_sees_permutations_and_small_rotations():
    """The distance the test above relies on: zero on every signed permutation, small near one."""
    P = signed_permutations()
    assert len(P) == 48 and len({p.tobytes() for p in P}) == 48
    np.testing.assert_allclose(permutation_distance(P), 0.0, atol=1e-15)
    c, s = np.cos(0.1), np.sin(0.1)
    near = P[7] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert 0.0 < permutation_distance(near)[0] < 0.2


def test_the_field_turns_across_the_axis_it_is_given_and_refuses_a_bad_one(cube):
    from common.frames import HelixField

    points, cells = cube
    R = helix_frames(points, cells, HelixField(axis=1))
    depth = points[cells].mean(axis=1)[:, 1]
    f = R[:, :, 0]  # the wall plane is now (z, x): the fibre's angle follows the depth along y
    angle = np.degrees(np.arctan2(f[:, 0], f[:, 2]))
    assert np.corrcoef(depth, angle)[0, 1] > 0.99 and np.ptp(angle) > 100.0
    flat = points.copy()
    flat[:, 0] = 0.0  # no extent along the transmural axis: every cell at mid-wall
    np.testing.assert_allclose(helix_frames(flat, cells[:3]), np.stack([mid_wall_frame()] * 3))
    with pytest.raises(ValueError, match="axis must be 0, 1 or 2"):
        HelixField(axis=3)
    with pytest.raises(ValueError, match="two finite angles"):
        HelixField(helix=(0.0, float("nan")))


def test_only_a_frameless_costa_gets_the_default_field(cube):
    points, cells = cube
    given = with_default_frame(COSTA, points, cells)
    np.testing.assert_array_equal(given.frame, helix_frames(points, cells, HELIX))
    own = dataclasses.replace(COSTA, frame=np.eye(3))
    assert with_default_frame(own, points, cells) is own  # a frame the user chose is kept
    nh = DEFAULT_MATERIALS["NeoHookean"]
    assert with_default_frame(nh, points, cells) is nh


@pytest.mark.parametrize("state", ["fibre-stretch", "fibre-shear"])
@pytest.mark.parametrize("wrong", ["identity", "transposed", "first cell"])
def test_a_frame_mistake_shows_in_force_and_stiffness_of_the_fibre_states(cube, state, wrong):
    from common.states import apply_state

    points, cells = cube
    right = with_default_frame(COSTA, points, cells)
    R = right.frame
    other = {
        "identity": np.eye(3),
        "transposed": np.swapaxes(R, 1, 2).copy(),
        "first cell": R[0].copy(),
    }[wrong]
    mesh = mjed.TetMesh(points, cells)
    x = apply_state(state, points, cells)
    f, K = mjed.HyperelasticForceField(mesh, right).force_and_stiffness(x)
    mistaken = dataclasses.replace(COSTA, frame=other)
    g, L = mjed.HyperelasticForceField(mesh, mistaken).force_and_stiffness(x)
    assert np.linalg.norm(g - f) > 1e-3 * np.linalg.norm(f)
    assert abs(L - K).max() > 1e-3 * abs(K).max()


def test_the_kit_exports_the_frame_hashed_and_reads_it_back(tmp_path, cube):
    from conformance.kit.cases import build_cases
    from conformance.kit.exchange import FormatError
    from conformance.kit.read import read_kit
    from conformance.kit.write import write_kit

    points, cells = cube
    cases = build_cases(
        [COSTA, DEFAULT_MATERIALS["NeoHookean"]],
        [("cube-small", points, cells)],
        ["fibre-shear"],
        probes=1,
    )
    write_kit(str(tmp_path / "kit"), cases)
    manifest = json.loads((tmp_path / "kit" / "manifest.json").read_text())
    costa = next(e for e in manifest["cases"] if e["id"] == "Costa.cube-small.fibre-shear")
    assert "frame.f64" in costa["input_sha256"]
    nh = next(e for e in manifest["cases"] if e["id"] == "NeoHookean.cube-small.fibre-shear")
    assert "frame.f64" not in nh["input_sha256"]
    folder = tmp_path / "kit" / costa["input"]
    entry = json.loads((folder / "case.json").read_text())["arrays"]["frame"]
    assert entry == {"file": "frame.f64", "dtype": "<f8", "shape": [len(cells), 3, 3]}
    assert f"array frame frame.f64 <f8 {len(cells)} 3 3" in (folder / "case.txt").read_text()
    raw = np.fromfile(folder / "frame.f64", dtype="<f8").reshape(-1, 3, 3)
    np.testing.assert_array_equal(raw, helix_frames(points, cells))  # row-major, columns f, s, n

    kit = read_kit(str(tmp_path / "kit"))
    read = next(c for c in kit.cases if c.case_id == costa["id"])
    np.testing.assert_array_equal(read.input.model.frame, raw)

    tampered = raw.copy()
    tampered[3] = np.eye(3)
    os.chmod(folder / "frame.f64", 0o644)
    tampered.tofile(folder / "frame.f64")
    assert costa["id"] in read_kit(str(tmp_path / "kit")).errors
    with pytest.raises(FormatError):
        raise FormatError(read_kit(str(tmp_path / "kit")).errors[costa["id"]])


@pytest.fixture(scope="module")
def frame_runs():
    from conformance_mutations import FRAME_MATERIAL, FRAME_MUTATIONS, broken_frame_engine

    from conformance.protocol import check_implementation

    states = ("rest", "fibre-stretch", "fibre-shear")
    return {
        name: check_implementation(
            broken_frame_engine(name),
            material=FRAME_MATERIAL,
            mesh="cube-small",
            states=states,
            probes=False,
        )
        for name in FRAME_MUTATIONS
    }


@needs_oracle
@pytest.mark.oracle
@pytest.mark.parametrize(
    "mutation",
    [
        "frame-blind engine (identity frame)",
        "transposed rotation",
        "global axes (one frame for the mesh)",
        "fibre and sheet columns swapped",
    ],
)
def test_each_frame_mistake_fails_and_is_named(frame_runs, mutation):
    from conformance_mutations import FRAME_EXPECTED

    for outcome in frame_runs[mutation].outcomes:
        d = outcome.diagnosis
        assert outcome.status == "failed", d.text()
        codes = [f.code for f in d.causes]
        assert codes == [FRAME_EXPECTED[mutation]], d.text()
        assert d.causes[0].figures["residual"] <= 1e-10
        if FRAME_EXPECTED[mutation] == "frame-columns":  # which order, not only that one was wrong
            assert "the sheet, fibre, normal columns used as fibre" in d.causes[0].title
        if outcome.state != "rest":  # at rest every frame gives a zero force: only K can tell
            assert d.errors.force > 1e-4 and d.errors.stiffness > 1e-3, d.text()


@needs_oracle
@pytest.mark.oracle
def test_mjed_passes_the_costa_kit_with_its_frames_on_every_state(cube):
    """The project's engine held to the kit: the same per-cell frames, every state."""
    from common.states import state_names
    from conformance.protocol import check_implementation

    def engine(case):
        assert np.asarray(case.model.frame).shape == (len(case.cells), 3, 3)
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
        f, K = field.force_and_stiffness(case.positions)
        return f, K, field.energy(case.positions)

    run = check_implementation(engine, material=COSTA, mesh="cube-small", states=state_names())
    assert run.exit_code == 0, run.text()
    assert len(run.outcomes) == len(state_names())


@needs_oracle
@pytest.mark.oracle
def test_the_equivalence_study_uses_the_kits_frames(cube):
    from comparisons.equivalence.study import run_cases
    from reference_fem import UFLOracle

    points, cells = cube
    seen = []

    def oracle(pts, cls, material):
        seen.append(material)
        return UFLOracle(pts, cls, material)

    (result,) = run_cases(
        [("cube-small", points, cells)], [COSTA], ["fibre-shear"], oracle_factory=oracle
    )
    assert result.passed, result
    np.testing.assert_array_equal(seen[0].frame, helix_frames(points, cells))


@needs_oracle
@pytest.mark.oracle
def test_an_engine_command_reads_the_frame_and_one_that_does_not_is_named(tmp_path, capsys):
    """Through files: the engine process reads frame.f64; a process that ignores it is diagnosed."""
    import sys

    from comparisons.cli import main

    engine = os.path.join(os.path.dirname(__file__), "engines", "mjed_engine.py")
    args = ["--material", "Costa", "--mesh", "cube-small", "--states", "fibre-stretch", "--quiet"]
    assert (
        main(
            [
                "check",
                "--command",
                f"{sys.executable} {engine} {{input}} {{output}}",
                "--out",
                str(tmp_path / "ok"),
            ]
            + args
        )
        == 0
    )
    blind = f"{sys.executable} {engine} {{input}} {{output}} --mistake ignore-frame"
    assert (
        main(
            [
                "check",
                "--command",
                blind,
                "--out",
                str(tmp_path / "blind"),
                "--json",
                str(tmp_path / "blind.json"),
            ]
            + args
        )
        == 1
    )
    result = json.loads((tmp_path / "blind.json").read_text())
    (case,) = result["cases"]
    named = [f["code"] for f in case["findings"] if f["strength"] == "explains"]
    assert named == ["frame-ignored"], case


FIBRE_ENERGY = "mu/2*(I1b-3) + K/2*(J-1)**2 + k1/(2*k2)*(exp(k2*(I4-1)**2)-1) + c*(I5-I4**2)"
FIBRE_PARAMS = {"mu": 1.0e3, "K": 1.0e4, "k1": 2.0e3, "k2": 0.7, "c": 300.0}


def test_a_fibre_energy_without_a_direction_gets_the_field_in_the_kit(tmp_path, cube):
    from conformance.kit.cases import build_cases
    from conformance.kit.read import read_kit
    from conformance.kit.write import write_kit
    from reference_fem.user_energy import UserEnergy

    points, cells = cube
    energy = UserEnergy(FIBRE_ENERGY, FIBRE_PARAMS, name="fibres")
    one = UserEnergy(FIBRE_ENERGY, FIBRE_PARAMS, fibre=(0.0, 1.0, 0.0), name="one")
    cases = build_cases([energy, one], [("cube-small", points, cells)], ["fibre-stretch"], probes=0)
    write_kit(str(tmp_path / "kit"), cases)
    kit = {c.case_id: c for c in read_kit(str(tmp_path / "kit")).cases}
    field = kit["fibres.cube-small.fibre-stretch"].input.model
    np.testing.assert_array_equal(field.frame, helix_frames(points, cells))
    assert field.fibre is None
    chosen = kit["one.cube-small.fibre-stretch"].input.model  # a direction the user gave is kept
    assert chosen.frame is None and chosen.fibre == (0.0, 1.0, 0.0)
    folder = tmp_path / "kit" / "cases" / "one.cube-small.fibre-stretch" / "input"
    assert (folder / "points.f64").exists() and not (folder / "frame.f64").exists()


@needs_oracle
@pytest.mark.oracle
@pytest.mark.parametrize(
    "wrong, expected",
    [("global axes", "frame-ignored"), ("sheet as fibre", "frame-columns")],
)
def test_a_fibre_energy_engine_with_a_frame_mistake_is_named(cube, wrong, expected):
    """The frame hypotheses on a user energy. There is no independent I4/I5 engine in the project
    (MJED has no user energies), so the mistaken engine is the oracle itself run with the wrong
    frame: this checks that the kit's field reaches the check and that the variants are tried and
    named for user energies, not the oracle's arithmetic (test_user_energy.py does that). I4 and
    I5 see only the fibre column, so the two column orders that put the sheet first predict the
    same forces: the mistake is named once.
    """
    from conformance.protocol import check_implementation
    from reference_fem import UFLOracle
    from reference_fem.user_energy import UserEnergy

    def mistaken(case):
        R = case.model.frame
        frame = np.eye(3) if wrong == "global axes" else R[..., [1, 0, 2]].copy()
        oracle = UFLOracle(case.points, case.cells, dataclasses.replace(case.model, frame=frame))
        f, K = oracle.force_and_stiffness(case.positions)
        return f, K

    energy = UserEnergy(FIBRE_ENERGY, FIBRE_PARAMS, name="fibres")
    run = check_implementation(
        mistaken, energy=energy, mesh="cube-small", states=("fibre-shear",), probes=False
    )
    (outcome,) = run.outcomes
    named = [f.code for f in outcome.diagnosis.causes]
    assert outcome.status == "failed" and named == [expected], outcome.diagnosis.text()
