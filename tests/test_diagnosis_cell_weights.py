"""Each cell weighted by a wrong geometric quantity (conformance.diagnosis.cell_weights): the
mistaken engines are written here from MJED's per-cell densities with their own volume
weighting, not with the module's weights; MJED stands in for the oracle.
"""

from __future__ import annotations

import numpy as np
from conftest import box_mesh, mjed_split

from common.cases import default_material
from conformance.diagnosis.cell_weights import cell_weight_findings
from conformance.diagnosis.elements import assemble
from conformance.judge.compare import DOUBLE


def _case(material, seed=0):
    points, cells = box_mesh(2, jitter=0.25, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    return mjed_split(default_material(material), points, cells, x)


def _engine(split, volume_f, volume_K):
    """Force and stiffness from per-unit-volume element terms (the oracle's over V0) weighted
    by the engine's own volume per cell.
    """
    V0 = split.V0
    per_volume_f = split.fe / V0[:, None, None]
    per_volume_K = split.Ke / V0[:, None, None]
    f = assemble(split.cells, split.n, volume_f[:, None, None] * per_volume_f, None)[0]
    K = assemble(split.cells, split.n, 0 * split.fe, volume_K[:, None, None] * per_volume_K)[1]
    return f, K


def test_stiffness_with_v0_twice_is_named():
    split, f_o, K_o, s = _case("MooneyRivlin")
    f, K = _engine(split, split.V0, split.V0**2)
    found = cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures == {
        **found[0].figures,
        "weighting": "V0 twice",
        "applies_to": "stiffness",
    }
    assert "V0 twice" in found[0].title and "stiffness" in found[0].title


def test_mean_cell_volume_is_named():
    split, f_o, K_o, s = _case("Yeoh", seed=1)
    mean = np.full_like(split.V0, split.V0.mean())
    f, K = _engine(split, mean, mean)
    found = cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures["weighting"] == "mean volume"
    assert found[0].figures["applies_to"] == "force and stiffness"


def test_other_weightings_are_named_only_as_a_factor_per_cell():
    """The current volume J V0 for V0 matches no declared weighting: it is said only as a
    fitted factor per cell (with how many cells are off). A global factor, the same in every
    cell, and one cell counted twice are not said here at all (the global readings and
    conformance.diagnosis.cells name them).
    """
    split, f_o, K_o, s = _case("NeoHookean", seed=2)
    J = np.linalg.det(split.F)
    f, K = _engine(split, J * split.V0, J * split.V0)
    found = cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE)
    assert [x.figures["weighting"] for x in found] == ["fitted per cell"], found
    assert found[0].figures["cells_off"] == split.V0.size and "rest volume" in found[0].title
    twice = np.where(np.arange(split.V0.size) == 3, 2.0, 1.0)
    for weight in (np.full_like(J, 1.01), twice):
        f, K = _engine(split, weight * split.V0, weight * split.V0)
        assert cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE) == []


def test_a_volume_with_a_typo_is_named_as_a_factor_per_cell_and_a_wrong_force_is_not():
    """Each cell's volume from a triple product whose cross product has a sign typo in one
    component (the engine's own formula): a fitted weight per cell matches force and stiffness
    together. The same engine with its force also off in one node's entries (no weighting of
    the cells gives it) is not named.
    """
    split, f_o, K_o, s = _case("Gent", seed=4)
    points, cells = box_mesh(2, jitter=0.25, seed=4)
    u, v, w = (points[cells[:, k]] - points[cells[:, 0]] for k in (1, 2, 3))
    cross = np.stack(
        [
            u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1],
            u[:, 0] * v[:, 2] - u[:, 2] * v[:, 0],  # the typo: the sign of the y component
            u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0],
        ],
        axis=1,
    )
    volume = np.abs(np.einsum("mi,mi->m", cross, w)) / 6
    f, K = _engine(split, volume, volume)
    found = cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE)
    assert [x.figures["weighting"] for x in found] == ["fitted per cell"], found
    assert found[0].figures["residual"] <= 1e-9
    f[0] += 1e-3 * np.abs(f).max()
    assert cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE) == []


def test_volume_from_the_inverse_edge_matrix_is_named():
    """An engine that takes each cell's volume as |det(Dm^-1)| / 6, computed here from its own
    edge matrices: every cell scaled by 1 / (36 V0^2), named with the formula; a power of V0
    that is not declared (V0^1.5) is not named as a formula, only as a fitted factor per cell.
    """
    split, f_o, K_o, s = _case("ArrudaBoyce", seed=3)
    points, cells = box_mesh(2, jitter=0.25, seed=3)
    Dm = np.swapaxes(points[cells[:, 1:]] - points[cells[:, :1]], 1, 2)
    from_inverse = np.abs(np.linalg.det(np.linalg.inv(Dm))) / 6
    f, K = _engine(split, from_inverse, from_inverse)
    found = cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE)
    assert len(found) == 1, [x.title for x in found]
    assert found[0].figures["weighting"] == "V0^-1"
    assert found[0].figures["applies_to"] == "force and stiffness"
    assert "det(Dm^-1)| / 6" in found[0].title
    f, K = _engine(split, split.V0**1.5, split.V0**1.5)
    found = cell_weight_findings(split, f, K, f_o, K_o, s, DOUBLE)
    assert [x.figures["weighting"] for x in found] == ["fitted per cell"], found


def test_geometric_stiffness_outside_the_volume_is_named():
    """V0 B^T D B + K_geo where V0 (B^T D B + K_geo) belongs: the engine's geometric element
    matrix (D_a . S D_b) I from mjed's stress per cell, without V0; the force right.
    """
    import mjed

    points, cells = box_mesh(2, jitter=0.25, seed=2)
    rng = np.random.default_rng(2)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    model = default_material("VerondaWestmann")
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    S = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model).stress(x)
    DSD = np.einsum("maI,mIJ,mbJ->mab", split.D, S, split.D)
    geo = np.einsum("mab,kl->makbl", DSD, np.eye(3)).reshape(-1, 12, 12)
    K = K_o + assemble(cells, split.n, 0 * split.fe, (1.0 - split.V0)[:, None, None] * geo)[1]
    found = cell_weight_findings(split, f_o, K, f_o, K_o, s, DOUBLE)
    assert [f.figures["applies_to"] for f in found] == ["geometric stiffness"], found
    assert found[0].figures["weighting"] == "V0 missing"
    # the material part without V0 is another reading, not this one
    K = (
        K_o
        + assemble(
            cells,
            split.n,
            0 * split.fe,
            (1.0 / split.V0 - 1.0)[:, None, None] * (split.Ke - split.V0[:, None, None] * geo),
        )[1]
    )
    found = cell_weight_findings(split, f_o, K, f_o, K_o, s, DOUBLE)
    assert [f.figures["applies_to"] for f in found] == ["material stiffness"], found


def test_geometric_stiffness_over_the_rest_volume_in_a_spatial_engine_is_named():
    """A spatial engine's initial-stress part v (g_a . sigma g_b) I written with V0 for v = J V0:
    the geometric element matrix (D_a . S D_b) I from mjed's stress, times V0 / J per cell, the
    rest right; named with the rest volume; the same part times 1/J^2 is not.
    """
    import mjed

    points, cells = box_mesh(2, jitter=0.25, seed=4)
    rng = np.random.default_rng(4)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.05 * rng.standard_normal(points.shape)
    model = default_material("Demiray")
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    S = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model).stress(x)
    DSD = np.einsum("maI,mIJ,mbJ->mab", split.D, S, split.D)
    geo = np.einsum("mab,kl->makbl", DSD, np.eye(3)).reshape(-1, 12, 12)
    J = np.linalg.det(split.F)
    for power, named in ((-1.0, True), (-2.0, False)):
        w = (split.V0 * (J**power - 1.0))[:, None, None]
        K = K_o + assemble(cells, split.n, 0 * split.fe, w * geo)[1]
        found = cell_weight_findings(split, f_o, K, f_o, K_o, s, DOUBLE)
        weights = [f.figures["weighting"] for f in found]
        assert ("rest volume" in weights) is named, [f.title for f in found]


def test_a_geometric_part_scaled_by_the_one_j_of_a_state_is_said_as_a_volume():
    """On a homogeneous state (one J), the geometric stiffness scaled by 1/J is said as that part
    over the rest volume; by J, over the deformed volume; by another factor, nothing added.
    """
    from conformance.diagnosis.diagnose import _geometric_volume_words

    points, cells = box_mesh(2, jitter=0.25, seed=5)
    x = points @ np.diag([1.3, 1.0, 1.0]).T  # J = 1.3 in every cell
    mesh = (points, cells, x)
    assert "rest volume V0 where the deformed volume" in _geometric_volume_words(1 / 1.3, mesh)
    assert "over the deformed volume" in _geometric_volume_words(1.3, mesh)
    assert _geometric_volume_words(0.7, mesh) == ""
