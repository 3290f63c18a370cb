"""A frame energy's columns taken in another order is the same energy as its coefficients b_xy
exchanged (conformance.diagnosis.frames): the frame-columns cause says so, naming exactly the
coefficients whose values differ, and the two energies are equal.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import MATERIALS, deformed_cube

import mjed
from conformance.diagnosis.frames import _same_as_coefficients_exchanged


def test_sheet_and_normal_exchanged_is_the_fs_fn_and_ss_nn_coefficients_exchanged():
    costa = MATERIALS["Costa"]
    said = _same_as_coefficients_exchanged(costa, (0, 2, 1))
    assert "b_fn and b_fs exchanged" in said and "b_nn and b_ss exchanged" in said
    # equal sheet and normal coefficients: only the shear pair differs
    same_ss_nn = dataclasses.replace(costa, b_nn=costa.b_ss)
    said = _same_as_coefficients_exchanged(same_ss_nn, (0, 2, 1))
    assert "b_fn and b_fs exchanged" in said and "b_ss" not in said
    # a cycle of the columns permutes more than pairs
    assert "permuted" in _same_as_coefficients_exchanged(costa, (1, 2, 0))
    # coefficients all equal: the column order changes nothing that a coefficient could say
    equal = dataclasses.replace(
        costa, split="eigen", **{n: 0.5 for n in ("b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn")}
    )
    assert _same_as_coefficients_exchanged(equal, (0, 2, 1)) == ""
    # an energy without such coefficients
    assert _same_as_coefficients_exchanged(MATERIALS["NeoHookean"], (0, 2, 1)) == ""


@pytest.mark.parametrize("order", [(0, 2, 1), (1, 0, 2), (2, 1, 0)])
def test_the_two_energies_are_equal(order):
    from scipy.spatial.transform import Rotation

    mesh, x = deformed_cube()
    R = Rotation.random(mesh.n_cells, random_state=5).as_matrix()
    costa = dataclasses.replace(MATERIALS["Costa"], frame=R)
    columns = dataclasses.replace(costa, frame=np.ascontiguousarray(R[..., list(order)]))
    letters = "fsn"
    B = {}
    for a in range(3):
        for b in range(3):
            name = next(
                n
                for n in (f"b_{letters[a]}{letters[b]}", f"b_{letters[b]}{letters[a]}")
                if hasattr(costa, n)
            )
            B[a, b] = name
    # the component (order[a], order[b]) of the true frame weighted by b_(a, b)
    moved = {B[order[a], order[b]]: getattr(costa, B[a, b]) for a in range(3) for b in range(3)}
    coefficients = dataclasses.replace(costa, **moved)
    said = _same_as_coefficients_exchanged(costa, order)
    assert said  # the cause says it
    e_columns = mjed.make_force_field(mesh, columns).energy(x)
    e_coefficients = mjed.make_force_field(mesh, coefficients).energy(x)
    e_right = mjed.make_force_field(mesh, costa).energy(x)
    assert e_columns == pytest.approx(e_coefficients, rel=1e-12)
    assert abs(e_columns - e_right) > 1e-6 * abs(e_right)
