"""The user's organ in the liver study: an anatomical-style legacy gmsh mesh (cm, y up) hung
from three nodes, units, gravity, materials and numbering on the command line, the typed
result and its reproduce command, and the oscillation measurements.
"""

from __future__ import annotations

import json
import shlex

import numpy as np
import pytest

from common.result import Status
from comparisons.cli import main
from comparisons.commands import liver as liver_command_module
from comparisons.liver.oscillation import euler_decay_rate, oscillation_metrics
from comparisons.liver.oscillation_records import OscillationData
from comparisons.liver.records import LiverData, LiverRun
from comparisons.liver.study import BACKEND_AGREEMENT_TOL, MODELS, PHASES, liver_study
from comparisons.liver.terzaghi_records import TerzaghiResult, TerzaghiTime
from mjed.compiled import numba_available

pytest.importorskip("meshio")


@pytest.fixture(scope="module")
def organ_files(tmp_path_factory):
    from meshes.anatomical import write_anatomical_liver

    folder = tmp_path_factory.mktemp("organ")
    path, numbers = write_anatomical_liver(folder / "organ.msh", folder / "ids.txt")
    return folder, path, numbers


def test_a_liver_hung_from_three_nodes_y_up_in_cm_completes_with_substeps(
    organ_files, tmp_path, capsys
):
    """The issue's scenario: legacy gmsh, centimetres, y up, three nodes given in the file's
    numbering. Every model completes; the first 0.3 s step is taken in substeps.
    """
    folder, path, numbers = organ_files
    assert path.read_text().startswith("$NOD\n")
    code = main(
        [
            "liver",
            "--mesh",
            str(path),
            "--units",
            "cm",
            "--gravity",
            "0,-9.81,0",
            "--fixed",
            f"nodes:{folder / 'ids.txt'}",
            "--steps",
            "6",
            "--no-series",
            "--no-oscillation",
            "--out",
            str(tmp_path),
            "--json",
            str(tmp_path / "liver.json"),
        ]
    )
    out = capsys.readouterr().out
    data = json.loads((tmp_path / "liver.json").read_text())
    assert (
        data["key"] == "liver" and data["status"] in ("passed", "target missed") and data["partial"]
    )
    liver = LiverData.from_dict(data["data"])  # the --json file read back, every key checked
    runs = liver.runs
    backends = ["numpy", "numba"] if numba_available() else ["numpy"]
    assert [(r.backend, r.model) for r in runs] == [(b, m) for b in backends for m in MODELS]
    # Every backend follows the same trajectory (the compiled one is checked against NumPy's).
    agreement = liver.backend_agreement
    assert len(agreement) == len(MODELS) * (len(backends) - 1)
    assert all(
        a.relative_difference is not None and a.relative_difference <= BACKEND_AGREEMENT_TOL
        for a in agreement
    )
    for r in runs:
        assert r.error is None and r.steps == r.steps_planned and r.fps > 0
    assert sum(r.steps_split for r in runs) >= 1 and runs[0].substeps[0] > 1
    assert liver.fixed_node_ids == tuple(sorted(numbers.tolist())) and liver.scale == 0.01
    # It hangs: the sag is along -y, in metres.
    assert 0.02 < runs[0].final_max_displacement < 0.3
    assert code == 3  # complete for what it ran, but partial: six steps, no oscillation study
    assert (
        "split" in out
        and "substeps" in out
        and "FPS" in out
        and "reproduce: mjed-verify liver --mesh" in out
    )


def test_units_and_scale_mean_the_same_and_not_both(organ_files, tmp_path):
    folder, path, _ = organ_files
    common = dict(
        mesh=str(path),
        fixed=[f"nodes:{folder / 'ids.txt'}"],
        steps=2,
        series=False,
        oscillation=False,
        models=["hyperelastic"],
    )
    from comparisons.liver.study import LiverParameters

    params = LiverParameters(gravity=(0.0, -9.81, 0.0))
    a = liver_study(out_dir=str(tmp_path / "a"), units="cm", params=params, **common)
    b = liver_study(out_dir=str(tmp_path / "b"), scale=0.01, params=params, **common)
    first = [LiverData.from_dict(r.data).runs[0] for r in (a, b)]
    assert first[0].max_displacement == first[1].max_displacement
    assert (
        main(
            [
                "liver",
                "--mesh",
                str(path),
                "--units",
                "cm",
                "--scale",
                "0.01",
                "--out",
                str(tmp_path),
            ]
        )
        == 2
    )


def test_nodes_files_use_the_mesh_files_numbering_and_index_files_positions(organ_files):
    from common.options import InputError
    from comparisons.liver.organ import fixed_nodes, load_organ

    folder, path, numbers = organ_files
    organ = load_organ(str(path), scale=0.01)
    by_id = fixed_nodes(organ, [f"nodes:{folder / 'ids.txt'}"])
    assert organ.node_ids[by_id].tolist() == sorted(
        numbers.tolist()
    )  # gmsh numbers 1..n -> positions 0..n-1
    index_file = folder / "positions.txt"
    index_file.write_text(" ".join(str(n - 1) for n in numbers))
    assert fixed_nodes(organ, [f"index:{index_file}"]).tolist() == by_id.tolist()
    bad = folder / "bad.txt"
    bad.write_text("0\n")  # gmsh numbers start at 1
    with pytest.raises(
        InputError, match=r"node id 0 is not in the mesh \(gmsh node numbers: 1 to 200"
    ):
        fixed_nodes(organ, [f"nodes:{bad}"])


@pytest.mark.parametrize(
    "content, words",
    [
        (bytes(range(256)) * 4, "not a text file; expected node numbers as text"),
        (b"12345678901234567890\n", "node number 12345678901234567890 is too large"),
    ],
    ids=["binary", "20-digit id"],
)
def test_a_binary_or_absurd_node_file_is_a_clear_error(organ_files, tmp_path, content, words):
    from common.options import InputError
    from comparisons.liver.organ import fixed_nodes, load_organ

    organ = load_organ(str(organ_files[1]), scale=0.01)
    bad = tmp_path / "ids.bin"
    bad.write_bytes(content)
    with pytest.raises(InputError, match=words) as info:
        fixed_nodes(organ, [f"nodes:{bad}"])
    assert str(bad) in str(info.value)


def test_fixing_every_node_is_refused(organ_files, tmp_path, capsys):
    folder, path, _ = organ_files
    every = tmp_path / "all.txt"
    every.write_text("\n".join(str(i) for i in range(1, 201)))
    one_step = "--units cm --gravity 0,-9.81,0 --steps 1 --models hyperelastic --no-series"
    args = ["liver", "--mesh", str(path), "--fixed", f"nodes:{every}", "--out", str(tmp_path)]
    assert main(args + one_step.split() + ["--no-oscillation"]) == 2
    assert "select every one of its 200 nodes; nothing would move" in capsys.readouterr().err


def _two_cubes(gap: float):
    """Two unit cubes of 6 tetrahedra side by side along x, numbered apart (gap 0: they touch,
    with duplicated nodes on the shared face).
    """
    from conftest import box_mesh

    points, cells = box_mesh(1)
    other = points + [1.0 + gap, 0.0, 0.0]
    return np.vstack([points, other]), np.vstack([cells, cells + len(points)])


def test_a_part_of_the_mesh_that_nothing_holds_is_refused(tmp_path):
    from common.options import InputError
    from comparisons.liver.organ import load_organ
    from comparisons.liver.study import run_liver

    organ = load_organ(_two_cubes(0.5))
    with pytest.raises(
        InputError,
        match=r"2 disconnected parts, 1 with no fixed node "
        r"\(8 nodes around "
        r"\[2.0, 0.5, 0.5\]\): such a part would fall freely",
    ):
        run_liver(
            organ=organ,
            fixed=["box:-1,-1,-1,0.1,2,2"],
            steps=1,
            models=["hyperelastic"],
            series=False,
            out=str(tmp_path),
        )


def test_a_mesh_in_several_held_parts_needs_the_option_and_names_duplicated_nodes(tmp_path):
    from common.options import InputError
    from comparisons.liver.organ import check_supports, fixed_nodes, load_organ

    organ = load_organ(_two_cubes(0.0))
    both = fixed_nodes(organ, ["box:-1,-1,-1,0.1,2,2", "box:1.9,-1,-1,3,2,2"])
    with pytest.raises(InputError, match="Run again with --allow-disconnected") as info:
        check_supports(organ, both)
    assert "Nodes at the same position with different ids (0-based positions): 4, 8; 5, 9" in str(
        info.value
    )
    (warning,) = check_supports(organ, both, allow_disconnected=True)
    assert "2 disconnected parts, each with fixed nodes" in warning and "4, 8" in warning


def test_a_negatively_oriented_mesh_names_the_option_that_fixes_it(tmp_path, capsys):
    import meshes
    from meshes.io import write_mesh

    points, cells = meshes.load("liver-coarse")
    flipped = cells.copy()
    flipped[:10, [1, 2]] = flipped[:10, [2, 1]]
    path = write_mesh(tmp_path / "flipped.vtu", points, flipped)
    args = [
        "liver",
        "--mesh",
        str(path),
        "--steps",
        "1",
        "--models",
        "hyperelastic",
        "--no-series",
        "--no-oscillation",
        "--out",
        str(tmp_path),
    ]
    assert main(args) == 2
    assert "Run again with --fix-orientation" in capsys.readouterr().err
    assert main(args + ["--fix-orientation"]) in (0, 3)
    assert "10 cell(s) reoriented (--fix-orientation)" in capsys.readouterr().out


def test_materials_from_the_command_line(tmp_path, capsys):
    from mjed.materials import ArrudaBoyce, NeoHookean

    parse = liver_command_module.material_from_options
    assert parse(None, None, None, "sofa") is None
    assert parse("NeoHookean", ["mu=3000", "lam=30000"], None, "sofa") == NeoHookean(
        mu=3000.0, lam=30000.0
    )
    assert parse("ArrudaBoyce", ["mu=1500"], None, "sofa") == ArrudaBoyce(
        mu=1500.0, k0=20000.0, N=8.0
    )  # liver's k0
    assert parse("ArrudaBoyce", None, "2000 20000", "sofa") == ArrudaBoyce(mu=2000.0, k0=20000.0)
    base = ["liver", "--quick", "--out", str(tmp_path)]
    for extra, word in [
        (["--material", "NeoHookean", "--param", "nu=0.3"], "not a parameter of NeoHookean"),
        (["--material", "Rubber"], "unknown material"),
        (["--param", "mu=1"], "need --material"),
        (["--material", "ArrudaBoyce", "--sofa-parameters", "1 2 3 4"], "expects 2 parameters"),
        (["--allow-inverted"], "ArrudaBoyce does not qualify"),
        (["--gravity", "0,-9.81"], "three comma-separated numbers"),
        (["--dt", "-1"], "dt must be finite and > 0"),
        (["--gravity", "0,-9.81,0"], "default fixed regions (vena cava, ligament) assume a z-up"),
    ]:
        assert main(base + extra) == 2
        assert word in capsys.readouterr().err


def test_the_study_result_and_its_reproduce_command(tmp_path):
    """Checks are typed (Terzaghi and completion as tolerances, FPS as targets); the command
    parsed again gives the same options.
    """
    import argparse

    from comparisons.liver.study import LiverParameters
    from mjed.materials import NeoHookean

    params = LiverParameters(
        material=NeoHookean(mu=2500.0, lam=25000.0),
        dt=0.2,
        rayleigh_mass=0.05,
        gravity=(0.0, 0.0, -5.0),
    )
    result = liver_study(
        quick=True,
        out_dir=str(tmp_path),
        series=False,
        models=["hyperelastic"],
        steps=2,
        params=params,
        oscillation=False,
    )
    kinds = {c.name.split(" ")[0] + " " + c.kind for c in result.checks}
    compiled = {"hyperelastic: tolerance"} if numba_available() else set()  # the backends agree
    assert (
        kinds == {"Terzaghi tolerance", "hyperelastic tolerance", "hyperelastic target"} | compiled
    )
    assert sum("compiled backend" in c.name for c in result.checks) == (
        1 if numba_available() else 0
    )
    assert result.status in (Status.PASSED, Status.TARGET_MISSED) and result.partial
    assert any("quick" in n for n in result.not_covered) and any(
        "oscillation" in n for n in result.not_covered
    )
    argv = shlex.split(result.command)
    assert argv[:2] == ["mjed-verify", "liver"]
    parser = argparse.ArgumentParser()
    liver_command_module.configure(parser)
    again = liver_command_module.liver_options(parser.parse_args(argv[2:]))
    assert again["params"] == params and again["quick"] and again["models"] == ["hyperelastic"]
    assert (
        again["steps"] == 2
        and not again["oscillation"]
        and not again["series"]
        and again["out_dir"] == str(tmp_path)
    )
    assert again["backends"] == ["numpy", "numba"]


def test_backends_option_and_a_missing_numba(tmp_path, monkeypatch, capsys):
    # One backend: no agreement check, the command line says so; an unknown one is bad input (2).
    one = liver_study(
        quick=True,
        out_dir=str(tmp_path),
        series=False,
        models=["hyperelastic"],
        steps=1,
        oscillation=False,
        backends=["numpy"],
    )
    one_data = LiverData.from_dict(one.data)
    assert [r.backend for r in one_data.runs] == ["numpy"] and one_data.backend_agreement == ()
    assert "--backends numpy" in one.command
    assert main(["liver", "--quick", "--backends", "numpy,fortran", "--out", str(tmp_path)]) == 2
    assert "--backends" in capsys.readouterr().err
    # Without Numba the compiled runs are left out and the result says so (partial), not silently.
    import mjed.compiled

    monkeypatch.setattr(mjed.compiled, "numba_available", lambda: False)
    res = liver_study(
        quick=True,
        out_dir=str(tmp_path),
        series=False,
        models=["hyperelastic"],
        steps=1,
        oscillation=False,
    )
    assert [r.backend for r in LiverData.from_dict(res.data).runs] == ["numpy"]
    assert any("Numba is not installed" in n for n in res.not_covered) and res.partial


def test_oscillation_metrics_recover_a_known_damped_oscillation():
    t = np.linspace(0.0, 4.0, 801)
    a = 0.05 + 0.02 * np.exp(-1.5 * t) * np.cos(2 * np.pi * t / 0.4)
    m = oscillation_metrics(t, a)
    assert m.period == pytest.approx(0.4, rel=1e-2) and m.decay_rate == pytest.approx(1.5, rel=2e-2)
    assert m.extrema > 10 and m.final == pytest.approx(a[-1])
    overdamped = oscillation_metrics(t, 0.05 * (1 - np.exp(-3 * t)))
    assert overdamped.decay_rate is None and overdamped.extrema == 0  # no swings


def test_backward_euler_decay_rate_matches_the_scheme_on_an_oscillator():
    """X'' = -w^2 x by backward Euler: the amplitude decays at ln(1 + (w dt)^2) / (2 dt)."""
    w, dt, n = 10.0, 0.03, 200
    A = np.linalg.inv(np.array([[1.0, -dt], [dt * w * w, 1.0]]))  # (x, v)_{k+1} = A (x, v)_k
    rate = -np.log(np.abs(np.linalg.eigvals(np.linalg.matrix_power(A, n)))[0]) / (n * dt)
    assert euler_decay_rate(w, dt) == pytest.approx(rate, rel=1e-10)


@pytest.mark.parametrize(
    "full, quick, mesh, expected",
    [
        (False, False, "liver", ("liver-coarse", (0.3, 0.1, 0.03, 0.01), 3.0)),
        (True, False, "liver", ("liver", (0.3, 0.1, 0.03, 0.01, 0.003), 5.0)),
        (True, True, "liver", ("liver-coarse", (0.3, 0.1, 0.03), 1.5)),  # quick wins over full
    ],
)
def test_the_oscillation_study_sizes(monkeypatch, tmp_path, full, quick, mesh, expected):
    """Which organ, steps and duration the oscillation study uses (the runs themselves stubbed)."""
    import comparisons.liver.oscillation as oscillation_module
    import comparisons.liver.study as liver_module

    seen = {}

    def fake(organ, fixed, params, *, dts, duration, **kw):
        seen.update(label=organ.label, dts=tuple(dts), duration=duration)
        return OscillationData(
            mesh=organ.label,
            dts=tuple(dts),
            duration=duration,
            rayleigh=(0.0, 0.0),
            curves=(),
            table=(),
            amplitude_ordering=(),
            amplitude_ordering_dt=min(dts),
            figures=(),
        )

    monkeypatch.setattr(oscillation_module, "run_oscillations", fake)
    monkeypatch.setattr(liver_module, "run_liver", lambda **kw: _stub_liver_data())
    result = liver_study(quick=quick, out_dir=str(tmp_path), full_oscillation=full, mesh=mesh)
    assert (seen["label"], seen["dts"], seen["duration"]) == expected
    assert ("the full version" in result.protocol) == (full and not quick)


def _stub_liver_data() -> LiverData:
    """A liver study of one hyperelastic run that took no step (for stubbing run_liver)."""
    run = LiverRun(
        model="hyperelastic",
        dt=0.3,
        steps_planned=1,
        error=None,
        time=(0.0,),
        max_displacement=(0.0,),
        cg_iterations=(),
        substeps=(),
        retries=(),
        inverted_cells=(),
        factorizations=0,
        solver="direct",
        force_field="stub",
        backend="numpy",
        stepping_seconds=0.0,
        cpu_fps=None,
        phase_seconds=dict.fromkeys(PHASES, 0.0),
    )
    return LiverData(
        mesh="m",
        mesh_description="m",
        n_nodes=4,
        n_cells=1,
        scale=1.0,
        numbering="0-based positions",
        reoriented_cells=0,
        unused_nodes=0,
        mesh_warnings=(),
        fixed_regions=(),
        n_fixed=0,
        fixed_node_ids=(),
        quick=False,
        duration=0.3,
        parameters={},
        runs=(run,),
        step_split=(),
        backend_agreement=(),
        terzaghi=TerzaghiResult((), 1, 0.1, 1, 0.5, 1.0, 1.0, 1.0, (TerzaghiTime(0.1, 0.0),)),
        figures=(),
        series=(),
    )
