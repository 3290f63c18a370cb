"""The liver scenario: a few steps on the coarse mesh, its outputs, and input errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from common.options import InputError
from comparisons.cli import main
from comparisons.liver.records import LiverData
from comparisons.liver.regions import parse_region, select_nodes
from comparisons.liver.study import MODELS, default_fixed_specs, run_liver

pytest.importorskip("meshio", reason="the ParaView series is written with meshio")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("liver")
    return run_liver(quick=True, steps=3, out=str(out), json_path=str(out / "liver.json")), out


def test_three_models_run_and_write_their_outputs(quick_run):
    result, out = quick_run
    assert result.mesh == "liver-coarse" and [r.model for r in result.runs] == list(MODELS)
    hyper, visco, poro = result.runs
    assert hyper.dt == 0.3 and poro.dt == 0.15 and poro.steps == 2 * hyper.steps
    for r in result.runs:
        amp = np.asarray(r.max_displacement)
        assert (
            amp[0] == 0.0 and np.all(np.isfinite(amp)) and amp[-1] > 1e-3
        )  # it sags under gravity
        assert r.fps > 0
    # The Prony series softens the response: the visco liver sags further than the elastic one.
    assert visco.final_max_displacement > hyper.final_max_displacement
    assert max(abs(p) for p in poro.max_abs_pressure) > 0  # the fluid responds
    for path in result.figures + result.series:
        assert (out / path.split("/")[-1]).is_file()
    assert len(result.figures) == 5 and len(result.series) == 3
    assert result.passed and result.terzaghi_error <= 1e-2
    for r in result.runs:  # substeps and where the time went, per step and per run
        assert len(r.substeps) == r.steps and r.substeps_total >= r.steps
        assert set(r.phase_seconds) == {
            "hyperelastic force + stiffness",
            "other forces",
            "building the system",
            "linear solve",
            "rest",
        }
    split = {s.model: s.shares for s in result.step_split}
    assert set(split) == set(MODELS) and all(
        abs(sum(v.values()) - 1) < 1e-12 for v in split.values()
    )
    assert (
        split["hyperelastic"]["other forces"] == 0
        and split["visco-poro-hyperelastic"]["other forces"] > 0
    )
    assert LiverData.from_dict(json.loads((out / "liver.json").read_text())) == result


def test_series_holds_displacement_J_and_pressure(quick_run):
    import re

    import meshio

    result, out = quick_run
    pvd = out / "liver_visco-poro-hyperelastic.pvd"
    files = re.findall(r'file="([^"]+)"', pvd.read_text())
    assert len(files) == result.runs[2].steps + 1
    last = meshio.read(out / files[-1])
    assert set(last.point_data) == {"displacement", "pressure"} and "J" in last.cell_data
    assert last.point_data["displacement"].shape == last.points.shape
    assert np.all(last.cell_data["J"][0] > 0)
    amplitude = np.linalg.norm(last.point_data["displacement"], axis=1).max()
    assert amplitude == pytest.approx(result.runs[2].final_max_displacement, rel=1e-12)


def test_default_fixed_region_is_not_empty_on_both_liver_meshes():
    import meshes

    for name in ("liver", "liver-coarse"):
        points, _ = meshes.load(name)
        nodes = select_nodes(default_fixed_specs(points), points)
        assert 0.05 < len(nodes) / len(points) < 0.3


def test_region_specs(tmp_path):
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    assert parse_region("box:-0.1,-0.1,-0.1,0.5,0.5,0.5", points).tolist() == [0]
    assert parse_region("sphere:1,1,1,0.1", points).tolist() == [4]
    f = tmp_path / "nodes.txt"
    f.write_text("# ligament\n3, 1\n1\n")
    assert parse_region(f"nodes:{f}", points).tolist() == [1, 3]
    assert select_nodes(["sphere:1,1,1,0.1", f"nodes:{f}"], points).tolist() == [1, 3, 4]
    for spec, match in [
        ("box:1,2,3", "6"),
        ("box:1,1,1,0,0,0", "minimum"),
        ("sphere:0,0,0,-1", "radius"),
        ("cube:1", "unknown kind"),
        ("box", "expected"),
        (f"nodes:{tmp_path / 'missing.txt'}", "no such file"),
    ]:
        with pytest.raises(InputError, match=match):
            parse_region(spec, points)
    f.write_text("7\n")
    with pytest.raises(InputError, match="outside"):
        parse_region(f"nodes:{f}", points)
    with pytest.raises(InputError, match="select no node"):
        select_nodes(["box:5,5,5,6,6,6"], points)


def test_mesh_without_volume_cells_and_bad_input_are_refused(tmp_path, capsys):
    import meshio

    surface = tmp_path / "surface.vtu"
    meshio.write(str(surface), meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 2]]))]))
    with pytest.raises(InputError, match="no linear tetrahedra"):
        run_liver(str(surface), out=str(tmp_path))
    with pytest.raises(InputError, match="select no node"):
        run_liver("liver-coarse", fixed=["box:5,5,5,6,6,6"], out=str(tmp_path))
    with pytest.raises(InputError, match="unknown liver model"):
        run_liver("liver-coarse", models=["elastic"], out=str(tmp_path))
    # The CLI turns them into exit code 2 with the message.
    assert main(["liver", "--quick", "--fixed", "sphere:0,0,0,-1", "--out", str(tmp_path)]) == 2
    assert "radius" in capsys.readouterr().err
    assert main(["liver", "--mesh", str(surface), "--out", str(tmp_path)]) == 2


def test_a_failing_run_is_reported_not_hidden(tmp_path):
    """A force field whose stiffness is indefinite at every state (forced: K negated) fails at
    every substep: the run records the integrator's clear message and the study does not pass.
    """
    from comparisons.liver.study import numpy_force_field

    class Indefinite:
        def __init__(self, inner):
            self.inner = inner

        def force_and_stiffness(self, x):
            f, K = self.inner.force_and_stiffness(x)
            return f, -K

    def broken(mesh, material, **kw):
        return Indefinite(numpy_force_field(mesh, material, **kw))

    result = run_liver(
        "liver-coarse",
        steps=3,
        out=str(tmp_path),
        series=False,
        models=["hyperelastic"],
        force_fields=[broken],
    )
    (run,) = result.runs
    assert not result.passed and run.steps == 0 < run.steps_planned
    assert run.error.startswith("time step 1 (t = 0.3 s) failed:")
    assert (
        "retried in substeps down to dt/16 = 0.0187 s" in run.error
        and "kept the state" in run.error
    )
    assert (
        main(
            [
                "liver",
                "--quick",
                "--models",
                "hyperelastic",
                "--no-series",
                "--no-oscillation",
                "--out",
                str(tmp_path),
            ]
        )
        == 3
    )  # passed, but partial (quick, one model)


def test_a_soft_organ_survives_in_substeps(tmp_path):
    """Mu = 50 Pa: the 0.3 s linearised step is refused whole and taken in substeps, reported."""
    from comparisons.liver.study import LiverParameters
    from mjed.materials import ArrudaBoyce

    result = run_liver(
        "liver-coarse",
        steps=3,
        out=str(tmp_path),
        series=False,
        models=["hyperelastic"],
        params=LiverParameters(material=ArrudaBoyce(mu=50.0, k0=500.0)),
    )
    (run,) = result.runs
    assert run.error is None and run.steps == 3 and run.steps_split >= 1
    assert run.substeps_total > 3 and any(run.retries)
    assert result.to_dict()["fps_table"][0]["steps_split"] == run.steps_split


def test_the_solver_options_change_the_cost_not_the_motion(tmp_path):
    """Jacobi CG, the kept-factorisation preconditioner (the default) and the direct solve give
    the same amplitudes to the CG tolerance; the FPS table says which solver ran.
    """
    from comparisons.liver.study import LiverParameters

    runs = {}
    import dataclasses

    from comparisons.liver.study import LIVER_SOLVER

    for name, params in (
        ("factorized", LiverParameters()),
        (
            "jacobi",
            LiverParameters(solver=dataclasses.replace(LIVER_SOLVER, preconditioner="jacobi")),
        ),
        ("direct", LiverParameters(solver=dataclasses.replace(LIVER_SOLVER, solver="direct"))),
    ):
        result = run_liver(
            quick=True,
            steps=3,
            out=str(tmp_path / name),
            params=params,
            models=["visco-poro-hyperelastic"],
            series=False,
        )
        runs[name] = result
        assert result.passed and result.to_dict()["fps_table"][0]["solver"] == result.runs[0].solver
    amp = {k: np.asarray(r.runs[0].max_displacement) for k, r in runs.items()}
    scale = amp["direct"].max()
    for k in ("factorized", "jacobi"):
        np.testing.assert_allclose(amp[k], amp["direct"], rtol=0, atol=2e-6 * scale)  # CG rtol 1e-5
    fact, jac = runs["factorized"].runs[0], runs["jacobi"].runs[0]
    assert (
        "kept single-precision sparse LU" in fact.solver
        and "jacobi" in jac.solver
        and "direct" in runs["direct"].runs[0].solver
    )
    assert fact.factorizations >= 1 and jac.factorizations == 0
    assert fact.cg_iterations_mean < jac.cg_iterations_mean / 5


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(solver="cg"), "solver"),
        (dict(dt=0.0), "dt"),
        (dict(gravity=(0.0, 9.81)), "gravity"),
        (dict(max_halvings=-1), "max_halvings"),
        (dict(max_volume_change=1.0), "max_volume_change"),
        (dict(allow_inverted=True), "ArrudaBoyce does not qualify"),
    ],
)
def test_bad_liver_parameters_are_refused_by_name(kwargs, word):
    from comparisons.liver.study import LiverParameters

    with pytest.raises(ValueError, match=word):
        LiverParameters(**kwargs)
