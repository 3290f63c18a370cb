"""The liver study with the cuda backends on Numba's CUDA simulator, on a tiny organ, printed
as JSON (tests/test_liver_gpu.py runs this in a subprocess: NUMBA_ENABLE_CUDASIM must be set
before Numba is first imported).

    NUMBA_ENABLE_CUDASIM=1 python tests/liver_cuda_simulated.py OUT_DIR

Two runs, both with the numpy backend first (the reference) and then cuda and cuda-fp32:

- ``command``: ``mjed-verify liver`` on a 48-cell box written as a gmsh file, every model,
  1 step, the study's own solver tolerance (its exit code, printed table and JSON);
- ``tight``: the Python study, hyperelastic, 3 steps, every linear solve to a relative
  residual of 1e-12, so that the trajectories differ by the force fields' arithmetic alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import sys


def _write_msh(path: str, points, cells) -> None:
    """A gmsh 2.2 text file (read by meshes.io's own reader, without meshio)."""
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", str(len(points))]
    lines += [f"{i + 1} {x!r} {y!r} {z!r}" for i, (x, y, z) in enumerate(points)]
    lines += ["$EndNodes", "$Elements", str(len(cells))]
    lines += [f"{e + 1} 4 2 1 1 " + " ".join(str(v + 1) for v in c) for e, c in enumerate(cells)]
    lines += ["$EndElements"]
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def _runs(data) -> list:
    keys = ("model", "backend", "steps", "steps_planned", "error", "solver", "force_field", "fps")
    return [{k: r[k] for k in keys} for r in data["runs"]]


def main(out: str) -> dict:
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1", "run with NUMBA_ENABLE_CUDASIM=1"
    from comparisons.cli import main as cli
    from comparisons.liver.study import LIVER_SOLVER, LiverParameters, liver_study
    from meshes.structured import structured_box

    points, cells = structured_box(2, (0.1, 0.1, 0.1))  # 48 cells, 27 nodes, 10 cm
    top = "box:-1,-1,0.099,1,1,1"  # hung from its top face, gravity -z
    mesh_file = os.path.join(out, "box.msh")
    _write_msh(mesh_file, points, cells)
    printed = io.StringIO()
    argv = ["liver", "--mesh", mesh_file, "--fixed", top, "--backends", "numpy,cuda,cuda-fp32"]
    argv += ["--steps", "1", "--no-series", "--no-oscillation"]
    argv += ["--out", os.path.join(out, "command"), "--json", os.path.join(out, "liver.json")]
    with contextlib.redirect_stdout(printed):
        code = cli(argv)
    with open(os.path.join(out, "liver.json")) as fh:
        data = json.load(fh)
    result = {
        "command": {
            "exit_code": code,
            "printed": printed.getvalue(),
            "status": data["status"],
            "runs": _runs(data["data"]),
            "agreement": data["data"]["backend_agreement"],
        }
    }
    tight = dataclasses.replace(LIVER_SOLVER, cg_tol=1e-12)
    study = liver_study(
        mesh=(points, cells),
        fixed=[top],
        steps=3,
        models=["hyperelastic"],
        backends=["numpy", "cuda", "cuda-fp32"],
        params=LiverParameters(solver=tight),
        oscillation=False,
        series=False,
        out_dir=os.path.join(out, "tight"),
    )
    result["tight"] = {
        "runs": _runs(study.data),
        "agreement": study.data["backend_agreement"],
        "peak": [max(r["max_displacement"]) for r in study.data["runs"]],
    }
    return result


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1])))
