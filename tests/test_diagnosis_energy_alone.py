"""The energy wrong while force and stiffness are right (conformance.diagnosis.energy_alone):
the mistaken energies are summed here from MJED's per-cell energies at a state and four probes
around it, the way an engine's own energy routine would; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh

import mjed
from common.cases import default_material
from conformance.diagnosis.elements import cell_kinematics
from conformance.diagnosis.energy_alone import energy_alone_findings, energy_states
from mjed.evaluation import Want

TOL = 1e-10


def _states(material, uniform=False, seed=0):
    """(model, points, cells, positions of the state and 4 probes, per-cell V0 W at each (5, m),
    J at each (5, m), V0 (m,)).
    """
    model = default_material(material)
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    stretch = np.diag([1.2, 0.95, 0.95])
    x = points @ stretch.T
    if not uniform:
        x = x + 0.03 * rng.standard_normal(points.shape)
    field = mjed.make_force_field(mjed.TetMesh(points, cells), model)
    positions = [x] + [x + 1e-3 * 0.5 * rng.standard_normal(x.shape) for _ in range(4)]
    cell_w = np.stack([field.evaluate(p, want=Want.ENERGY).energy for p in positions])
    J = np.stack([np.linalg.det(cell_kinematics(points, cells, p)[2]) for p in positions])
    V0 = cell_kinematics(points, cells, x)[0]
    return model, points, cells, positions, cell_w, J, V0


def _findings(material, engine_of, **kw):
    model, points, cells, positions, cell_w, J, V0 = _states(material, **kw)
    oracle = cell_w.sum(1)
    engine = engine_of(cell_w, J, V0)
    st = energy_states(
        model, points, cells, positions, engine, oracle, float(np.abs(oracle).max()), TOL
    )
    assert st.cells is not None
    return energy_alone_findings(st, TOL, None)


@pytest.mark.parametrize(
    "code, engine_of",
    [
        ("energy-mean-volume", lambda w, J, V0: V0.mean() * (w / V0).sum(1)),
        ("energy-no-volume", lambda w, J, V0: (w / V0).sum(1)),
        ("energy-V0-twice", lambda w, J, V0: (w * V0).sum(1)),
        ("energy-deformed-volume", lambda w, J, V0: (w * J).sum(1)),
        ("energy-factor", lambda w, J, V0: 0.5 * w.sum(1)),
        ("energy-constant", lambda w, J, V0: w.sum(1) + 3.0),
    ],
)
def test_each_declared_energy_mistake_is_named_alone(code, engine_of):
    found = _findings("NeoHookean", engine_of)
    assert [f.code for f in found] == [code], [f.title for f in found]
    assert found[0].title.startswith("your energy is wrong")


def test_another_energy_is_called_the_energy_routine_not_a_declared_mistake():
    # a term of the energy alone changed (a penalty on J the stress does not have)
    found = _findings("MooneyRivlin", lambda w, J, V0: w.sum(1) + 10.0 * (V0 * (J - 1) ** 2).sum(1))
    assert [f.code for f in found] == ["energy"], [f.title for f in found]
    assert "no declared energy mistake" in found[0].evidence


def test_the_mean_volume_hides_on_a_uniform_state_and_the_probes_show_it():
    found = _findings("Yeoh", lambda w, J, V0: V0.mean() * (w / V0).sum(1), uniform=True, seed=1)
    assert found and found[0].code == "energy-mean-volume", [f.title for f in found]


def test_the_oracles_own_energy_is_not_called_wrong():
    assert _findings("Costa", lambda w, J, V0: w.sum(1)) == []


@pytest.mark.parametrize(
    "factor, said", [(2.0, "doubled"), (0.5, "halved"), (1.3, "scaled by 13/10")]
)
def test_one_part_of_the_energy_alone_scaled_is_named_with_its_factor(factor, said):
    """Mooney-Rivlin's isochoric part alone scaled in the energy routine (its volumetric
    k0/2 (ln J)^2, summed here with its own formula, right); and the volumetric part alone.
    """
    k0 = default_material("MooneyRivlin").k0

    def vol(J, V0):
        return (V0 * 0.5 * k0 * np.log(J) ** 2).sum(1)

    found = _findings(
        "MooneyRivlin", lambda w, J, V0: factor * (w.sum(1) - vol(J, V0)) + vol(J, V0)
    )
    assert [f.code for f in found] == ["energy-isochoric-factor"], [f.title for f in found]
    assert f"isochoric part (all but U(J)) alone {said}" in found[0].title, found[0].title
    found = _findings("MooneyRivlin", lambda w, J, V0: w.sum(1) + (factor - 1.0) * vol(J, V0))
    assert [f.code for f in found] == ["energy-volumetric-factor"], [f.title for f in found]
