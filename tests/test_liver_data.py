"""The liver study's typed records: what a run returns, their validation, and the JSON form
(the keys results.json has always had, read back by from_dict with every key checked).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from comparisons.liver.oscillation_records import (
    OscillationCurve,
    OscillationData,
    OscillationMetrics,
    OscillationRow,
)
from comparisons.liver.records import PHASES, BackendAgreement, LiverData, LiverRun, StepSplit
from comparisons.liver.terzaghi_records import TerzaghiResult, TerzaghiTime

#: The keys of a run's JSON record, in results.json's order (a porous run adds max_abs_pressure).
RUN_KEYS = [
    "model",
    "dt",
    "steps",
    "steps_planned",
    "error",
    "time",
    "max_displacement",
    "final_max_displacement",
    "peak_max_displacement",
    "cg_iterations_mean",
    "cg_iterations",
    "substeps",
    "steps_split",
    "substeps_total",
    "retries",
    "inverted_cells",
    "inverted_cells_max",
    "factorizations",
    "solver",
    "force_field",
    "backend",
    "stepping_seconds",
    "fps",
    "cpu_fps",
    "realtime_factor",
    "paper_fps",
    "phase_seconds",
]
#: The keys of the study's JSON record (liver_study adds oscillation and protocol).
STUDY_KEYS = [
    "mesh",
    "mesh_description",
    "n_nodes",
    "n_cells",
    "scale",
    "numbering",
    "reoriented_cells",
    "unused_nodes",
    "mesh_warnings",
    "fixed_regions",
    "n_fixed",
    "fixed_node_ids",
    "quick",
    "duration",
    "parameters",
    "runs",
    "backends",
    "fps_table",
    "step_split",
    "backend_agreement",
    "terzaghi",
    "passed",
    "figures",
    "series",
    "oscillation",
    "protocol",
]


def a_run(**changes) -> LiverRun:
    """Two steps of the hyperelastic model, the second in two substeps (made-up numbers)."""
    values = dict(
        model="hyperelastic",
        dt=0.3,
        steps_planned=2,
        error=None,
        time=[0.0, 0.3, 0.6],
        max_displacement=[0.0, 0.02, 0.03],
        cg_iterations=[4, 6],
        substeps=[1, 2],
        retries=[[], ["negative curvature"]],
        inverted_cells=[0, 0],
        factorizations=1,
        solver="CG",
        force_field="NumPy MJED",
        backend="numpy",
        stepping_seconds=0.5,
        cpu_fps=3.0,
        phase_seconds=dict(zip(PHASES, [0.2, 0.0, 0.1, 0.15, 0.05])),
    )
    values.update(changes)
    return LiverRun(**values)


def an_oscillation() -> OscillationData:
    run = a_run()
    metrics = OscillationMetrics(2, 0.031, 0.4, None, 1.03, 0.03, 0.031)
    row = dataclasses.replace(
        OscillationRow.of_run(run, metrics), omega_smallest_dt=15.7, euler_decay_rate=5.1
    )
    return OscillationData(
        mesh="liver-coarse",
        dts=(0.3,),
        duration=0.6,
        rayleigh=(0.0, 0.0),
        curves=(OscillationCurve.of_run(run),),
        table=(row,),
        amplitude_ordering=("hyperelastic",),
        amplitude_ordering_dt=0.3,
        figures=("fig4_oscillations.png",),
    )


def a_terzaghi() -> TerzaghiResult:
    return TerzaghiResult(
        figures=("terzaghi.png",),
        n_layers=20,
        dt=0.004,
        coupling_iterations=1,
        B=0.4,
        c_v=1.0,
        K_lim=2000.0,
        constrained_modulus=4000.0,
        times=(TerzaghiTime(0.05, 0.005), TerzaghiTime(0.2, 0.002)),
    )


def test_terzaghi_record_round_trip_worst_error_and_refusals():
    record = a_terzaghi()
    data = record.to_dict()
    assert list(data) == [
        "figures",
        "n_layers",
        "dt",
        "coupling_iterations",
        "B",
        "c_v",
        "K_lim",
        "constrained_modulus",
        "times",
    ]
    assert TerzaghiResult.from_dict(json.loads(json.dumps(data))) == record
    assert record.worst_error == 0.005
    with pytest.raises(ValueError, match="TerzaghiTime: key 'relative_l2_error' must be a number"):
        TerzaghiTime(0.1, -1e-3)
    with pytest.raises(ValueError, match="TerzaghiResult: key 'n_layers' must be an integer >= 1"):
        TerzaghiResult(**{**vars(record), "n_layers": 0})
    data["times"][1]["T_v"] = "late"
    with pytest.raises(ValueError, match="times/1: TerzaghiTime: key 'T_v'"):
        TerzaghiResult.from_dict(data)


def a_study(**changes) -> LiverData:
    numba = a_run(backend="numba", max_displacement=[0.0, 0.02, 0.030001])
    values = dict(
        mesh="liver-coarse",
        mesh_description="liver-coarse (200 nodes)",
        n_nodes=200,
        n_cells=598,
        scale=1.0,
        numbering="0-based positions",
        reoriented_cells=0,
        unused_nodes=0,
        mesh_warnings=(),
        fixed_regions=("box:0,0,0,1,1,1",),
        n_fixed=3,
        fixed_node_ids=(4, 7, 9),
        quick=True,
        duration=0.6,
        parameters={"dt": 0.3},
        runs=(a_run(), numba),
        step_split=(StepSplit("hyperelastic", "numpy", 250.0, dict.fromkeys(PHASES, 0.2)),),
        backend_agreement=(BackendAgreement("hyperelastic", "numba", "numpy", 3e-5),),
        terzaghi=a_terzaghi(),
        figures=("fig4_max_displacement.png",),
        series=(),
        oscillation=an_oscillation(),
        protocol="2 runs",
    )
    values.update(changes)
    return LiverData(**values)


# ----------------------------------------------------------------------------- a real run
def test_simulate_returns_a_typed_run_whose_json_keeps_its_keys():
    """One real step: simulate gives a LiverRun (not a dict), its derived figures follow from
    the per-step lists, and its JSON form has exactly the historical keys, read back equal.
    """
    from comparisons.liver.organ import fixed_nodes, load_organ
    from comparisons.liver.setup import LiverParameters
    from comparisons.liver.simulation import simulate
    from comparisons.liver.study import default_fixed_specs

    organ = load_organ("liver-coarse")
    fixed = fixed_nodes(organ, default_fixed_specs(organ.file_points))
    run = simulate("visco-poro-hyperelastic", organ.mesh, LiverParameters(), fixed, 0.3)
    assert isinstance(run, LiverRun) and run.steps == run.steps_planned == 2 and run.completed
    assert run.final_max_displacement == run.max_displacement[-1] > 0
    assert run.fps == pytest.approx(2 / run.stepping_seconds)
    assert run.pressure_snapshot is not None and run.pressure_snapshot.positions.shape == (
        organ.mesh.n_nodes,
        3,
    )
    data = run.to_dict()
    assert list(data) == RUN_KEYS + ["max_abs_pressure"]
    assert "pressure_snapshot" not in json.dumps(data)
    again = LiverRun.from_dict(json.loads(json.dumps(data)))
    assert again == run and again.to_dict() == data


# ----------------------------------------------------------------------------- the JSON form
def test_the_json_forms_keep_their_keys_and_read_back_equal():
    study = a_study()
    data = study.to_dict()
    assert list(data) == STUDY_KEYS
    assert list(data["runs"][0]) == RUN_KEYS
    assert data["backends"] == ["numpy", "numba"] and data["passed"] is True
    assert data["fps_table"][1] == {
        **{k: data["runs"][1][k] for k in ("model", "backend", "dt", "fps", "cpu_fps")},
        **{k: data["runs"][1][k] for k in ("paper_fps", "solver", "force_field")},
        **{k: data["runs"][1][k] for k in ("cg_iterations_mean", "factorizations", "steps")},
        **{k: data["runs"][1][k] for k in ("steps_split", "substeps_total")},
        "inverted_cells_max": 0,
        "target_fps": 25.0,
        "completed": True,
        "meets_target": False,
    }
    assert list(data["oscillation"]["table"][0]) == [
        "model",
        "dt",
        "completed",
        "error",
        "steps_split",
        "extrema",
        "first_peak",
        "period",
        "decay_rate",
        "overshoot",
        "final",
        "peak",
        "omega_smallest_dt",
        "euler_decay_rate",
    ]
    text = json.dumps(data)
    again = LiverData.from_dict(json.loads(text))
    assert again == study and json.dumps(again.to_dict()) == text
    # run_liver's record has neither the oscillation study nor the protocol: not in its JSON.
    bare = a_study(oscillation=None, protocol=None)
    assert list(bare.to_dict()) == STUDY_KEYS[:-2]
    assert LiverData.from_dict(bare.to_dict()) == bare


def test_derived_values_follow_the_per_step_lists():
    run = a_run()
    assert (run.steps, run.steps_split, run.substeps_total) == (2, 1, 3)
    assert run.cg_iterations_mean == 5.0 and run.peak_max_displacement == 0.03
    assert run.fps == 4.0 and run.realtime_factor == pytest.approx(1.2) and run.paper_fps == 7.5
    stopped = a_run(
        error="time step 1 failed",
        time=[0.0],
        max_displacement=[0.0],
        cg_iterations=[],
        substeps=[],
        retries=[],
        inverted_cells=[],
        stepping_seconds=0.0,
        cpu_fps=None,
    )
    assert stopped.steps == 0 and not stopped.completed
    assert stopped.fps is None and stopped.cg_iterations_mean is None
    assert a_study(runs=(stopped,)).passed is False


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda d: d.pop("dt"), "LiverRun: missing key 'dt'"),
        (lambda d: d.pop("steps"), "LiverRun: missing key 'steps'"),  # derived, still required
        (lambda d: d.update(dt="0.3"), "key 'dt' must be a finite number > 0"),
        (lambda d: d.update(model="elastic"), "key 'model' must be one of"),
        (lambda d: d.update(cg_iterations=[4, -1]), "key 'cg_iterations[1]'"),
        (lambda d: d.update(time=[0.0, 0.3]), "key 'time' must be 3 values"),
        (lambda d: d.update(phase_seconds={"rest": 1.0}), "key 'phase_seconds'"),
        (lambda d: d.update(error=1), "key 'error' must be a string or None"),
        (lambda d: d.update(colour="red"), "LiverRun: unexpected key 'colour'"),
    ],
)
def test_a_run_record_read_back_names_its_missing_or_bad_key(change, message):
    data = a_run().to_dict()
    change(data)
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        LiverRun.from_dict(data)


def test_a_study_read_back_names_the_bad_key_and_where_it_is():
    data = a_study().to_dict()
    del data["runs"][1]["substeps"]
    with pytest.raises(ValueError, match=r"^<dict>: runs/1: LiverRun: missing key 'substeps'$"):
        LiverData.from_dict(data)
    data = a_study().to_dict()
    data["oscillation"]["table"][0]["period"] = "long"
    with pytest.raises(
        ValueError, match=r"^<dict>: oscillation/table/0: OscillationRow: key 'period'"
    ):
        LiverData.from_dict(data)
    data = a_study().to_dict()
    del data["n_fixed"]
    with pytest.raises(ValueError, match="LiverData: missing key 'n_fixed'"):
        LiverData.from_dict(data)
    data = a_study().to_dict()
    data["terzaghi"]["times"] = []
    with pytest.raises(ValueError, match="terzaghi: TerzaghiResult: key 'times' must be at least"):
        LiverData.from_dict(data)
    data["terzaghi"] = {"times": [{"T_v": 0.1, "relative_l2_error": 0.005}], "figures": []}
    with pytest.raises(ValueError, match="terzaghi: TerzaghiResult: missing key 'n_layers'"):
        LiverData.from_dict(data)
    with pytest.raises(ValueError, match="LiverData: expected a JSON object, got list"):
        LiverData.from_dict([])


# ----------------------------------------------------------------------------- the records
def test_records_are_frozen_and_refuse_inconsistent_values_on_construction():
    run = a_run()
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.dt = 0.1
    assert isinstance(run.time, tuple) and isinstance(run.retries[1], tuple)
    with pytest.raises(ValueError, match="key 'substeps' must be 2 values"):
        a_run(substeps=[1])
    with pytest.raises(ValueError, match="key 'steps_planned' must be >= the 2 steps taken"):
        a_run(steps_planned=1)
    with pytest.raises(ValueError, match=r"LiverData: key 'runs\[0\]' must be LiverRun, got \{"):
        a_study(runs=(a_run().to_dict(),))
    with pytest.raises(ValueError, match="key 'ms_per_step' must be a finite number > 0"):
        StepSplit("hyperelastic", "numpy", 0.0, dict.fromkeys(PHASES, 0.2))


def test_oscillation_metrics_are_typed():
    from comparisons.liver.oscillation import oscillation_metrics

    t = np.linspace(0.0, 2.0, 201)
    m = oscillation_metrics(t, 0.05 * (1 - np.exp(-3 * t)))
    assert isinstance(m, OscillationMetrics) and m.extrema == 0 and m.period is None
    assert m.final == pytest.approx(0.05 * (1 - np.exp(-6.0)))
