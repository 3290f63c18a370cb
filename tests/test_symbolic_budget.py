"""The symbolic budget of user energies (reference_fem.symbolic_budget): which energies share
one check. Its refusal past the budget is tested on a kit (tests/test_kit_hostile.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from reference_fem import dolfinx_available, symbolic_budget
from reference_fem.user_energy import UserEnergy

EXPRESSION = "mu*(I1 - 3) + k*(I4 - 1)**2"


def _frames(m: int, seed: int) -> np.ndarray:
    return Rotation.random(m, random_state=seed).as_matrix()


def _energy(mu=1.0, k=2.0, **direction) -> UserEnergy:
    return UserEnergy(EXPRESSION, {"mu": mu, "k": k}, **direction)


def test_energies_whose_forms_are_the_same_share_a_form_key():
    key = symbolic_budget._form_key
    per_cell = key(_energy(frame=_frames(5, 0)))
    # other frame values per cell, other parameter values, another name: the same forms
    assert key(_energy(3.0, 4.0, frame=_frames(7, 1))) == per_cell
    assert key(_energy(frame=_frames(5, 0), name="other")) == per_cell
    # a direction written into the form as numbers, another expression, other parameters: not
    others = [
        key(_energy(frame=_frames(1, 0)[0])),
        key(_energy(frame=_frames(1, 1)[0])),
        key(_energy(fibre=(1.0, 0.0, 0.0))),
        key(_energy(fibre=(0.0, 1.0, 0.0))),
        key(UserEnergy("mu*(I1 - 3) + k*(I4 - 1)**3", {"mu": 1.0, "k": 2.0}, frame=_frames(5, 0))),
        key(UserEnergy("mu*(I1 - 3) + c*(I4 - 1)**2", {"mu": 1.0, "c": 2.0}, frame=_frames(5, 0))),
    ]
    assert len({per_cell, *others}) == 1 + len(others)


@pytest.mark.skipif(not dolfinx_available(), reason="the child builds the UFL oracle (dolfinx)")
def test_one_child_per_form_not_per_energy(monkeypatch):
    started = []
    real = symbolic_budget.subprocess.Popen

    def counting(*args, **kwargs):
        started.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(symbolic_budget, "_within", set())
    monkeypatch.setattr(symbolic_budget.subprocess, "Popen", counting)
    symbolic_budget.check_symbolic_budget(_energy(frame=_frames(4, 0)))
    symbolic_budget.check_symbolic_budget(_energy(5.0, 6.0, frame=_frames(9, 2)))
    assert len(started) == 1
    symbolic_budget.check_symbolic_budget(_energy(fibre=(0.0, 0.0, 1.0)))
    assert len(started) == 2
