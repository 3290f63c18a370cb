"""SOFA's force fields as a kit engine: the material mapping (always), and SOFA's own output
through `mjed-verify check` (only where the engine program is built; skipped loudly otherwise).
"""

from __future__ import annotations

import json
import os
import shlex
import sys

import numpy as np
import pytest

from conformance.adapters.sofa import NotExpressible, find_program, how_to_build, sofa_material
from conformance.adapters.sofa.__main__ import main as sofa_main
from conformance.adapters.sofa.program import ENV


def _model(name, **parameters):
    return {"kind": "material", "name": name, "parameters": parameters}


def test_orders_come_from_the_declarations():
    m = sofa_material(_model("MooneyRivlin", c1=1.0, c2=2.0, k0=3.0), "standard")
    assert (m.name, m.parameters) == ("MooneyRivlin", (1.0, 2.0, 3.0))
    m = sofa_material(_model("NeoHookean", mu=5.0, lam=7.0), "mjed")
    assert (m.name, m.parameters) == ("NeoHookean", (5.0, 7.0))


def test_ogden_order_differs_between_the_plugin_and_sofa_core():
    ogden = _model("Ogden", mu=10.0, alpha=3.0, k0=100.0)
    assert sofa_material(ogden, "mjed").parameters == (100.0, 10.0, 3.0)
    assert sofa_material(ogden, "hyperelasticity").parameters == (10.0, 3.0, 100.0)
    assert sofa_material(ogden, "standard").parameters == (10.0, 3.0, 100.0)


def test_parameter_set_round_trips_exactly():
    value = 3448.2758620689656
    m = sofa_material(_model("NeoHookean", mu=value, lam=0.1), "mjed")
    assert [float(v) for v in m.parameter_set().split()] == [value, 0.1]


@pytest.mark.parametrize(
    "model, why",
    [
        (_model("Yeoh", c10=1.0, c20=1.0, c30=1.0, k0=1.0), "no Yeoh"),
        ({"kind": "energy", "expression": "mu*(I1-3)", "parameters": {"mu": 1.0}}, "user energy"),
    ],
)
def test_what_sofa_lacks_is_refused_with_the_reason(model, why):
    with pytest.raises(NotExpressible, match=why):
        sofa_material(model, "hyperelasticity")


def test_costa_only_with_the_global_axes():
    b = dict(b_ff=3.0, b_fs=4.0, b_ss=5.0, b_fn=6.0, b_sn=7.0, b_nn=8.0)
    costa = _model("Costa", a=1.0, k0=2.0, **b)
    identity = np.broadcast_to(np.eye(3), (5, 3, 3))
    assert sofa_material(costa, "mjed", identity).parameters == (
        1.0,
        2.0,
        3.0,
        4.0,
        5.0,
        6.0,
        7.0,
        8.0,
    )
    turned = identity.copy()
    turned[2] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    with pytest.raises(NotExpressible, match="per-cell fibre frame"):
        sofa_material(costa, "mjed", turned)


def test_unknown_forcefield_is_a_plain_error():
    with pytest.raises(ValueError, match="unknown force field"):
        sofa_material(_model("NeoHookean", mu=1.0, lam=1.0), "corotational")


def test_missing_program_says_how_to_build(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(ENV, str(tmp_path / "nowhere" / "sofa_engine"))
    assert find_program() is None
    assert sofa_main([]) == 3
    assert "python -m conformance.adapters.sofa build --sofa" in capsys.readouterr().out


# --- SOFA's own output, judged by the checker (needs the built engine program) -----------------

PROGRAM = find_program()  # the run's header says loudly when it is missing (conftest.py)
needs_sofa = pytest.mark.skipif(PROGRAM is None, reason=f"SOFA checks skipped: {how_to_build()}")


def _check(tmp_path, forcefield, material, mesh="single-tet", states="uniaxial,random"):
    from comparisons.cli import main

    command = (
        f"{shlex.quote(sys.executable)} -m conformance.adapters.sofa case "
        f"--forcefield {forcefield} {{input}} {{output}}"
    )
    out = tmp_path / "r"
    code = main(
        [
            "check",
            "--command",
            command,
            "--material",
            material,
            "--mesh",
            mesh,
            "--states",
            states,
            "--out",
            str(out),
            "--quiet",
        ]
    )
    (run,) = os.listdir(out)
    return code, json.load(open(out / run / "results.json"))


@needs_sofa
@pytest.mark.oracle
@pytest.mark.parametrize("forcefield", ["mjed", "hyperelasticity", "standard"])
def test_sofa_neo_hookean_passes(tmp_path, forcefield):
    code, results = _check(tmp_path, forcefield, "NeoHookean")
    assert code == 0, [c.get("diagnosis") for c in results["cases"]]


def test_sofa_study_options_reach_the_study(monkeypatch):
    """--skip-checks, --skip-timing, --calls and the command line arrive as given (they were
    once passed by position into the wrong parameters).
    """
    import comparisons.sofa.study as study
    from comparisons.cli import main

    seen = {}

    def fake(*args, **kwargs):
        seen.update(kwargs)
        from common.result import StudyResult

        return StudyResult.not_run("sofa", "SOFA", "test", kwargs["command"])

    monkeypatch.setattr(study, "sofa_study", fake)
    main(["sofa", "--skip-checks", "--calls", "3"])
    assert seen["checks_on"] is False and seen["timing_on"] is True
    assert seen["timing_calls"] == 3 and callable(seen["progress"])
