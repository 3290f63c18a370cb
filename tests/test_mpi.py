"""The oracle on 2 MPI ranks (mpirun in a subprocess) against the same oracle in serial.

dolfinx partitions cube-small over the ranks; force and stiffness gathered on rank 0 in
input order must equal the serial ones to 1e-12 relative, and `mjed-verify equivalence`
under mpirun must report the same cases, all passing, printed once.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from reference_fem import dolfinx_available

pytestmark = [
    pytest.mark.oracle,
    pytest.mark.skipif(
        not dolfinx_available(), reason="the UFL oracle needs dolfinx (Debian: python3-dolfinx)"
    ),
]

REPO = Path(__file__).resolve().parents[1]
RANKS = 2


def _launcher():
    from comparisons.cross_release.study import mpirun_command

    try:
        return mpirun_command(sys.executable, RANKS)
    except FileNotFoundError as exc:
        pytest.skip(f"cannot test MPI runs: {exc}")


def _mpirun(args, timeout=240):
    prefix, extra = _launcher()
    env = {**os.environ, **extra}
    return subprocess.run(
        prefix + args, cwd=str(REPO), env=env, capture_output=True, text=True, timeout=timeout
    )


def _verify_command():
    script = Path(sys.executable).parent / "mjed-verify"  # the installed entry point
    return [str(script)] if script.exists() else [sys.executable, "-m", "comparisons.cli"]


def test_two_rank_oracle_equals_serial_oracle(tmp_path):
    from comparisons.cross_release.study import (
        TOLERANCE,
        compare_snapshots,
        load_snapshot,
        take_snapshot,
    )
    from reference_fem.compat import comm_self

    out = tmp_path / "mpi.npz"
    proc = _mpirun(
        [
            sys.executable,
            "-m",
            "comparisons.cross_release.study",
            "snapshot",
            "--quick",
            "--out",
            str(out),
        ]
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    parallel = load_snapshot(str(out))
    meta = parallel["meta"]
    # dolfinx really split the mesh: both ranks own cells, and all 510 of them together.
    assert meta["mpi_ranks"] == RANKS and len(meta["cells_per_rank"]) == RANKS
    assert min(meta["cells_per_rank"]) > 0 and sum(meta["cells_per_rank"]) == 510
    serial = take_snapshot(quick=True, comm=comm_self())
    diff = compare_snapshots(serial, parallel)
    assert diff.passed, diff
    assert diff.worst <= TOLERANCE
    # Not vacuous: the comparison sees a change of one force entry by 1e-8 of the largest.
    case = next(iter(parallel["cases"].values()))
    case["force"][0, 0] += 1e-8 * abs(case["force"]).max()
    assert not compare_snapshots(serial, parallel).passed


def test_mpirun_equivalence_reports_what_a_serial_run_reports(tmp_path):
    from comparisons.cli import main

    args = [
        "equivalence",
        "--material",
        "NeoHookean,Costa",
        "--mesh",
        "cube-small",
        "--states",
        "random,shear",
    ]
    out = tmp_path / "mpi.json"
    proc = _mpirun(_verify_command() + args + ["--json", str(out)])
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.count("4/4 cases pass") == 1  # only rank 0 prints
    assert "oracle on 2 MPI ranks" in proc.stdout
    written = json.loads(out.read_text())
    assert written["command"].startswith(
        f"mpirun -n {RANKS} mjed-verify equivalence"
    )  # reproduces the run
    parallel = written["data"]
    assert parallel["mpi_ranks"] == RANKS

    serial_out = tmp_path / "serial.json"
    assert main(args + ["--quiet", "--json", str(serial_out)]) == 0
    serial = json.loads(serial_out.read_text())["data"]
    key = lambda c: (c["material"], c["mesh"], c["state"], c["n_cells"], c["n_nodes"])  # noqa: E731
    assert [key(c) for c in parallel["cases"]] == [key(c) for c in serial["cases"]]
    assert len(parallel["cases"]) == 4 and all(c["passed"] for c in parallel["cases"])
    # Errors at round-off on both: the serial and parallel oracles differ at ~1e-15 at most.
    for p, s in zip(parallel["cases"], serial["cases"]):
        assert abs(p["force_rel_err"] - s["force_rel_err"]) <= 1e-12
        assert abs(p["stiffness_rel_err"] - s["stiffness_rel_err"]) <= 1e-12


def test_mpirun_equivalence_refuses_bad_input_on_every_rank(tmp_path):
    proc = _mpirun(
        _verify_command() + ["equivalence", "--mesh", str(tmp_path / "missing.msh")], timeout=120
    )
    assert proc.returncode == 2
    assert "missing.msh" in proc.stderr
