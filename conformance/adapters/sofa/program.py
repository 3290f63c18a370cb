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
import sys
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
    """Compile sofa_engine against the SOFA at ``sofa_dir``; link it as ``build_dir/sofa_engine``.

    A SOFA *build* folder (it has a CMakeCache.txt) gets this folder added to its
    ``SOFA_EXTERNAL_DIRECTORIES`` (said on stderr; the other entries are kept) and builds the
    target ``sofa_engine``, so the program links the very libraries of that build. A SOFA
    *installation* (``lib/cmake`` with the packages' target files) is built against from
    ``build_dir``. Either way the SOFA commits found are written to ``sofa_commits.txt`` beside
    the program, for every figure to name its source.

    Raises:
        FileNotFoundError: cmake missing, or ``sofa_dir`` neither a SOFA build nor install.
        subprocess.CalledProcessError: configuring or compiling failed (CMake's output is shown).
    """
    if shutil.which("cmake") is None:
        raise FileNotFoundError("cmake is not on PATH (Debian: apt install cmake)")
    sofa_dir = Path(sofa_dir).resolve()
    build_dir = Path(build_dir)
    build_dir.mkdir(parents=True, exist_ok=True)
    cache = sofa_dir / "CMakeCache.txt"
    if cache.is_file():
        program = _build_in_tree(sofa_dir, cache)
    else:
        program = _build_against_install(sofa_dir, build_dir)
    link = build_dir / "sofa_engine"
    if link != program:
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(program)
    (build_dir / "sofa_commits.txt").write_text(_commits(sofa_dir) + "\n")
    return link


def _cache_value(cache: Path, key: str) -> str:
    for line in cache.read_text(errors="replace").splitlines():
        if line.startswith(key + ":"):
            return line.split("=", 1)[1]
    return ""


def _build_in_tree(sofa_dir: Path, cache: Path) -> Path:
    entries = [e for e in _cache_value(cache, "SOFA_EXTERNAL_DIRECTORIES").split(";") if e]
    if str(SOURCE_DIR) not in entries:
        entries.append(str(SOURCE_DIR))
        print(
            f"sofa adapter: adding {SOURCE_DIR} to SOFA_EXTERNAL_DIRECTORIES of {sofa_dir}",
            file=sys.stderr,
        )
        subprocess.run(
            ["cmake", f"-DSOFA_EXTERNAL_DIRECTORIES={';'.join(entries)}", str(sofa_dir)], check=True
        )
    subprocess.run(["cmake", "--build", str(sofa_dir), "--target", "sofa_engine"], check=True)
    return sofa_dir / "bin" / "sofa_engine"


def _build_against_install(sofa_dir: Path, build_dir: Path) -> Path:
    config_dir = sofa_dir / "lib" / "cmake"
    if not config_dir.is_dir():
        raise FileNotFoundError(
            f"{sofa_dir}: neither a SOFA build (no CMakeCache.txt) nor an installation "
            f"(no {config_dir})"
        )
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    subprocess.run(
        [
            "cmake",
            *generator,
            "-S",
            str(SOURCE_DIR),
            "-B",
            str(build_dir / "cmake"),
            "-DCMAKE_BUILD_TYPE=Release",
            f"-DCMAKE_PREFIX_PATH={config_dir}",
        ],
        check=True,
    )
    subprocess.run(["cmake", "--build", str(build_dir / "cmake")], check=True)
    return build_dir / "cmake" / "sofa_engine"


def _commits(sofa_dir: Path) -> str:
    """'<folder> at <commit>' for SOFA's sources and each external directory that is a git
    checkout ('not a git checkout' otherwise): what the program was built from.
    """
    cache = sofa_dir / "CMakeCache.txt"
    folders = []
    if cache.is_file():
        folders.append(_cache_value(cache, "CMAKE_HOME_DIRECTORY"))
        folders += [e for e in _cache_value(cache, "SOFA_EXTERNAL_DIRECTORIES").split(";") if e]
    else:
        folders.append(str(sofa_dir))
    described = []
    for folder in folders:
        if not folder or Path(folder) == SOURCE_DIR:
            continue
        done = subprocess.run(
            ["git", "-C", folder, "rev-parse", "HEAD"], capture_output=True, text=True
        )
        commit = done.stdout.strip() if done.returncode == 0 else "not a git checkout"
        described.append(f"{folder} at {commit}")
    return "; ".join(described)
