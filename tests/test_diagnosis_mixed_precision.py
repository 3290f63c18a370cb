"""Part of a double-precision engine in single precision (conformance.diagnosis.mixed_precision):
a St Venant-Kirchhoff engine written here by hand whose material routine gets C in float32 (and
so computes S in float32), F, the force and the assembly in double. MJED stands in for the
oracle in the fast tests; one test runs the whole check with the oracle and the kit's probes.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_mesh, mjed_split
from diagnosis_stubs import cell_gradients

from conformance.diagnosis.mixed_precision import (
    mixed_precision_finding,
    noise,
    rest_rounding_finding,
)
from mjed import materials as M
from reference_fem import dolfinx_available

MU, LAM = 1.0, 2.0


def _svk_force(points, cells, x, *, f32=False, p32=False, mu=MU, noise_rng=None, d32=False):
    """Force (n, 3) of W = lam/2 (tr E)^2 + mu tr(E^2); f32: C handed to the material in
    float32 (S computed in float32); p32: the first Piola stress P = F S kept in a float32
    field, the rest double; noise_rng: S given random relative noise of float32's size instead
    (noise that is not rounding, e.g. an iteration's tolerance); d32: the shape-function
    gradients from the rest edge matrix inverted in float32 (a single-precision mesh buffer).
    """
    X = points[cells]
    Mt = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)
    V0 = np.linalg.det(Mt) / 6.0
    Minv = np.linalg.inv(Mt.astype(np.float32)).astype(float) if d32 else np.linalg.inv(Mt)
    D = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)
    F = np.einsum("mai,maj->mij", x[cells], D)
    C = np.einsum("mki,mkj->mij", F, F)
    if f32:
        C = C.astype(np.float32)
    eye = np.eye(3, dtype=C.dtype)
    E = 0.5 * (C - eye)
    S = (LAM * np.trace(E, axis1=1, axis2=2)[:, None, None] * eye + 2 * mu * E).astype(float)
    if noise_rng is not None:
        S = S * (1 + 2.0**-24 * noise_rng.standard_normal(S.shape))
        S = 0.5 * (S + np.swapaxes(S, 1, 2))
    P = F @ S
    if p32:
        P = P.astype(np.float32).astype(float)
    fe = -V0[:, None, None] * np.einsum("mij,maj->mai", P, D)
    f = np.zeros(points.shape)
    np.add.at(f, cells.ravel(), fe.reshape(-1, 3))
    return f


def _setup(seed=0):
    points, cells = box_mesh(3, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    model = M.StVenantKirchhoff(mu=MU, lam=LAM)
    split, f_o, K_o, s = mjed_split(model, points, cells, x)
    probes = [x + 1e-4 / 3 * 2.0**-k * rng.standard_normal(x.shape) for k in range(3)]
    return points, cells, x, model, split, f_o, probes


def _errors(points, cells, x, probes, **engine):
    """The engine's force error at x and at each probe, MJED as the oracle."""
    import mjed

    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), M.StVenantKirchhoff(MU, LAM))
    err = [_svk_force(points, cells, y, **engine) - field.force(y) for y in [x, *probes]]
    return err[0], err[1:]


def test_c_in_float32_inside_a_double_engine_is_named():
    points, cells, x, model, split, f_o, probes = _setup()
    assert np.allclose(_svk_force(points, cells, x), f_o, rtol=0, atol=1e-13)
    e, pe = _errors(points, cells, x, probes, f32=True)
    assert 1e-10 < np.linalg.norm(e) / np.linalg.norm(f_o) < 1e-6
    found = mixed_precision_finding(split, model, points, x, e, pe)
    assert found is not None and found.code == "single-precision-intermediate"
    assert found.figures["best"] == "C" and "single precision (float32)" in found.title
    assert noise(e, pe).noisy
    # without probes: the rounding's pattern over the many distinct cells still says it
    assert mixed_precision_finding(split, model, points, x, e, None) is not None


def test_a_float32_first_piola_stress_field_is_named_as_p_rounded():
    """P computed in double and kept in float32 (a stress buffer) before a double assembly: the
    rounding of P, not of C or S, predicts the error (corpus 12's Veronda-Westmann engine).
    """
    points, cells, x, model, split, f_o, probes = _setup(2)
    e, pe = _errors(points, cells, x, probes, p32=True)
    found = mixed_precision_finding(split, model, points, x, e, pe)
    assert found is not None and found.figures["best"] == "P", found
    assert found.figures["correlations"]["P"] > 0.99 > found.figures["correlations"]["S"]


def test_a_small_smooth_error_or_other_noise_is_not_called_float32():
    points, cells, x, model, split, f_o, probes = _setup(1)
    # a parameter off by 1e-7: as small, but smooth in x (the same at every probe)
    e, pe = _errors(points, cells, x, probes, mu=MU * (1 + 1e-7))
    assert not noise(e, pe).noisy
    assert mixed_precision_finding(split, model, points, x, e, pe) is None
    # noise of float32's size that is not the rounding of C, F, S or the positions
    rng = np.random.default_rng(5)
    e, pe = _errors(points, cells, x, probes, noise_rng=rng)
    assert noise(e, pe).noisy
    assert mixed_precision_finding(split, model, points, x, e, pe) is None


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
def test_the_check_names_c_in_float32_inside_a_double_engine():
    import mjed
    from conformance.protocol import check_implementation

    def engine(case):
        field = mjed.make_force_field(mjed.TetMesh(case.points, case.cells), case.model)
        f = _svk_force(case.points, case.cells, case.positions, f32=True)
        return f, field.stiffness(case.positions)

    run = check_implementation(
        engine, material=M.StVenantKirchhoff(MU, LAM), mesh="cube-small", states=("random",)
    )
    (outcome,) = run.outcomes
    d = outcome.diagnosis
    assert outcome.status == "failed" and d.causes, d.text()
    assert d.causes[0].code == "single-precision-intermediate", d.text()
    assert "probe" in d.causes[0].evidence


def test_element_matrices_in_a_float32_buffer_are_named_from_their_exact_rounding():
    """Element stiffness matrices stored in float32, assembled in double (corpus 6): the oracle's
    element matrices rounded and summed predict the engine entry by entry. Nearby: the
    assembled K rounded (another mistake, the output's storage) and a formula error of the same
    size are not this.
    """
    from types import SimpleNamespace

    import scipy.sparse as sp

    from conformance.diagnosis.elements import assemble
    from conformance.diagnosis.mixed_precision import rounded_elements_finding
    from conformance.judge.compare import DOUBLE

    points, cells = box_mesh(2, jitter=0.2, seed=1)
    rng = np.random.default_rng(1)
    x = points @ np.diag([1.1, 0.95, 1.0]).T + 0.03 * rng.standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(M.Ogden(mu=3000.0, alpha=8.0, k0=3e4), points, cells, x)
    f32 = lambda a: a.astype(np.float32).astype(np.float64)  # noqa: E731
    _, K_elements = assemble(cells, points.shape[0], split.fe, f32(split.Ke))
    found = rounded_elements_finding(
        split, SimpleNamespace(force=f_o, stiffness=K_elements), s, DOUBLE
    )
    assert found is not None and "stiffness matrices are kept in float32" in found.title
    K_rounded = sp.csr_matrix(K_o.copy())
    K_rounded.data = f32(K_rounded.data)
    for K in (K_rounded, K_o * (1 + 3e-8)):
        assert (
            rounded_elements_finding(split, SimpleNamespace(force=f_o, stiffness=K), s, DOUBLE)
            is None
        )


def _svk_spatial_stiffness(points, cells, x, transform):
    """K of an updated-Lagrangian St Venant-Kirchhoff engine (MU, LAM) whose per-cell spatial
    tangent J c = lam b (x) b + 2 mu b (.) b is passed through ``transform`` (the rest double):
    K_e = v (grad N . c . grad N + grad N . sigma grad N I), v = J V0.
    """
    import scipy.sparse as sp

    V0, D, F, J = cell_gradients(points, cells, x)
    b = F @ F.swapaxes(1, 2)
    E = 0.5 * (F.swapaxes(1, 2) @ F - np.eye(3))
    S = LAM * np.trace(E, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * MU * E
    sig = F @ S @ F.swapaxes(1, 2) / J[:, None, None]
    Jc = LAM * np.einsum("mij,mkl->mijkl", b, b) + MU * (
        np.einsum("mik,mjl->mijkl", b, b) + np.einsum("mil,mjk->mijkl", b, b)
    )
    c = transform(Jc, F) / J[:, None, None, None, None]
    g = D @ np.linalg.inv(F)
    Ke = np.einsum("maj,mijkl,mbl->maibk", g, c, g) + np.einsum(
        "mab,ik->maibk", np.einsum("maj,mjl,mbl->mab", g, sig, g), np.eye(3)
    )
    Ke = (J * V0)[:, None, None, None, None] * Ke
    dofs = (3 * cells[:, :, None] + np.arange(3)).reshape(-1, 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    n = 3 * points.shape[0]
    return sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(n, n))


@pytest.mark.parametrize("uniform", [False, True])
def test_a_tangent_in_float32_with_a_double_exact_force_is_named(uniform):
    """The per-cell spatial tangent J c rounded to float32 (a UMAT's REAL*4 tangent), the stress,
    force and assembly in double (corpus 7): named as the stiffness in single precision, on a
    random state and on a uniform one (every cell rounds alike). Nearby, double engines with a
    small systematic tangent error of the same size (a coefficient off by 1e-8; a tangent off
    by a smooth term, as a finite-difference tangent with a tiny step) are not named so.
    """
    from types import SimpleNamespace

    from conformance.diagnosis.mixed_precision import rounded_tangent_finding

    points, cells = box_mesh(2, jitter=0.0 if uniform else 0.2, seed=1)
    rng = np.random.default_rng(1)
    x = points @ np.diag([1.1, 0.95, 0.97]).T
    if not uniform:
        x = x + 0.03 * rng.standard_normal(points.shape)
    split, f_o, K_o, s = mjed_split(M.StVenantKirchhoff(mu=MU, lam=LAM), points, cells, x)

    def found(transform):
        K = _svk_spatial_stiffness(points, cells, x, transform)
        return rounded_tangent_finding(split, SimpleNamespace(force=f_o, stiffness=K), s)

    exact = found(lambda Jc, F: Jc)
    assert exact is None  # the engine right: nothing to name
    f32 = found(lambda Jc, F: Jc.astype(np.float32).astype(np.float64))
    assert f32 is not None and f32.figures["form"] == "Jc", f32
    assert "single precision" in f32.title
    for wrong in (
        lambda Jc, F: Jc * (1 + 1e-8),
        lambda Jc, F: Jc + 1e-8 * MU * np.einsum("mij,mkl->mijkl", F @ F, F @ F),
    ):
        K = _svk_spatial_stiffness(points, cells, x, wrong)
        e = np.abs(K - K_o).max() / np.abs(K_o).max()
        assert 1e-10 < e < 1e-6  # a failing tangent of float32's size
        assert found(wrong) is None


def test_rest_gradients_inverted_in_float32_are_named_and_rounding_in_the_material_is_not():
    """The rest edge matrix inverted in float32, the rest double: the error is that inverse's
    own, fixed at the probes; named as rest data. C in float32 (drawn anew at the probes) is
    not rest data, and a correct engine has nothing to name.
    """
    points, cells, x, model, split, f_o, probes = _setup(1)
    error, at_probes = _errors(points, cells, x, probes, d32=True)
    found = rest_rounding_finding(split, model, points, x, error, at_probes)
    assert found is not None and found.code == "single-precision-rest-data", found
    assert "inverse rest edge matrix" in found.title
    error, at_probes = _errors(points, cells, x, probes, f32=True)
    assert rest_rounding_finding(split, model, points, x, error, at_probes) is None


def _nh_force(points, cells, x, *, cof32=False, mu=1.0, lam=2.0):
    """Force (n, 3) of W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 written in F:
    P = mu F + Psi_J cof F, Psi_J = (lam ln J - mu) / J; cof32: the cofactor matrix taken from
    F rounded to float32 (a single-precision cross-product kernel), the rest in double.
    """
    X = points[cells]
    Mt = np.swapaxes(X[:, 1:] - X[:, :1], 1, 2)
    V0 = np.linalg.det(Mt) / 6.0
    Minv = np.linalg.inv(Mt)
    D = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)
    F = np.einsum("mai,maj->mij", x[cells], D)
    J = np.linalg.det(F)
    G = F.astype(np.float32).astype(float) if cof32 else F
    f0, f1, f2 = G[:, :, 0], G[:, :, 1], G[:, :, 2]
    cof = np.stack([np.cross(f1, f2), np.cross(f2, f0), np.cross(f0, f1)], axis=2)
    P = mu * F + ((lam * np.log(J) - mu) / J)[:, None, None] * cof
    fe = -V0[:, None, None] * np.einsum("mij,maj->mai", P, D)
    f = np.zeros(points.shape)
    np.add.at(f, cells.ravel(), fe.reshape(-1, 3))
    return f


def test_the_cofactor_from_a_float32_f_is_named_as_that_gradient_rounded():
    """Only the J piece Psi_J cof F of P sees the rounded F (corpus 19's Demiray engine): the
    rounding of F as a whole predicts it poorly where the I1 piece dominates the stress.
    """
    import mjed

    points, cells = box_mesh(3, jitter=0.2, seed=4)
    rng = np.random.default_rng(4)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.03 * rng.standard_normal(points.shape)
    model = M.NeoHookean(mu=1.0, lam=2.0)
    split, f_o, _, _ = mjed_split(model, points, cells, x)
    assert np.allclose(_nh_force(points, cells, x), f_o, rtol=0, atol=1e-13)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    probes = [x + 1e-4 / 3 * 2.0**-k * rng.standard_normal(x.shape) for k in range(3)]
    err = [_nh_force(points, cells, y, cof32=True) - field.force(y) for y in [x, *probes]]
    found = mixed_precision_finding(split, model, points, x, err[0], err[1:])
    assert found is not None and found.figures["best"] == "grad J", found
    assert "cofactor" in found.title
    r = found.figures["correlations"]
    assert r["grad J"] > 0.99 and r["grad J"] - r["F"] > 0.05  # F as a whole fits worse
