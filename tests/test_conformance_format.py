"""The exchange format: round trips, and every bad input named with its case and file (no oracle
needed).
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import box_mesh

from comparisons.cli import main
from conformance.kit.cases import build_cases
from conformance.kit.exchange import FormatError, read_case_input, read_output, write_output
from conformance.kit.read import read_kit
from conformance.kit.write import write_kit
from mjed import materials as M


@pytest.fixture
def mesh():
    points, cells = box_mesh(1)
    return "box", points, cells


@pytest.fixture
def kit(tmp_path, mesh):
    cases = build_cases([M.NeoHookean(mu=1.3, lam=2.1)], [mesh], ["uniaxial", "random"], probes=2)
    folder = str(tmp_path / "kit")
    write_kit(folder, cases)
    return folder, cases


def _matrix(n, seed=0):
    rng = np.random.default_rng(seed)
    A = sp.random(3 * n, 3 * n, density=0.3, random_state=seed, format="csr")
    return (A + A.T).tocsr(), rng.standard_normal((n, 3))


def test_case_input_round_trip(kit):
    folder, cases = kit
    c = cases[0]
    back = read_case_input(os.path.join(folder, "cases", c.case_id, "input"), c.case_id)
    assert back.case_id == c.case_id and back.model == c.input.model
    for name in ("points", "cells", "positions"):
        np.testing.assert_array_equal(getattr(back, name), getattr(c.input, name))
    text = open(os.path.join(folder, "cases", c.case_id, "input", "case.txt")).read()
    assert "parameter mu 1.3" in text and "array positions positions.f64 <f8" in text


def test_costa_frame_round_trip(tmp_path, mesh):
    label, points, cells = mesh
    R = np.linalg.qr(np.random.default_rng(1).standard_normal((3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    frames = np.repeat(R[None], len(cells), axis=0)
    costa = M.Costa(
        a=0.9, k0=3.0, b_ff=1.0, b_fs=0.3, b_ss=0.8, b_fn=0.2, b_sn=0.1, b_nn=0.5, frame=frames
    )
    cases = build_cases([costa], [mesh], ["shear"], probes=0)
    write_kit(str(tmp_path / "k"), cases)
    back = read_case_input(str(tmp_path / "k" / "cases" / cases[0].case_id / "input"))
    np.testing.assert_array_equal(back.model.frame, frames)


@pytest.mark.parametrize("layout", ["coo", "csr", "dense"])
def test_output_round_trip(tmp_path, layout):
    K, f = _matrix(5)
    write_output(str(tmp_path), f, K, 1.25, layout=layout)
    out = read_output(str(tmp_path), 5, "c1")
    np.testing.assert_array_equal(out.force, f)
    assert abs(out.stiffness - K).max() == 0 and out.energy == 1.25


def test_coo_duplicates_are_summed(tmp_path):
    f = np.zeros((2, 3))
    write_output(str(tmp_path), f, sp.csr_matrix((6, 6)))
    rows, cols, vals = np.array([0, 0, 5]), np.array([1, 1, 5]), np.array([1.0, 2.0, 4.0])
    rows.astype("<i8").tofile(tmp_path / "stiffness_rows.i64")
    cols.astype("<i8").tofile(tmp_path / "stiffness_cols.i64")
    vals.astype("<f8").tofile(tmp_path / "stiffness_values.f64")
    K = read_output(str(tmp_path), 2, "c").stiffness
    assert K[0, 1] == 3.0 and K[5, 5] == 4.0


def _bad(tmp_path, mutate, n=4):
    K, f = _matrix(n)
    write_output(str(tmp_path), f, K, 1.0)
    mutate(tmp_path, f, K)
    with pytest.raises(FormatError) as err:
        read_output(str(tmp_path), n, "case-7")
    return str(err.value)


def test_bad_outputs_are_named(tmp_path):
    msgs = {
        "short": _bad(tmp_path / "a", lambda p, f, K: f[:-1].astype("<f8").tofile(p / "force.f64")),
        "nan": _bad(
            tmp_path / "b",
            lambda p, f, K: (
                np.where(np.arange(12).reshape(4, 3) == 5, np.nan, f)
                .astype("<f8")
                .tofile(p / "force.f64")
            ),
        ),
        "missing": _bad(tmp_path / "c", lambda p, f, K: os.remove(p / "force.f64")),
        "no stiffness": _bad(
            tmp_path / "d",
            lambda p, f, K: [
                os.remove(p / x) for x in ("stiffness_rows.i64", "stiffness_cols.i64")
            ],
        ),
        "index": _bad(
            tmp_path / "e",
            lambda p, f, K: (
                (sp.coo_matrix(K).row + 1).astype("<i8").tofile(p / "stiffness_rows.i64")
            ),
        ),
        "two layouts": _bad(
            tmp_path / "f", lambda p, f, K: K.toarray().astype("<f8").tofile(p / "stiffness.f64")
        ),
        "energy": _bad(
            tmp_path / "g", lambda p, f, K: np.array([1.0, 2.0]).tofile(p / "energy.f64")
        ),
    }
    assert "force.f64: 9 values (3 nodes), expected 3n = 12 for 4 nodes" in msgs["short"]
    assert "force.f64: 1 non-finite value(s)" in msgs["nan"] and "flat index 5" in msgs["nan"]
    assert "force.f64: file missing" in msgs["missing"]
    assert "no stiffness" in msgs["no stiffness"]
    assert "stiffness_rows.i64: indices must lie in [0, 12)" in msgs["index"]
    assert "several stiffness layouts" in msgs["two layouts"]
    assert "energy.f64: expected exactly one" in msgs["energy"]
    for m in msgs.values():
        assert m.startswith("case case-7: ")


def test_missing_output_directory(tmp_path):
    with pytest.raises(FormatError, match="case x: .*nothing: output directory missing"):
        read_output(str(tmp_path / "nothing"), 4, "x")


def test_kit_read_back_and_bad_cases_isolated(kit):
    folder, cases = kit
    k = read_kit(folder)
    assert len(k.cases) == len(cases) and not k.errors
    # A changed input and a malformed case manifest: those cases fail to read, the others are kept.
    first, second = cases[0].case_id, cases[3].case_id
    with open(os.path.join(folder, "cases", first, "input", "positions.f64"), "r+b") as fh:
        fh.write(b"\0" * 8)
    with open(os.path.join(folder, "cases", second, "input", "case.json"), "w") as fh:
        fh.write("{not json")
    k = read_kit(folder)
    assert set(k.errors) == {first, second}
    assert (
        f"case {first}: " in k.errors[first]
        and "positions.f64: changed since export" in k.errors[first]
    )
    assert "case.json" in k.errors[second]
    assert len(k.cases) == len(cases) - 2


def test_malformed_kit_manifest(tmp_path, kit):
    folder, _ = kit
    path = os.path.join(folder, "manifest.json")
    data = json.load(open(path))
    data["format_version"] = 99
    json.dump(data, open(path, "w"))
    with pytest.raises(FormatError, match="manifest.json: format_version 99 is not supported"):
        read_kit(folder)
    open(path, "w").write("[")
    with pytest.raises(FormatError, match="manifest.json: malformed JSON"):
        read_kit(folder)


def test_export_cli_refuses_non_empty_dir(tmp_path, capsys):
    target = tmp_path / "kit"
    target.mkdir()
    (target / "mine.txt").write_text("keep me")
    assert main(["export", str(target), "--material", "NeoHookean", "--states", "rest"]) == 2
    assert "not an empty directory" in capsys.readouterr().err
    assert (target / "mine.txt").read_text() == "keep me" and len(os.listdir(target)) == 1


def test_export_cli_writes_kit(tmp_path, capsys):
    target = tmp_path / "kit"
    assert (
        main(["export", str(target), "--material", "NeoHookean,Ogden", "--states", "rest,shear"])
        == 0
    )
    k = read_kit(str(target))
    assert (
        sum(c.role == "case" for c in k.cases) == 4
        and sum(c.role == "probe" for c in k.cases) == 16
    )
    manifest = json.load(open(target / "manifest.json"))
    assert manifest["format_version"] == 1 and manifest["created_by"].startswith(
        "mjed-verify export"
    )


def test_export_user_energy(tmp_path):
    target = tmp_path / "kit"
    assert (
        main(
            [
                "export",
                str(target),
                "--energy",
                "mu/2*(I1b-3) + K/2*(J-1)**2",
                "--param",
                "mu=1e3",
                "--param",
                "K=1e4",
                "--states",
                "uniaxial",
                "--no-probes",
            ]
        )
        == 0
    )
    (case,) = read_kit(str(target)).cases
    assert case.input.model.expression == "mu/2*(I1b-3) + K/2*(J-1)**2"
    assert dict(case.input.model.params) == {"mu": 1e3, "K": 1e4}


def test_export_bad_energy_is_input_error(tmp_path, capsys):
    assert (
        main(["export", str(tmp_path / "k"), "--energy", "__import__('os')", "--states", "rest"])
        == 2
    )
    assert "--energy" in capsys.readouterr().err
