"""conformance.kit.agreement: two filled copies of a kit compared case by case."""

from __future__ import annotations

import glob
import os

import numpy as np
import pytest

from comparisons.cli import main as verify
from conformance.adapters.mjed_backend import main as fill
from conformance.kit.agreement import kit_agreement
from conformance.kit.agreement import main as agreement_main


def _filled(folder, states="rest,uniaxial,random", material="NeoHookean"):
    args = ["export", str(folder), "--mesh", "single-tet", "--material", material]
    assert verify([*args, "--states", states, "--no-probes"]) == 0
    assert fill(["--kit", str(folder), "--backend", "numpy"]) == 0
    return str(folder)


def test_identical_engines_agree_and_a_changed_output_shows(tmp_path, capsys):
    a, b = _filled(tmp_path / "a"), _filled(tmp_path / "b")
    same = kit_agreement(a, b)
    assert set(same) == {"NeoHookean"} and same["NeoHookean"].cases == 3
    assert same["NeoHookean"].force == 0.0 and same["NeoHookean"].stiffness == 0.0
    # one force value of the uniaxial case off by 1e-3 of the material's largest force
    (path,) = glob.glob(os.path.join(a, "cases", "*uniaxial*", "output", "force.f64"))
    largest = max(
        np.abs(np.fromfile(p, "<f8")).max()
        for p in glob.glob(os.path.join(b, "cases", "*", "output", "force.f64"))
    )
    f = np.fromfile(path, "<f8")
    f[1] += 1e-3 * largest
    f.tofile(path)
    moved = kit_agreement(a, b)["NeoHookean"]
    assert moved.force == pytest.approx(1e-3, rel=1e-9) and moved.stiffness == 0.0
    assert agreement_main([a, b]) == 0
    assert "force 1.0e-03, stiffness 0.0e+00" in capsys.readouterr().out


def test_kits_of_other_cases_are_refused(tmp_path, capsys):
    a = _filled(tmp_path / "a")
    b = _filled(tmp_path / "b", states="rest,uniaxial")
    with pytest.raises(ValueError, match="hold different cases: first NeoHookean.*random"):
        kit_agreement(a, b)
    assert agreement_main([a, b]) == 1
    assert "different cases" in capsys.readouterr().err
