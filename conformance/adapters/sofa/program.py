"""Finding, and building, the engine program ``sofa_engine`` (sofa_engine.cpp beside this file).

The program links SOFA and the SofaMJEDFEM plugin; it is built against a SOFA that the user
has built (the project never builds SOFA itself). Where it is looked for, first found wins:

1. ``$MJED_SOFA_ENGINE``, the path of the program;
2. ``build/sofa-engine/sofa_engine`` under the repository (what :func:`build` writes).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Optional

__all__ = ["SOURCE_DIR", "DEFAULT_BUILD_DIR", "build", "find_program", "how_to_build"]

SOURCE_DIR = Path(__file__).resolve().parent
DEFAULT_BUILD_DIR = SOURCE_DIR.parents[2] / "build" / "sofa-engine"
ENV = "MJED_SOFA_ENGINE"


def how_to_build() -> str:
    """What to do when the program is missing, in words a SOFA user can act on."""
    return (
        "the SOFA engine program is not built. It needs a SOFA build (or installation) with "
        "the SofaMJEDFEM plugin and the module Sofa.Component.SolidMechanics.FEM.HyperElastic; "
        "then run: python -m conformance.adapters.sofa build --sofa SOFA_BUILD_DIR "
        f"(or set {ENV} to an existing sofa_engine)"
    )


def find_program() -> Optional[Path]:
    """The engine program's path, or None when there is none (see :func:`how_to_build`)."""
    given = os.environ.get(ENV)
    if given:
        path = Path(given)
        return path if path.is_file() and os.access(path, os.X_OK) else None
    path = DEFAULT_BUILD_DIR / "sofa_engine"
    return path if path.is_file() and os.access(path, os.X_OK) else None


def build(sofa_dir: Path, build_dir: Path = DEFAULT_BUILD_DIR) -> Path:
    """Configure and compile sofa_engine against the SOFA at ``sofa_dir`` (its build or install
    folder, which holds ``lib/cmake``). Returns the program's path.

    Raises:
        FileNotFoundError: cmake missing, or no ``lib/cmake`` under ``sofa_dir``.
        subprocess.CalledProcessError: configuring or compiling failed (CMake's output is shown).
    """
    if shutil.which("cmake") is None:
        raise FileNotFoundError("cmake is not on PATH (Debian: apt install cmake)")
    config_dir = Path(sofa_dir).resolve() / "lib" / "cmake"
    if not config_dir.is_dir():
        raise FileNotFoundError(f"{config_dir}: no such folder; is {sofa_dir} a SOFA build?")
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    subprocess.run(
        [
            "cmake",
            *generator,
            "-S",
            str(SOURCE_DIR),
            "-B",
            str(build_dir),
            "-DCMAKE_BUILD_TYPE=Release",
            f"-DCMAKE_PREFIX_PATH={config_dir}",
        ],
        check=True,
    )
    subprocess.run(["cmake", "--build", str(build_dir)], check=True)
    return Path(build_dir) / "sofa_engine"
