"""Language neutrality: a C engine written from docs/conventions.md, compiled with the system
compiler,
passes `mjed-verify check --command`; compiled with -DMISTAKE (force sign flipped) it is named.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess

import pytest

from common.states import state_names
from comparisons.cli import main
from reference_fem import dolfinx_available

pytestmark = [
    pytest.mark.oracle,
    pytest.mark.skipif(
        not dolfinx_available(), reason="the oracle needs dolfinx (python3-dolfinx)"
    ),
]

logging.disable(logging.INFO)
SOURCE = os.path.join(os.path.dirname(__file__), "c_engine", "neohookean.c")
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")


def _compile(tmp_path, *flags):
    if CC is None:
        pytest.skip("no C compiler (cc, gcc or clang) on PATH")
    exe = str(tmp_path / ("neohookean" + "".join(f.replace("-", "_") for f in flags)))
    subprocess.run(
        [CC, "-std=c99", "-O2", "-Wall", "-Werror", *flags, "-o", exe, SOURCE, "-lm"],
        check=True,
        capture_output=True,
    )
    return exe


def _results(out):
    (run,) = os.listdir(out)
    return json.load(open(os.path.join(out, run, "results.json")))


def _check(exe, out, *options):
    """``mjed-verify check --command 'EXE {input} {output}' --out OUT --quiet OPTIONS``: its exit
    code and its results.json.
    """
    argv = ["check", "--command", f"{exe} {{input}} {{output}}", "--out", str(out), "--quiet"]
    code = main(argv + list(options))
    return code, _results(out)


def test_c_engine_passes(tmp_path):
    exe = _compile(tmp_path)
    code, res = _check(exe, tmp_path / "r", "--material", "NeoHookean", "--mesh", "cube-small")
    assert code == 0
    assert len(res["cases"]) == len(state_names())
    assert all(c["status"] == "passed" for c in res["cases"])
    assert max(c["errors"]["stiffness"] for c in res["cases"]) < 1e-12


def test_c_engine_files_mode(tmp_path):
    """The same program run by hand over an exported kit (the 'files' way)."""
    exe = _compile(tmp_path)
    kit = tmp_path / "kit"
    assert main(["export", str(kit), "--material", "NeoHookean", "--states", "random"]) == 0
    for entry in json.load(open(kit / "manifest.json"))["cases"]:
        subprocess.run([exe, str(kit / entry["input"]), str(kit / entry["output"])], check=True)
    assert main(["check", str(kit), "--out", str(tmp_path / "r"), "--quiet"]) == 0


def test_c_engine_mistake_is_named(tmp_path):
    exe = _compile(tmp_path, "-DMISTAKE")
    code, res = _check(
        exe, tmp_path / "r", "--material", "NeoHookean", "--states", "uniaxial,random"
    )
    assert code == 1
    for case in res["cases"]:
        assert (
            case["findings"][0]["code"] == "force-sign"
            and case["findings"][0]["strength"] == "explains"
        )


def test_c_engine_refusal_is_bad_input(tmp_path):
    """A material the program does not implement: it exits 2 with a message, reported for that
    case.
    """
    exe = _compile(tmp_path)
    code, res = _check(exe, tmp_path / "r", "--material", "Ogden", "--states", "rest")
    assert code == 2
    msg = res["cases"][0]["message"]
    assert "exit code 2" in msg and "only NeoHookean is implemented, not Ogden" in msg


def test_c_engine_in_single_precision(tmp_path):
    """Built with -DSINGLE the engine computes in float and writes .f32 files: it passes at single
    precision; checked at double precision it is told its error is float32 round-off; with its
    sign mistake it still fails at single precision, the mistake named.
    """
    exe = _compile(tmp_path, "-DSINGLE")
    args = ["--material", "NeoHookean", "--mesh", "cube-small", "--states", "uniaxial,random"]
    code, res = _check(exe, tmp_path / "s", *args)
    assert code == 0
    assert all(c["tolerances"]["precision"] == "single" for c in res["cases"])
    assert max(c["errors"]["stiffness"] for c in res["cases"]) > 1e-8  # really float32 arithmetic
    code, res = _check(exe, tmp_path / "d", "--precision", "double", *args)
    assert code == 1
    assert all(c["findings"][0]["code"] == "single-precision" for c in res["cases"])
    wrong = _compile(tmp_path, "-DSINGLE", "-DMISTAKE")
    code, res = _check(wrong, tmp_path / "m", *args)
    assert code == 1
    assert all(
        c["status"] == "failed" and c["findings"][0]["code"] == "force-sign" for c in res["cases"]
    )


def test_c_engine_writing_one_triangle_is_named(tmp_path):
    exe = _compile(tmp_path, "-DUPPER")
    code, res = _check(
        exe,
        tmp_path / "r",
        "--material",
        "NeoHookean",
        "--mesh",
        "cube-small",
        "--states",
        "random",
    )
    assert code == 1
    (case,) = res["cases"]
    assert case["findings"][0]["code"] == "one-triangle"
