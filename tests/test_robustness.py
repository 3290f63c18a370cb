"""Property-based robustness of the public API (hypothesis).

Valid meshes, materials and states give finite, symmetric results; invalid ones raise our
errors (ValueError subclasses whose message names the problem), never a raw IndexError,
LinAlgError or a silent NaN.
"""

import itertools
import json

import numpy as np
import pytest
from conftest import box_mesh
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import mjed
from mjed import materials as M
from mjed.errors import InvertedElementError, MeshError

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def parameter_strategy(valid):
    """A declared range: ``(low, high)`` draws floats in it, a list draws one of its values."""
    return st.sampled_from(valid) if isinstance(valid, list) else st.floats(*valid)


#: Valid parameters of every declared material, from the ranges its declaration gives.
STRATEGIES = {
    d.material: st.builds(d.material, **{n: parameter_strategy(r) for n, r in d.ranges.items()})
    for d in M.declarations()
}
materials = st.one_of(*STRATEGIES.values())


@pytest.mark.parametrize("declared", M.declarations(), ids=lambda d: d.name)
def test_every_corner_of_the_declared_box_is_valid(declared):
    # Every corner, not only the all-low and all-high ones: a mixed corner of Costa's box once
    # made the split's second pivot exactly zero, and hypothesis found it in CI.
    names = sorted(declared.ranges)
    ends = [(declared.ranges[n][0], declared.ranges[n][-1]) for n in names]
    for corner in itertools.product(*ends):
        declared.material(**dict(zip(names, corner)))


@st.composite
def meshes_and_states(draw):
    n = draw(st.integers(1, 2))
    points, cells = box_mesh(n, jitter=draw(st.floats(0.0, 0.3)), seed=draw(st.integers(0, 10_000)))
    G = np.array(draw(st.lists(st.floats(-0.3, 0.3), min_size=9, max_size=9))).reshape(3, 3)
    rng = np.random.default_rng(draw(st.integers(0, 10_000)))
    x = points @ (np.eye(3) + G).T + 0.02 / n * rng.standard_normal(points.shape)
    return points, cells, x


@SETTINGS
@given(meshes_and_states(), materials)
def test_valid_input_gives_finite_symmetric_results(case, material):
    points, cells, x = case
    mesh = mjed.TetMesh(points, cells)
    field = mjed.HyperelasticForceField(mesh, material)
    try:
        f, K = field.force_and_stiffness(x)
    except (
        InvertedElementError
    ) as exc:  # a legitimate answer for a folded state: it names the cells
        assert len(exc.cells) > 0 and "J" in str(exc)
        assume(False)
    assert f.shape == (mesh.n_nodes, 3) and np.isfinite(f).all()
    assert np.isfinite(K.data).all()
    scale = abs(K).max()
    assert abs(K - K.T).max() <= 1e-11 * scale
    # Translation invariance: the forces are in equilibrium.
    assert np.abs(f.sum(axis=0)).max() <= 1e-9 * max(np.abs(f).max(), 1.0)


def _corrupt(points, cells, how, rng):
    points, cells = points.copy(), cells.copy()
    i = int(rng.integers(len(cells)))
    if how == "nan point":
        points[cells[i, 0], int(rng.integers(3))] = np.nan
    elif how == "inf point":
        points[cells[i, 1], 0] = np.inf
    elif how == "index too large":
        cells[i, int(rng.integers(4))] = len(points) + int(rng.integers(0, 5))
    elif how == "negative index":
        cells[i, int(rng.integers(4))] = -1 - int(rng.integers(0, 3))
    elif how == "repeated node":
        cells[i, 1] = cells[i, 0]
    elif how == "flat cell":
        a, b, c, _ = points[cells[i]]
        points[cells[i, 3]] = a + rng.uniform(0, 1) * (b - a) + rng.uniform(0, 1) * (c - a)
    elif how == "three-node cells":
        cells = cells[:, :3]
    elif how == "float cells":
        cells = cells.astype(float) + 0.5
    elif how == "no cells":
        cells = cells[:0]
    elif how == "2-d points":
        points = points[:, :2]
    return points, cells


@SETTINGS
@given(
    st.sampled_from(
        [
            "nan point",
            "inf point",
            "index too large",
            "negative index",
            "repeated node",
            "flat cell",
            "three-node cells",
            "float cells",
            "no cells",
            "2-d points",
        ]
    ),
    st.integers(0, 10_000),
    st.integers(1, 2),
)
def test_invalid_meshes_raise_mesh_errors(how, seed, n):
    points, cells = box_mesh(n, jitter=0.2, seed=seed)
    points, cells = _corrupt(points, cells, how, np.random.default_rng(seed))
    with pytest.raises(MeshError) as info:
        mjed.TetMesh(points, cells)
    assert len(str(info.value)) > 10


bad_numbers = st.sampled_from([0.0, -1.0, -1e-9, float("nan"), float("inf"), -float("inf")])
PARAMS = {
    M.StVenantKirchhoff: dict(mu=1.0, lam=1.0),
    M.NeoHookean: dict(mu=1.0, lam=1.0),
    M.MooneyRivlin: dict(c1=1.0, c2=1.0, k0=1.0),
    M.VerondaWestmann: dict(c1=1.0, c2=1.0, k0=1.0),
    M.ArrudaBoyce: dict(mu=1.0, k0=1.0, N=8.0),
    M.Costa: dict(a=1.0, k0=1.0, b_ff=1.0, b_fs=0.1, b_ss=1.0, b_fn=0.1, b_sn=0.1, b_nn=1.0),
    M.Ogden: dict(mu=1.0, alpha=2.0, k0=1.0),
}
# Parameters that may be zero or negative: lambda of the Lame pair, Mooney-Rivlin's c1 and c2,
# Costa's B entries (an indefinite B is handled by the signed split) and Ogden's alpha (not 0).
SIGNED = {"lam", "c1", "c2", "b_ff", "b_fs", "b_ss", "b_fn", "b_sn", "b_nn", "alpha"}


@SETTINGS
@given(st.sampled_from(sorted(PARAMS, key=lambda c: c.__name__)), st.data())
def test_invalid_parameters_name_the_parameter(cls, data):
    params = dict(PARAMS[cls])
    name = data.draw(st.sampled_from(sorted(params)))
    value = data.draw(bad_numbers)
    finite = np.isfinite(value)
    signed = name in SIGNED and not (cls is M.VerondaWestmann and name in ("c1", "c2"))
    assume(not (finite and signed and not (cls is M.Ogden and value == 0.0)))
    assume(not (cls is M.Ogden and name == "alpha" and finite and value != 0.0))
    params[name] = value
    with pytest.raises(ValueError) as info:
        cls(**params)
    assert name in str(info.value)


@SETTINGS
@given(st.sampled_from(["nan", "shape", "inf"]), st.integers(0, 100))
def test_invalid_positions_are_refused(kind, seed):
    points, cells = box_mesh(1)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), M.NeoHookean(mu=1.0, lam=1.0))
    x = points.copy()
    if kind == "nan":
        x[seed % len(x), seed % 3] = np.nan
    elif kind == "inf":
        x[seed % len(x), 0] = -np.inf
    else:
        x = x[: seed % len(x)]
    with pytest.raises(ValueError, match="positions"):
        field.force_and_stiffness(x)


@pytest.mark.oracle
@settings(max_examples=15, deadline=None)
@given(
    st.sampled_from(
        [
            "nan point",
            "index too large",
            "negative index",
            "repeated node",
            "flat cell",
            "three-node cells",
            "no cells",
            "2-d points",
        ]
    ),
    st.integers(0, 10_000),
)
def test_the_oracle_refuses_invalid_meshes_with_our_errors(how, seed):
    pytest.importorskip("dolfinx")
    from reference_fem import UFLOracle

    points, cells = box_mesh(1, jitter=0.2, seed=seed)
    points, cells = _corrupt(points, cells, how, np.random.default_rng(seed))
    with pytest.raises(ValueError) as info:
        UFLOracle(points, cells, M.NeoHookean(mu=1.0, lam=1.0))
    assert len(str(info.value)) > 10


def _strict_load(path):
    """json.load refusing the NaN and Infinity literals that Python writes by default."""

    def refuse(name):
        raise ValueError(f"{name} is not JSON")

    with open(path) as fh:
        return json.load(fh, parse_constant=refuse)


def test_results_are_written_as_strict_json_with_the_reason_for_each_null(tmp_path):
    from common.options import write_json

    path = tmp_path / "r.json"
    write_json(
        str(path),
        {
            "fps": float("inf"),
            "runs": [{"err": np.float64("nan")}],
            "field": np.array([1.0, -np.inf]),
            "ok": 2.5,
        },
    )
    data = _strict_load(path)
    assert data["fps"] is None and data["runs"][0]["err"] is None and data["field"] == [1.0, None]
    assert data["ok"] == 2.5
    assert data["non_finite"] == [
        {"path": "fps", "value": "inf"},
        {"path": "runs/0/err", "value": "nan"},
        {"path": "field/1", "value": "-inf"},
    ]


def test_the_check_report_json_is_strict(tmp_path):
    from conformance.report import write_report
    from conformance.run import CaseOutcome, CheckRun

    run = CheckRun(
        outcomes=[
            CaseOutcome(
                "c", "NeoHookean", "box", "rest", "bad input", message="m", seconds=float("nan")
            )
        ]
    )
    paths = write_report(str(tmp_path), run, command="mjed-verify check kit", fields={})
    data = _strict_load(paths["json"])
    assert data["cases"][0]["seconds"] is None
    assert data["non_finite"] == [{"path": "cases/0/seconds", "value": "nan"}]
