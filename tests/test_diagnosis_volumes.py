"""A factor that is the J of the cells is the volume confused (conformance.diagnosis.volumes):
uniform J on the global scale, varying J cell by cell; a constant factor that is not J stays a
number (corpus 5's "stiffness only scaled: factor 0.769231" for K integrated over V, f over v).
Each mistaken engine is built here from MJED's force and stiffness (the oracle's stand-in).
"""

from __future__ import annotations

import numpy as np
from conftest import box_mesh, mjed_split

import mjed
from conformance.diagnosis.diagnose import diagnose
from conformance.diagnosis.elements import assemble
from conformance.diagnosis.volumes import uniform_volume_words, volume_findings
from conformance.judge.compare import DOUBLE
from mjed.materials import NeoHookean


def _random_state(seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.15, 0.95, 0.9]).T + 0.04 * rng.standard_normal(points.shape)
    return points, cells, x


def _uniform_state():
    points, cells = box_mesh(2, jitter=0.2, seed=3)
    return points, cells, points @ np.diag([1.3, 1.0, 1.0]).T  # J = 1.3 in every cell


MODEL = NeoHookean(mu=3448.2759, lam=31034.483)


def test_factors_of_the_cells_j_are_read_as_the_volume():
    points, cells, x = _random_state()
    split, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    J = np.linalg.det(split.F)
    assert np.ptp(J) > 0.05
    n = points.shape[0]
    # tau and J c over the deformed volume: every cell's force and stiffness times J_c
    f, K = assemble(cells, n, split.fe * J[:, None, None], split.Ke * J[:, None, None])
    found = volume_findings(split, f, K, s, DOUBLE)
    assert [x.figures["force_power"] for x in found] == [1], [x.title for x in found]
    assert "Kirchhoff" in found[0].title
    # the stiffness over the rest volume, the force over the deformed one
    _, K = assemble(cells, n, split.fe, split.Ke / J[:, None, None])
    found = volume_findings(split, f_o, K, s, DOUBLE)
    assert len(found) == 1 and "rest volume" in found[0].title
    assert found[0].figures["stiffness_power"] == -1
    # nearby: one constant factor (the mean J) on both is no cell's volume; the right output
    assert volume_findings(split, f_o * J.mean(), K_o * J.mean(), s, DOUBLE) == []
    assert volume_findings(split, f_o, K_o, s, DOUBLE) == []


def test_a_uniform_factor_is_the_volume_only_when_it_is_j():
    J = np.full(8, 1.3)
    assert "Kirchhoff" in uniform_volume_words(1, 1, 1.3, J)
    assert "rest volume" in uniform_volume_words(0, 1, 1 / 1.3, J)
    assert "1/J" in uniform_volume_words(1, 1, 1 / 1.3, J)
    assert uniform_volume_words(1, 1, 1.25, J) is None  # not J: a constant factor
    assert uniform_volume_words(1, 1, 1.3, np.linspace(1.2, 1.4, 8)) is None  # J varies
    assert uniform_volume_words(1, 1, 1.0, np.ones(8)) is None  # J = 1 tells nothing


def _diagnose(points, cells, x, f, K, f_o, K_o, s):
    return diagnose("c", f=f, K=K, W=None, f_o=f_o, K_o=K_o, W_o=1.0, s=s, points=points,
                    cells=cells, x=x)  # fmt: skip


def test_the_global_scale_says_the_volume_where_the_factor_is_the_state_j():
    points, cells, x = _uniform_state()
    _, f_o, K_o, s = mjed_split(MODEL, points, cells, x)
    d = _diagnose(points, cells, x, f_o, K_o / 1.3, f_o, K_o, s)
    assert d.causes and d.causes[0].code == "scale-stiffness"
    assert "rest volume" in d.causes[0].title and "factor 0.769231" in d.causes[0].title
    # nearby: a factor that is not J stays a number
    d = _diagnose(points, cells, x, f_o, K_o * 0.8, f_o, K_o, s)
    assert d.causes[0].title == "stiffness only scaled: factor 0.8"


def test_a_force_scaled_by_j_squared_with_its_own_derivative_as_stiffness():
    """The deformed volume taken as V / J (force 1/J^2 times the oracle's, cell by cell) in an
    engine whose stiffness is the derivative of its own force (differences or a complex step):
    the stiffness is then not J^-2 times the oracle's, but that force's derivative.
    """
    import dataclasses

    import scipy.sparse as sp

    from conformance.diagnosis.elements import cell_kinematics

    points, cells, x = _random_state(seed=4)
    split, _, _, s = mjed_split(MODEL, points, cells, x)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), MODEL)
    n = points.shape[0]

    def force(y):
        _, _, F = cell_kinematics(points, cells, y)
        fe = np.asarray(field.element_forces(y)) / np.linalg.det(F)[:, None, None] ** 2
        return assemble(cells, n, fe, None)[0].ravel()

    h = 1e-6
    columns = []
    for j in range(3 * n):
        e = np.zeros(3 * n)
        e[j] = h
        columns.append(-(force(x + e.reshape(-1, 3)) - force(x - e.reshape(-1, 3))) / (2 * h))
    K = sp.csr_matrix(np.array(columns).T)
    f = force(x).reshape(-1, 3)
    loose = dataclasses.replace(DOUBLE, force=1e-6, stiffness=1e-6)
    found = volume_findings(split, f, K, s, loose)
    assert [(x.figures["force_power"], x.figures.get("derived")) for x in found] == [(-2, True)]
    assert "V / J" in found[0].title
    # the same force with the stiffness scaled like it is not this mistake
    scaled = split.Ke / np.linalg.det(split.F)[:, None, None] ** 2
    _, K_scaled = assemble(cells, n, split.fe / np.linalg.det(split.F)[:, None, None] ** 2, scaled)
    assert not any(x.figures.get("derived") for x in volume_findings(split, f, K_scaled, s, loose))
