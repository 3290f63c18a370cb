"""Per-cell frames left in the kit's cell order while the engine sorted its cells
(conformance.diagnosis.frames, ``frame-cells-sorted``). The mistaken engine is MJED on Costa
given the cells in its own sorted order and the kit's frames as they are; the oracle judges.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from common.cases import default_material
from conformance.diagnosis.frames import frame_models
from reference_fem import dolfinx_available


def test_sorted_cell_orders_are_offered_once_each_and_not_where_nothing_moves():
    R = np.linalg.qr(np.random.default_rng(0).standard_normal((4, 3, 3)))[0]
    R = R * np.sign(np.linalg.det(R))[:, None, None]
    model = replace(default_material("Costa"), frame=R)
    cells = np.array([[3, 4, 5, 6], [0, 1, 2, 3], [2, 3, 4, 7], [1, 2, 6, 7]])
    found = [
        (t, np.asarray(m.frame))
        for c, t, m in frame_models(model, cells)
        if c == "frame-cells-sorted"
    ]
    # lowest node: order (1, 3, 2, 0); the first node and the sorted nodes give the same order
    # (one variant, said by the first key)
    assert len(found) == 1, [t for t, _ in found]
    title, frame = found[0]
    assert "lowest node" in title and "3 of the 4 cells" in title
    order = np.array([1, 3, 2, 0])
    assert np.array_equal(frame[order], R)  # the engine's j-th cell, kit cell order[j], gets R[j]
    in_order = np.sort(cells, axis=0)  # already sorted by every node key: nothing moves
    assert not [c for c, _, _ in frame_models(model, in_order) if c == "frame-cells-sorted"]


def _checked(key):
    """MJED on Costa with the cells sorted by ``key(cells)`` (stable) and the kit's frames
    left in the kit's cell order; cube-small, random state, no probes.
    """
    import mjed
    from conformance.protocol import check_implementation

    def engine(case):
        cells = np.asarray(case.cells)
        order = np.argsort(key(cells), kind="stable")
        field = mjed.make_force_field(mjed.TetMesh(case.points, cells[order]), case.model)
        return field.force(case.positions), field.stiffness(case.positions)

    run = check_implementation(
        engine,
        material=default_material("Costa"),
        mesh="cube-small",
        states=("random",),
        probes=False,
    )
    (outcome,) = run.outcomes
    return outcome


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_frames_left_in_order_after_sorting_the_cells_by_their_lowest_node_are_named():
    outcome = _checked(lambda cells: cells.min(axis=1))
    causes = outcome.diagnosis.causes
    assert outcome.status == "failed" and causes, outcome.diagnosis.text()
    assert [c.code for c in causes] == ["frame-cells-sorted"], outcome.diagnosis.text()
    assert "lowest node" in causes[0].title


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_a_sort_by_another_key_is_not_named_as_one_of_the_declared_sorts():
    """Cells sorted by their highest node (no declared key): not named as a declared sort."""
    outcome = _checked(lambda cells: -cells.max(axis=1))
    assert outcome.status == "failed"
    assert all(c.code != "frame-cells-sorted" for c in outcome.diagnosis.causes), (
        outcome.diagnosis.text()
    )
