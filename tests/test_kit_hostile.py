"""A kit is untrusted input: its ids, paths, links, special files, sizes and malformed fields
are refused for that case only, naming the file, and nothing outside the kit and --out is
read or written (docs/checking.md, "Threat model").
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
import tracemalloc

import numpy as np
import pytest
from conftest import box_mesh

from comparisons.cli import main
from conformance.kit.cases import build_cases
from conformance.kit.exchange import ENTRIES_PER_CELL, FormatError, read_output, write_output
from conformance.kit.read import read_kit
from conformance.kit.write import write_kit
from mjed import materials as M
from reference_fem import dolfinx_available

needs_oracle = pytest.mark.skipif(
    not dolfinx_available(), reason="check needs the oracle (python3-dolfinx)"
)


def _kit(tmp_path, states=("uniaxial",), name="kit"):
    points, cells = box_mesh(1)
    cases = build_cases(
        [M.NeoHookean(mu=1.3, lam=2.1)], [("box", points, cells)], list(states), probes=0
    )
    folder = str(tmp_path / name)
    write_kit(folder, cases)
    return folder, cases


def _manifest(folder):
    with open(os.path.join(folder, "manifest.json")) as fh:
        return json.load(fh)


def _save(folder, manifest):
    with open(os.path.join(folder, "manifest.json"), "w") as fh:
        json.dump(manifest, fh)


def _rehash(folder, entry):
    """Recompute the digests of an entry's input files (a hostile kit is self-consistent)."""
    d = os.path.join(folder, entry["input"])
    entry["input_sha256"] = {
        n: hashlib.sha256(open(os.path.join(d, n), "rb").read()).hexdigest()
        for n in sorted(os.listdir(d))
        if os.path.isfile(os.path.join(d, n))
    }


def _tree(root):
    """Every path under root (files, links and directories), to see what a run created."""
    out = set()
    for base, dirs, files in os.walk(root):
        for n in dirs + files:
            out.add(os.path.relpath(os.path.join(base, n), root))
    return out


def _check_with(engine, folder, out):
    """mjed-verify check of ``folder`` with the Python script ``engine`` as the --command."""
    command = f"{sys.executable} {engine} {{input}} {{output}}"
    return main(["check", folder, "--command", command, "--out", out, "--quiet", "--timeout", "20"])


# ---------------------------------------------------------------- case ids
@pytest.mark.parametrize(
    "bad", ["../../escaped", "/tmp/absolute", "a/b", ".hidden", "a..b", "x" * 201, ""]
)
def test_unsafe_case_ids_are_refused(tmp_path, bad):
    folder, _ = _kit(tmp_path)
    m = _manifest(folder)
    m["cases"][0]["id"] = bad
    _save(folder, m)
    kit = read_kit(folder)
    assert not kit.cases
    (msg,) = kit.errors.values()
    assert "not a safe name" in msg or "longer than 200" in msg


@needs_oracle
def test_a_traversing_id_writes_nothing_outside_kit_and_out(tmp_path, capsys):
    folder, cases = _kit(tmp_path, states=("uniaxial", "shear"))
    m = _manifest(folder)
    m["cases"][0]["id"] = "../../../escaped"
    _save(folder, m)
    engine = tmp_path / "engine.py"
    engine.write_text("import sys, os\nos.makedirs(sys.argv[2], exist_ok=True)\n")
    before = _tree(str(tmp_path))
    code = _check_with(engine, folder, str(tmp_path / "out"))
    assert code == 2
    created = {p for p in _tree(str(tmp_path)) - before if not p.startswith("out")}
    assert created == set()
    (run,) = os.listdir(tmp_path / "out")
    res = json.load(open(tmp_path / "out" / run / "results.json"))
    assert any("not a safe name" in v for v in res["input_errors"].values())
    assert [c["case"] for c in res["cases"]] == [cases[1].case_id]  # the other case still ran


def test_a_duplicated_id_is_bad_input_not_counted_twice(tmp_path):
    folder, _ = _kit(tmp_path, states=("uniaxial", "shear"))
    m = _manifest(folder)
    m["cases"][1]["id"] = m["cases"][0]["id"]
    _save(folder, m)
    kit = read_kit(folder)
    assert not kit.cases
    where = f"case {m['cases'][0]['id']}: {os.path.join(folder, 'manifest.json')}"
    assert list(kit.errors.values()) == [
        f"{where}: the id appears 2 times; case ids must be unique"
    ]


def test_generated_ids_are_safe_whatever_the_mesh_name():
    points, cells = box_mesh(1)
    (case,) = build_cases(
        [M.NeoHookean(mu=1.0, lam=1.0)], [("../my..mesh.msh", points, cells)], ["rest"], probes=0
    )
    assert case.case_id == "NeoHookean.my.mesh.rest"


# ---------------------------------------------------------------- paths and links
def _set_array_file(folder, name):
    m = _manifest(folder)
    e = m["cases"][0]
    cj = os.path.join(folder, e["input"], "case.json")
    data = json.load(open(cj))
    data["arrays"]["points"]["file"] = name
    json.dump(data, open(cj, "w"))
    _rehash(folder, e)
    return m, e


@pytest.mark.parametrize(
    "name, words",
    [("../../../outside.f64", "climbs out with '..'"), ("/etc/hostname", "is an absolute path")],
)
def test_array_file_names_are_confined(tmp_path, name, words):
    folder, _ = _kit(tmp_path)
    m, e = _set_array_file(folder, name)
    e["input_sha256"][name] = "0" * 64
    _save(folder, m)
    (msg,) = read_kit(folder).errors.values()
    assert words in msg and e["id"] in msg


def test_a_symlink_out_of_the_kit_is_refused(tmp_path):
    folder, _ = _kit(tmp_path)
    secret = tmp_path / "secret.f64"
    secret.write_bytes(np.zeros((8, 3)).tobytes())
    m, e = _set_array_file(folder, "link.f64")
    link = os.path.join(folder, e["input"], "link.f64")
    os.symlink(secret, link)
    _rehash(folder, e)  # even with a matching digest
    _save(folder, m)
    (msg,) = read_kit(folder).errors.values()
    assert "leads outside" in msg and link in msg


def test_an_array_not_listed_in_the_hashes_is_refused(tmp_path):
    folder, _ = _kit(tmp_path)
    m, e = _set_array_file(folder, "points.f64")
    del e["input_sha256"]["points.f64"]
    _save(folder, m)
    (msg,) = read_kit(folder).errors.values()
    assert "not listed in the kit's input_sha256" in msg


@pytest.mark.parametrize("key", ["../../manifest.json", "/etc/passwd"])
def test_hash_keys_are_confined(tmp_path, key):
    folder, _ = _kit(tmp_path)
    m = _manifest(folder)
    m["cases"][0]["input_sha256"][key] = "0" * 64
    _save(folder, m)
    (msg,) = read_kit(folder).errors.values()
    assert "climbs out" in msg or "absolute path" in msg


@pytest.mark.parametrize("field", ["input", "output"])
def test_input_and_output_fields_are_confined(tmp_path, field):
    folder, _ = _kit(tmp_path)
    m = _manifest(folder)
    m["cases"][0][field] = "../elsewhere"
    _save(folder, m)
    (msg,) = read_kit(folder).errors.values()
    assert f"field '{field}'" in msg and "climbs out" in msg


@needs_oracle
def test_the_engine_gets_the_input_whose_hashes_were_checked(tmp_path, capsys):
    folder, cases = _kit(tmp_path)
    m = _manifest(folder)
    e = m["cases"][0]
    os.rename(os.path.join(folder, e["input"]), os.path.join(folder, "moved"))
    e["input"] = "moved"
    _save(folder, m)
    # a decoy where the old code looked
    os.makedirs(os.path.join(folder, "cases", e["id"], "input"))
    engine = tmp_path / "engine.py"
    engine.write_text(
        "import sys, os\nos.makedirs(sys.argv[2], exist_ok=True)\n"
        "open(os.path.join(sys.argv[2], 'seen.txt'), 'w').write(sys.argv[1])\n"
    )
    _check_with(engine, folder, str(tmp_path / "out"))
    run = os.path.join(str(tmp_path / "out"), os.listdir(tmp_path / "out")[0])
    seen = open(os.path.join(run, "outputs", e["id"], "seen.txt")).read()
    assert seen == os.path.abspath(os.path.join(folder, "moved"))


# ---------------------------------------------------------------- output files
def _output(tmp_path, n=8, m=6):
    folder = str(tmp_path / "output")
    write_output(folder, np.zeros((n, 3)), np.eye(3 * n))
    return folder


def test_output_special_files_are_named_by_their_kind(tmp_path):
    folder = _output(tmp_path)
    force = os.path.join(folder, "force.f64")
    os.remove(force)
    os.mkfifo(force)
    with pytest.raises(FormatError, match="is a FIFO"):  # and does not hang
        read_output(folder, 8, "c", n_cells=6)
    os.remove(force)
    os.mkdir(force)
    with pytest.raises(FormatError, match="is a directory"):
        read_output(folder, 8, "c", n_cells=6)
    os.rmdir(force)
    os.symlink("/dev/zero", force)
    with pytest.raises(FormatError, match="leads outside .* /dev/zero"):
        read_output(folder, 8, "c", n_cells=6)


def test_an_output_directory_linked_elsewhere_is_refused(tmp_path):
    real = _output(tmp_path)
    root = tmp_path / "outputs"
    root.mkdir()
    os.symlink(real, root / "case")
    with pytest.raises(FormatError, match="leads outside"):
        read_output(str(root / "case"), 8, "c", n_cells=6, within=str(root))


def test_a_huge_sparse_output_is_refused_before_it_is_read(tmp_path):
    folder = _output(tmp_path)
    n_cells = 6
    for name in ("stiffness_rows.i64", "stiffness_cols.i64", "stiffness_values.f64"):
        with open(os.path.join(folder, name), "wb") as fh:
            fh.truncate(2 << 30)  # 2 GB that cost no disk (a sparse file)
    tracemalloc.start()
    with pytest.raises(FormatError) as info:
        read_output(folder, 8, "c", n_cells=n_cells)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    bound = min(4 * 24**2, ENTRIES_PER_CELL * n_cells)  # (3n)^2 x 4 is the smaller for 8 nodes
    assert f"2147483648 bytes, more than the {8 * bound}" in str(info.value)
    assert f"at most {bound} coo entries are read for this mesh" in str(info.value)
    assert peak < 10 << 20


def test_a_dense_stiffness_too_large_to_hold_is_refused(tmp_path):
    folder = tmp_path / "o"
    folder.mkdir()
    (folder / "force.f64").write_bytes(np.zeros(3 * 3000).tobytes())
    with open(folder / "stiffness.f64", "wb") as fh:
        fh.truncate(8 * 9000 * 9000)
    with pytest.raises(FormatError, match="too large to read .* write it as COO or CSR"):
        read_output(str(folder), 3000, "c")


# ---------------------------------------------------------------- malformed fields
def _edit_case_json(folder, edit):
    m = _manifest(folder)
    e = m["cases"][0]
    cj = os.path.join(folder, e["input"], "case.json")
    data = json.load(open(cj))
    edit(data)
    with open(cj, "w") as fh:
        fh.write(data if isinstance(data, str) else json.dumps(data))
    _rehash(folder, e)
    _save(folder, m)
    return e["id"]


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda d: d["arrays"]["points"].update(shape=None), "shape must be a list"),
        (lambda d: d["arrays"]["points"].update(shape=[[8, 3]]), "shape must be a list"),
        (lambda d: d["arrays"]["points"].update(shape=[2**40, 2**40, 2**40]), "needs"),
        (lambda d: d["arrays"]["points"].update(dtype=["<f8"]), "is not one of"),
        (lambda d: d["model"].update(name=["NeoHookean"]), "case.json"),
        (lambda d: d["model"].update(parameters={"mu": 10**400, "lam": 1}), "case.json"),
        (lambda d: d["arrays"].update(points=None), "needs 'file', 'dtype' and 'shape'"),
    ],
)
def test_malformed_case_fields_are_bad_input_of_that_case(tmp_path, edit, words):
    folder, _ = _kit(tmp_path, states=("uniaxial", "shear"))
    cid = _edit_case_json(folder, edit)
    kit = read_kit(folder)
    assert len(kit.cases) == 1 and list(kit.errors) == [cid]
    assert words in kit.errors[cid] and cid in kit.errors[cid]


def test_deeply_nested_json_is_refused_not_a_recursion_error(tmp_path):
    folder, _ = _kit(tmp_path)
    m = _manifest(folder)
    e = m["cases"][0]
    with open(os.path.join(folder, e["input"], "case.json"), "w") as fh:
        fh.write("[" * 200_000 + "]" * 200_000)
    _rehash(folder, e)
    _save(folder, m)
    (msg,) = read_kit(folder).errors.values()
    assert "nested too deeply" in msg
    with open(os.path.join(folder, "manifest.json"), "w") as fh:
        fh.write('{"a":' * 200_000 + "1" + "}" * 200_000)
    with pytest.raises(FormatError, match="manifest.json: malformed JSON .nested too deeply"):
        read_kit(folder)


def test_cells_out_of_range_are_refused(tmp_path):
    folder, _ = _kit(tmp_path)
    m = _manifest(folder)
    e = m["cases"][0]
    cells = os.path.join(folder, e["input"], "cells.i64")
    a = np.fromfile(cells, "<i8")
    a[0] = 10**6
    a.tofile(cells)
    _rehash(folder, e)
    _save(folder, m)
    (msg,) = read_kit(folder).errors.values()
    assert "cell node indices must lie in [0, 8)" in msg


@needs_oracle
def test_a_malformed_manifest_is_exit_2_naming_it(tmp_path, capsys):
    folder, _ = _kit(tmp_path)
    with open(os.path.join(folder, "manifest.json"), "w") as fh:
        fh.write('{"format": NaN}')
    assert main(["check", folder, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "manifest.json: malformed JSON" in err and "NaN is not a JSON value" in err


# ---------------------------------------------------------------- user energy budget
@needs_oracle
def test_a_user_energy_past_the_symbolic_budget_is_refused_for_its_cases(
    tmp_path, capsys, monkeypatch
):
    import random

    from reference_fem import symbolic_budget

    monkeypatch.setattr(symbolic_budget, "SYMBOLIC_SECONDS", 3.0)
    # forty components of C multiplied: FFCx needs about 50 s for it (a fresh order each run,
    # so that no FFCx cache entry from an earlier run can make it fast)
    names = [f"C{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)] * 5
    random.shuffle(names)
    expression = "mu*(" + "*".join(names[:40]) + "-1)"
    engine = tmp_path / "engine.py"  # a well-formed output, so that the oracle is reached
    engine.write_text(
        "import json, os, sys\nimport numpy as np\n"
        "n = json.load(open(os.path.join(sys.argv[1], 'case.json')))['n_nodes']\n"
        "os.makedirs(sys.argv[2], exist_ok=True)\n"
        "np.zeros(3 * n).tofile(os.path.join(sys.argv[2], 'force.f64'))\n"
        "np.eye(3 * n).tofile(os.path.join(sys.argv[2], 'stiffness.f64'))\n"
    )
    t0 = time.monotonic()
    code = main(
        [
            "check",
            "--command",
            f"{sys.executable} {engine} {{input}} {{output}}",
            "--energy",
            expression,
            "--param",
            "mu=1",
            "--states",
            "uniaxial",
            "--out",
            str(tmp_path / "out"),
            "--quiet",
        ]
    )
    assert code == 2
    assert time.monotonic() - t0 < 40
    (run,) = os.listdir(tmp_path / "out")
    (case,) = json.load(open(tmp_path / "out" / run / "results.json"))["cases"]
    assert "took more than 3 s (the symbolic budget)" in case["message"]


# ---------------------------------------------------------------- concurrent exports
def test_an_export_into_a_folder_another_export_holds_is_refused(tmp_path, monkeypatch):
    from conformance.kit.write import EXPORT_LOCK

    cases = _kit(tmp_path, name="other")[1]
    folder = tmp_path / "kit"
    makedirs = os.makedirs

    def and_the_other_export_claims_it(path, *args, **kwargs):
        # the race: another export claims the folder just after this one found it empty
        makedirs(path, *args, **kwargs)
        if path == str(folder):
            (folder / EXPORT_LOCK).touch()

    monkeypatch.setattr(os, "makedirs", and_the_other_export_claims_it)
    with pytest.raises(FileExistsError, match="another export is writing into it"):
        write_kit(str(folder), cases)
    assert os.listdir(folder) == [EXPORT_LOCK]  # nothing of this export written


def test_two_concurrent_exports_into_one_folder_give_one_kit_and_one_clear_error(tmp_path):
    import subprocess

    folder = str(tmp_path / "kit")
    argv = [
        sys.executable,
        "-m",
        "comparisons.cli",
        "export",
        folder,
        "--material",
        "NeoHookean",
        "--states",
        "rest,uniaxial,shear",
        "--no-probes",
    ]
    procs = [
        subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    results = sorted((p.wait(timeout=120), p.stderr.read()) for p in procs)
    assert [code for code, _ in results] == [0, 2]
    assert "Traceback" not in results[1][1]
    assert (
        "another export is writing into it" in results[1][1]
        or "exists and is not an empty directory" in results[1][1]
    )
    assert len(read_kit(folder).cases) == 3
