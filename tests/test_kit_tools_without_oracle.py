"""The kit tools run where the oracle's stack is not installed: on a GPU machine,
scripts/gpu_session.sh exports kits, fills them with the cuda backend and compares them with a
CPU-filled kit there, and they are checked elsewhere. A diagnosis module that imported UFL on
import broke that once: `export` failed on the device with "No module named 'ufl'".

The tools run in a fresh interpreter in which dolfinx, UFL, FFCx, basix and petsc4py cannot be
imported, whether or not this machine has them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ORACLE_STACK = ("dolfinx", "ufl", "ffcx", "basix", "petsc4py")

BLOCK = f"""
import sys
class NoOracleStack:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {ORACLE_STACK!r}:
            raise ImportError(f"{{name}} is not installed here (blocked by the test)")
sys.meta_path.insert(0, NoOracleStack())
"""


def _run(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run(
        [sys.executable, "-c", BLOCK + code],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=600,
    )


def test_the_blocker_blocks(tmp_path):
    proc = _run("import ufl", tmp_path)
    assert proc.returncode != 0 and "blocked by the test" in proc.stderr


def test_export_fill_and_compare_kits_without_the_oracle(tmp_path):
    code = f"""
import json
from comparisons.cli import main as verify
from conformance.adapters.mjed_backend import main as adapter
from conformance.kit.agreement import main as agreement

for name in ("a", "b"):
    kit = {str(tmp_path)!r} + "/" + name
    assert verify(["export", kit, "--material", "NeoHookean", "--mesh", "cube-small",
                   "--states", "rest,uniaxial", "--no-probes"]) in (0, None)
    assert adapter(["--kit", kit, "--backend", "numpy"]) in (0, None)
code = agreement([{str(tmp_path / "a")!r}, {str(tmp_path / "b")!r}])
print(json.dumps({{"agreement": code}}))
"""
    proc = _run(code, tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == {"agreement": 0}
