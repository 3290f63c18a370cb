"""SOFA's own force fields as an engine of the exchange format.

Find the engine program, or say how to build it::

    python -m conformance.adapters.sofa

Build it against a SOFA build that has the SofaMJEDFEM plugin::

    python -m conformance.adapters.sofa build --sofa ~/sofa/build

One case, the ``--command`` way (``--forcefield`` mjed, hyperelasticity or standard)::

    mjed-verify export kit/ --material NeoHookean,MooneyRivlin --mesh cube-paper
    mjed-verify check kit/ --command \
        'python -m conformance.adapters.sofa case --forcefield mjed {input} {output}'

Exit codes: 0 written; 1 SOFA's program failed (its message is passed on); 2 the case's
material cannot be expressed in that SOFA force field (the reason is printed), or bad
arguments; 3 the engine program is not built (how to build it is printed).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from conformance.adapters.sofa.mapping import FORCEFIELDS, NotExpressible, sofa_material
from conformance.adapters.sofa.program import build, find_program, how_to_build

EXIT_NOT_EXPRESSIBLE = 2
EXIT_NOT_BUILT = 3


def _case_frame(input_dir: Path, case: dict) -> Optional[np.ndarray]:
    spec = case.get("arrays", {}).get("frame")
    if spec is None:
        return None
    values = np.fromfile(input_dir / spec["file"], dtype=spec["dtype"])
    return values.reshape(spec["shape"])


def run_case(
    forcefield: str,
    input_dir: Path,
    output_dir: Path,
    regularize: bool = False,
    as_material: Optional[str] = None,
    program: Optional[Path] = None,
) -> int:
    """Compute one case with SOFA; returns the exit code (see the module's docstring)."""
    program = program or find_program()
    if program is None:
        print(f"sofa adapter: {how_to_build()}", file=sys.stderr)
        return EXIT_NOT_BUILT
    case = json.loads((input_dir / "case.json").read_text())
    try:
        material = sofa_material(
            case["model"], forcefield, _case_frame(input_dir, case), as_material
        )
    except NotExpressible as why:
        print(
            f"sofa adapter: {case.get('case')}: not expressible in "
            f"{FORCEFIELDS[forcefield]}: {why}",
            file=sys.stderr,
        )
        return EXIT_NOT_EXPRESSIBLE
    output_dir.mkdir(parents=True, exist_ok=True)
    command = [
        str(program),
        "--forcefield",
        forcefield,
        "--material",
        material.name,
        "--parameters",
        material.parameter_set(),
        str(input_dir),
        str(output_dir),
    ]
    if regularize:
        command.insert(1, "--regularize")
    # SOFA prints its own messages on stdout; the check reads only the files
    done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        sys.stderr.write(done.stderr)
        return 1
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m conformance.adapters.sofa",
        description="SOFA's hyperelastic force fields as a kit engine (see the module docs)",
    )
    sub = parser.add_subparsers(dest="command")
    case = sub.add_parser("case", help="compute one case's force and stiffness with SOFA")
    case.add_argument("--forcefield", choices=sorted(FORCEFIELDS), required=True)
    case.add_argument(
        "--regularize",
        action="store_true",
        help="SOFA's matrixRegularization (K is then not the exact Hessian)",
    )
    case.add_argument(
        "--as-material",
        metavar="NAME",
        help="read a user-energy case as this material (its parameters named as the "
        "material's), e.g. Costa written in the global axes",
    )
    case.add_argument("input", type=Path)
    case.add_argument("output", type=Path)
    make = sub.add_parser("build", help="compile the engine program against a SOFA build")
    make.add_argument(
        "--sofa",
        type=Path,
        required=True,
        help="a SOFA build or install folder (with lib/cmake) that has SofaMJEDFEM",
    )
    args = parser.parse_args(argv)

    if args.command == "case":
        return run_case(args.forcefield, args.input, args.output, args.regularize, args.as_material)
    if args.command == "build":
        try:
            print(build(args.sofa))
        except (FileNotFoundError, subprocess.CalledProcessError) as error:
            print(f"sofa adapter: build failed: {error}", file=sys.stderr)
            return 1
        return 0
    program = find_program()
    if program is None:
        print(how_to_build())
        return EXIT_NOT_BUILT
    print(program)
    return 0


if __name__ == "__main__":
    sys.exit(main())
