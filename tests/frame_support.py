"""What the tests of the fibre-frame readings share: MJED on Costa given the frames a mistaken
engine would use, checked on cube-small (tests/test_diagnosis_frame_*.py, test_diagnosis_cells).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from common.cases import default_material


def check_with_frames(used: Callable[[np.ndarray, np.ndarray], np.ndarray], state: str):
    """The outcome of checking MJED on Costa computed with the frames ``used(R, cells)`` (R the
    kit's per-cell frames (m, 3, 3), cells (m, 4)) instead of R, in ``state`` on cube-small.
    """
    import mjed
    from conformance.protocol import check_implementation

    def engine(case):
        R = np.asarray(case.model.frame)
        frames = np.ascontiguousarray(used(R, np.asarray(case.cells)))
        wrong = replace(case.model, frame=frames)
        field = mjed.make_force_field(mjed.TetMesh(case.points, case.cells), wrong)
        return field.force(case.positions), field.stiffness(case.positions)

    run = check_implementation(
        engine, material=default_material("Costa"), mesh="cube-small", states=(state,), probes=False
    )
    (outcome,) = run.outcomes
    return outcome
