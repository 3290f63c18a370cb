"""Per-cell frames looked up wrongly (conformance.diagnosis.frames): by a node number
(``frame-node-indexed``) or replaced by one averaged frame for the whole mesh
(``frame-averaged``). The mistaken engines are MJED given the frames such an engine would use,
written here; the oracle judges.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from common.cases import default_material
from conformance.diagnosis.frames import frame_models
from reference_fem import dolfinx_available


def _rotations(m: int, seed: int = 0) -> np.ndarray:
    R = np.linalg.qr(np.random.default_rng(seed).standard_normal((m, 3, 3)))[0]
    return R * np.sign(np.linalg.det(R))[:, None, None]


def _averaged_by_svd(R: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(R.mean(axis=0))
    return U @ Vt


def _smoothed_by_svd(R: np.ndarray, cells: np.ndarray) -> np.ndarray:
    n = cells.max() + 1
    nodal = np.zeros((n, 3, 3))
    for k, cell in enumerate(cells):  # a test's plain loop: the reading's einsum is not reused
        for a in cell:
            nodal[a] += R[k]
    nodal /= np.bincount(cells.ravel(), minlength=n)[:, None, None]
    U, _, Vt = np.linalg.svd(nodal[cells].mean(axis=1))
    return U @ Vt


def test_smoothed_frames_are_rotations_offered_only_with_the_mesh():
    R = _rotations(6, seed=5)
    model = replace(default_material("Costa"), frame=R)
    cells = np.array(
        [[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5], [0, 2, 4, 5], [1, 3, 5, 0], [5, 4, 3, 2]]
    )
    smoothed = [
        np.asarray(m.frame) for c, _, m in frame_models(model, cells) if c == "frame-smoothed"
    ]
    assert len(smoothed) == 4
    for A in smoothed:
        assert np.allclose(np.einsum("kji,kjl->kil", A, A), np.eye(3), atol=1e-12)
    assert any(np.allclose(A, _smoothed_by_svd(R, cells)) for A in smoothed)
    assert not [c for c, _, _ in frame_models(model) if c == "frame-smoothed"]  # no mesh given


def test_node_indexed_frames_are_offered_only_where_node_numbers_are_cell_indices():
    R = _rotations(6)
    model = replace(default_material("Costa"), frame=R)
    cells = np.array(
        [[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5], [0, 2, 4, 5], [1, 3, 5, 0], [5, 4, 3, 2]]
    )
    found = [
        (t, np.asarray(m.frame))
        for c, t, m in frame_models(model, cells)
        if c == "frame-node-indexed"
    ]
    assert len(found) == 4 and all(
        np.array_equal(fr, R[cells[:, a]]) for a, (_, fr) in enumerate(found)
    )
    assert not [c for c, _, _ in frame_models(model, cells + 1) if c == "frame-node-indexed"]
    assert not [c for c, _, _ in frame_models(model) if c == "frame-node-indexed"]  # no mesh given


def test_the_averaged_frames_are_rotations_and_the_svd_one_is_the_nearest():
    R = _rotations(7, seed=3)
    model = replace(default_material("Costa"), frame=R)
    averaged = [np.asarray(m.frame) for c, _, m in frame_models(model) if c == "frame-averaged"]
    assert len(averaged) == 2
    for A in averaged:
        assert np.allclose(A.T @ A, np.eye(3), atol=1e-12)
    gram_schmidt, polar = averaged
    mean = R.mean(axis=0)
    assert np.allclose(gram_schmidt[:, 0], mean[:, 0] / np.linalg.norm(mean[:, 0]))
    assert np.allclose(polar, _averaged_by_svd(R))


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
@pytest.mark.parametrize("mistake", ["node-indexed", "averaged", "smoothed", "twice", "first cell"])
def test_a_frame_looked_up_wrongly_is_named_as_such(mistake):
    from frame_support import check_with_frames

    def used(R, cells):
        if mistake == "node-indexed":
            return R[cells[:, 0]]
        if mistake == "averaged":
            return np.broadcast_to(_averaged_by_svd(R), R.shape)
        if mistake == "smoothed":  # a fibre field stored per node: cells -> nodes -> cells
            return _smoothed_by_svd(R, cells)
        if mistake == "twice":  # the strain rotated into the frame by a helper and its caller
            return R @ R
        return np.broadcast_to(R[0], R.shape)  # a nearby mistake with its own name

    outcome = check_with_frames(used, "random")
    causes = outcome.diagnosis.causes
    expected = {
        "node-indexed": "frame-node-indexed",
        "averaged": "frame-averaged",
        "smoothed": "frame-smoothed",
        "twice": "frame-twice",
    }.get(mistake, "frame-global")
    assert outcome.status == "failed" and causes, outcome.diagnosis.text()
    assert [c.code for c in causes] == [expected], outcome.diagnosis.text()
    if mistake == "node-indexed":
        assert "cells[k, 0]" in causes[0].title
    if mistake in ("averaged", "smoothed"):
        assert "nearest rotation" in causes[0].title


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
@pytest.mark.parametrize("layout", ["cells last", "column major", "transposed"])
def test_a_frame_file_read_in_another_layout_is_named(layout):
    """The engine (hyper-dual, tests/hyperdual_engine.py: a frame that is not a rotation is
    refused by mjed's Costa) computes Costa's energy with the matrices it read; the per-cell
    transpose, also a misread layout, keeps its own name.
    """
    from hyperdual_engine import density_engine

    from conformance.protocol import check_implementation
    from mjed.materials import Costa
    from mjed.materials.declaration import declaration_of

    def misread(R):
        flat, m = np.ascontiguousarray(R).ravel(), R.shape[0]
        if layout == "cells last":
            return np.moveaxis(flat.reshape(3, 3, m), -1, 0)
        if layout == "column major":
            return flat.reshape((m, 3, 3), order="F")
        return np.swapaxes(R, -1, -2)

    formula = declaration_of(Costa).energy
    engine = density_engine(
        lambda model, k, F, R: formula(lambda name: float(getattr(model, name)), k),
        frame_of=lambda model: misread(np.asarray(model.frame)),
    )
    run = check_implementation(
        engine, material=default_material("Costa"), mesh="cube-small", states=("random",),
        probes=False,
    )  # fmt: skip
    (outcome,) = run.outcomes
    causes = outcome.diagnosis.causes
    expected = "frame-transposed" if layout == "transposed" else "frame-layout"
    assert outcome.status == "failed" and [c.code for c in causes] == [expected], (
        outcome.diagnosis.text()
    )
    if layout != "transposed":
        assert ("cell index last" in causes[0].title) == (layout == "cells last")


def test_only_a_frame_marked_as_read_passes_the_oracles_check_without_being_a_rotation():
    from reference_fem.validation import AsReadFrame, check_frame

    R = np.moveaxis(_rotations(4).ravel().reshape(3, 3, 4), -1, 0)  # read cells last
    with pytest.raises(ValueError, match="orthonormal"):
        check_frame(R, 4)
    assert np.array_equal(check_frame(R.view(AsReadFrame), 4), R)
    with pytest.raises(ValueError, match="non-finite"):
        check_frame(np.full((4, 3, 3), np.nan).view(AsReadFrame), 4)


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_an_energy_with_the_frame_twice_and_a_stress_without_is_named_from_the_energy():
    """The strain rotated into the frame twice in the energy routine only (corpus 12): the
    force is no variant's, but the energy is the frame-twice variant's at the case and every
    probe. An energy off by a factor instead is no frame's.
    """
    import mjed
    from conformance.protocol import check_implementation

    def run(energy_of):
        def engine(case):
            mesh = mjed.TetMesh(case.points, case.cells)
            field = mjed.make_force_field(mesh, case.model)
            f, K = field.force_and_stiffness(case.positions)
            return f, K, energy_of(case, mesh)

        result = check_implementation(
            engine, material=default_material("Costa"), mesh="cube-small", states=("random",)
        )
        return result.outcomes[0].diagnosis

    def twice(case, mesh):
        R = np.asarray(case.model.frame)
        wrong = replace(case.model, frame=np.ascontiguousarray(R @ R))
        return mjed.make_force_field(mesh, wrong).energy(case.positions)

    d = run(twice)
    named = d.findings[0]
    assert named.code == "variant-energy" and named.figures["variant"] == "frame-twice", d.text()
    assert "force and stiffness are right" in named.title and named.figures["states"] == 5
    d = run(
        lambda case, mesh: 1.01 * mjed.make_force_field(mesh, case.model).energy(case.positions)
    )
    assert all(f.code != "variant-energy" for f in d.findings), d.text()
