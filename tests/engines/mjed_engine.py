"""A command-line engine for the conformance tests: reads a case input directory, writes the output
with MJED, optionally with one mistake (--mistake force-sign|crash|hang|nan|short|ignore-frame).

    python tests/engines/mjed_engine.py INPUT OUTPUT [--mistake NAME]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--mistake", default="none")
    a = p.parse_args()
    import mjed
    from conformance.kit.exchange import read_case_input, write_output

    case = read_case_input(a.input)
    if a.mistake == "crash":
        print("engine: segmentation fault in assemble() (simulated)", file=sys.stderr)
        return 139
    if a.mistake == "hang":
        time.sleep(600)
    model = case.model
    if a.mistake == "ignore-frame":  # never reads frame.f64: global x, y, z as fibre, sheet, normal
        import dataclasses

        model = dataclasses.replace(model, frame=None)
    field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), model)
    f, K = field.force_and_stiffness(case.positions)
    W = field.energy(case.positions)
    if a.mistake == "force-sign":
        f = -f
    if a.mistake == "nan":
        f = f.copy()
        f[0, 0] = np.nan
    if a.mistake == "short":
        f = f[:-1]
    write_output(a.output, f, K, W)
    return 0


if __name__ == "__main__":
    sys.exit(main())
