"""Energies the user writes (reference_fem/user_energy.py): the parser refuses everything
outside its whitelist, every variable means what it says, and the UFL oracle built on a
user energy agrees with the built-in materials it re-expresses.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import box_mesh, perturbed, random_tetrahedron

from reference_fem.user_energy import (
    EnergySyntaxError,
    PrestressWarning,
    UserEnergy,
    parse_fibre,
    parse_param,
    parse_user_energy,
    user_energy_from_cli,
)

NH = "mu/2*(I1-3) - mu*ln(J) + lam/2*ln(J)**2"


def _random_F(rng, m=5, scale=0.2):
    F = np.eye(3) + scale * rng.standard_normal((m, 3, 3))
    F[np.linalg.det(F) < 0] *= -1.0  # keep J > 0 (odd dimension: -F flips the sign of det)
    return F


# -- the parser refuses ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "expression, fragment",
    [
        (
            "__import__('os').system('true')",
            "only calls of ln, log, exp, sqrt, pow are allowed: '__import__('os').system' at "
            "column 1",
        ),
        ("__import__('os')", "'__import__' at column 1"),
        ("mu.real", "attribute access"),
        ("(lambda: 1)()", "lambda"),
        ("[I1 for _ in [1]][0]", "subscript"),
        ("sum(I1 for _ in (1,))", "only calls of"),
        ("{I1 for _ in (1,)}", "comprehension"),
        ("I1 if J > 1 else I2", "conditional expression"),
        ("I1 < 3", "comparison"),
        ("'I1'", "only real numbers are allowed, not a str"),
        ("1j*I1", "not a complex"),
        ("True*I1", "not a bool"),
        ("exp(x=I1)", "keyword arguments"),
        ("exp(*[I1])", "starred"),
        ("exp(I1, I2)", "exp takes 1 argument(s), got 2"),
        ("pow(I1)", "pow takes 2 argument(s), got 1"),
        ("abs(I1)", "'abs' at column 1"),
        ("I1 // 2", "operator FloorDiv"),
        ("I1 % 2", "operator Mod"),
        ("~J", "operator Invert"),
        ("(x := I1)", "assignment expression"),
        ("I1**1e9", "exponent 1e+09 is outside"),
        ("pow(I1, -100)", "exponent -100 is outside"),
        ("9**9**9", "arithmetic error"),  # each literal exponent is small; the tower overflows
        ("I1 + 1e999", "not finite"),
        ("I1 +", "not a valid expression"),
        ("I1\nimport os", "one line"),
        ("", "empty"),
        ("I1 + " * 1200 + "1", "characters; at most"),
        ("I6 - 3", "unknown name 'I6'"),
    ],
)
def test_parser_refuses_with_the_offending_text(expression, fragment):
    with pytest.raises((EnergySyntaxError, ValueError)) as info:
        UserEnergy(expression, {"mu": 1.0} if "mu" in expression else {})
    assert fragment in str(info.value)


def test_an_error_names_the_column_of_the_offending_token():
    with pytest.raises(EnergySyntaxError, match=r"unknown name 'nu'.*'nu' at column 13"):
        UserEnergy("mu*(I1-3) + nu*(J-1)**2", {"mu": 1.0})
    with pytest.raises(EnergySyntaxError, match=r"'os\.getcwd' at column 8"):
        UserEnergy("I1 + 2*os.getcwd()", {})


def test_parameters_and_fibre_are_checked():
    with pytest.raises(ValueError, match="not used in the expression"):
        UserEnergy("mu*(I1-3)", {"mu": 1.0, "K": 2.0})
    with pytest.raises(ValueError, match="must be finite"):
        UserEnergy("mu*(I1-3)", {"mu": float("nan")})
    with pytest.raises(ValueError, match="is a variable or function name"):
        UserEnergy("J*(I1-3)", {"J": 1.0})
    deferred = UserEnergy("(I4-1)**2", {})  # built; a kit gives it the mesh's frame field
    assert deferred.direction_missing
    with pytest.raises(ValueError, match="need a fibre direction"):
        deferred.density(np.eye(3)[None])
    with pytest.raises(ValueError, match="neither I4 nor I5"):
        UserEnergy("I1-3", {}, fibre=(1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="a frame is given but neither I4 nor I5"):
        UserEnergy("I1-3", {}, frame=np.eye(3))
    with pytest.raises(ValueError, match="not both"):
        UserEnergy("(I4-1)**2", {}, fibre=(1.0, 0.0, 0.0), frame=np.eye(3))
    with pytest.raises(ValueError, match="must be orthonormal"):
        UserEnergy("(I4-1)**2", {}, frame=np.stack([np.eye(3), 2 * np.eye(3)]))
    with pytest.raises(ValueError, match="shape"):
        UserEnergy("(I4-1)**2", {}, frame=np.eye(3)[:2])
    with pytest.raises(ValueError, match="zero vector"):
        UserEnergy("(I4-1)**2", {}, fibre=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="not finite"):
        UserEnergy("ln(J-1)", {})


def test_cli_strings():
    e = user_energy_from_cli("mu/2*(I1b-3) + K/2*(J-1)**2", ["mu=1e3", " K = 1e4"])
    assert dict(e.params) == {"K": 1e4, "mu": 1e3}
    assert parse_param("c_1=-2.5") == ("c_1", -2.5)
    assert parse_fibre("1, 0,0") == (1.0, 0.0, 0.0)
    for bad, match in [
        ("mu", "NAME=VALUE"),
        ("mu=abc", "not a number"),
        ("1mu=2", "not a valid"),
        ("mu=inf", "finite"),
    ]:
        with pytest.raises(ValueError, match=match):
            parse_param(bad)
    with pytest.raises(ValueError, match="three numbers"):
        parse_fibre("1,0")
    with pytest.raises(ValueError, match="given twice"):
        user_energy_from_cli("mu*(I1-3)", ["mu=1", "mu=2"])


def test_the_user_values_are_kept_and_the_energy_is_frozen_and_hashable():
    params = {"mu": 2, "K": 3}
    e = parse_user_energy("mu*(I1b-3) + K*(J-1)**2", params, fibre=None)
    params["mu"] = 99.0  # the caller's dict is not aliased
    assert e.params["mu"] == 2.0
    with pytest.raises(TypeError):
        e.params["mu"] = 5.0  # read-only
    with pytest.raises(AttributeError):
        e.expression = "I1"
    assert e == UserEnergy("mu*(I1b-3) + K*(J-1)**2", {"K": 3.0, "mu": 2.0})
    assert len({e, UserEnergy("mu*(I1b-3) + K*(J-1)**2", {"K": 3.0, "mu": 2.0})}) == 1
    f = UserEnergy("(I4-1)**2", {}, fibre=(2.0, 0.0, 0.0))
    assert f.fibre == (2.0, 0.0, 0.0) and np.allclose(f.unit_fibre, [1.0, 0.0, 0.0])


# -- every variable, in NumPy ----------------------------------------------------------------


def test_every_variable_against_its_definition(rng):
    F = _random_F(rng)
    C = np.einsum("mki,mkj->mij", F, F)
    J = np.linalg.det(F)
    I1 = np.trace(C, axis1=1, axis2=2)
    I2 = 0.5 * (I1**2 - np.einsum("mij,mji->m", C, C))
    a = np.array([1.0, 2.0, -2.0]) / 3.0
    expected = {
        "I1": I1,
        "I2": I2,
        "I3": J**2,
        "J": J,
        "I1b": J ** (-2 / 3) * I1,
        "I2b": J ** (-4 / 3) * I2,
        "I4": np.einsum("i,mij,j->m", a, C, a),
        "I5": np.einsum("i,mij,mjk,k->m", a, C, C, a),
    }
    for i in range(3):
        for j in range(3):
            expected[f"C{i + 1}{j + 1}"] = C[:, i, j]
            expected[f"E{i + 1}{j + 1}"] = 0.5 * (C[:, i, j] - (i == j))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PrestressWarning)  # e.g. W = I1 is stressed at rest
        for name, value in expected.items():
            fibre = (3.0, 6.0, -6.0) if name in ("I4", "I5") else None  # normalised to a
            e = UserEnergy(name, {}, fibre=fibre)
            assert e.variables == (name,)
            np.testing.assert_allclose(e.density(F), value, rtol=1e-13, err_msg=name)


def test_functions_and_operators(rng):
    F = _random_F(rng)
    J = np.linalg.det(F)
    with pytest.warns(PrestressWarning):  # P(I) = (3 + 1 - 1 + 1/2 + 1/2) I
        e = UserEnergy("pow(J, 3) + exp(J-1) - log(J) + ln(J)**2 + sqrt(J) - -J/2 + +1", {})
    np.testing.assert_allclose(
        e.density(F),
        J**3 + np.exp(J - 1) - np.log(J) + np.log(J) ** 2 + np.sqrt(J) + J / 2 + 1,
        rtol=1e-14,
    )


def test_first_piola_matches_a_finite_difference_of_the_energy(rng):
    """The complex-step P of a fibre energy (I4, I5) against central differences of W."""
    e = UserEnergy(
        "k1/(2*k2)*(exp(k2*(I4-1)**2)-1) + c*(I5-1)**2 + mu/2*(I1b-3) + K/2*(J-1)**2",
        {"k1": 2.0, "k2": 0.7, "c": 0.3, "mu": 1.0, "K": 5.0},
        fibre=(1.0, 1.0, 0.5),
    )
    F = _random_F(rng, m=3)
    P = e.first_piola(F)
    h = 1e-6
    P_fd = np.zeros_like(P)
    for k in range(3):
        for l in range(3):
            dF = np.zeros((3, 3))
            dF[k, l] = h
            P_fd[:, k, l] = (e.density(F + dF) - e.density(F - dF)) / (2 * h)
    assert np.linalg.norm(P - P_fd) <= 1e-8 * np.linalg.norm(P)


def test_the_state_at_rest_is_reported():
    e = UserEnergy("mu/2*(I1b-3) + K/2*(J-1)**2", {"mu": 1e3, "K": 1e4})
    assert not e.prestressed and e.rest_energy == 0.0 and "stress-free" in e.rest_report()
    with pytest.warns(PrestressWarning, match=r"\|P\(I\)\| = 1\.73205"):
        shifted = UserEnergy("mu/2*I1", {"mu": 1.0})  # W(I) = 3/2, P(I) = mu I: pre-stressed
    assert shifted.prestressed and shifted.rest_energy == 1.5
    np.testing.assert_allclose(shifted.rest_stress, np.eye(3), atol=1e-15)
    # A constant offset of W alone leaves the rest stress-free.
    felupe_like = UserEnergy("mu*(I1/2 - ln(J)) + lam/2*ln(J)**2", {"mu": 1.0, "lam": 2.0})
    assert not felupe_like.prestressed and felupe_like.rest_energy == 1.5


def test_cell_energies_sum_v0_w(rng):
    P, cells = random_tetrahedron(rng)
    x = perturbed(P, rng, 0.05)
    e = UserEnergy(NH, {"mu": 1.3, "lam": 2.1})
    D0 = (P[cells[0, 1:]] - P[cells[0, 0]]).T
    F = (x[cells[0, 1:]] - x[cells[0, 0]]).T @ np.linalg.inv(D0)
    np.testing.assert_allclose(
        e.cell_energies(P, cells, x), abs(np.linalg.det(D0)) / 6 * e.density(F[None]), rtol=1e-14
    )


# -- the UFL translation through the oracle ---------------------------------------------------


def _oracle_class():
    pytest.importorskip("dolfinx", reason="the UFL oracle needs dolfinx (Debian: python3-dolfinx)")
    from reference_fem import UFLOracle

    return UFLOracle


def _relative(a, b):
    a = a.toarray() if hasattr(a, "toarray") else np.asarray(a)
    b = b.toarray() if hasattr(b, "toarray") else np.asarray(b)
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def _cube_small():
    pytest.importorskip("meshio", reason="cube-small is stored as a gmsh file")
    import meshes

    return meshes.load("cube-small")


@pytest.mark.oracle
@pytest.mark.parametrize(
    "builtin, expression",
    [
        ("NeoHookean", NH),
        ("MooneyRivlin", "c1*(I1b-3) + c2*(I2b-3) + k0/2*ln(J)**2"),
        (
            "StVenantKirchhoff",
            "lam/2*(E11+E22+E33)**2 + mu*(E11**2+E22**2+E33**2+2*(E12**2+E13**2+E23**2))",
        ),
    ],
)
def test_a_user_energy_equal_to_a_builtin_gives_the_builtin_oracle(builtin, expression):
    from conftest import MATERIALS

    UFLOracle = _oracle_class()

    mat = MATERIALS[builtin]
    names = {
        "NeoHookean": ("mu", "lam"),
        "MooneyRivlin": ("c1", "c2", "k0"),
        "StVenantKirchhoff": ("mu", "lam"),
    }
    user = UserEnergy(
        expression, {n: getattr(mat, n) for n in names[builtin]}, name=f"{builtin} as an expression"
    )
    points, cells = _cube_small()
    ref, mine = UFLOracle(points, cells, mat), UFLOracle(points, cells, user)
    from common.states import apply_state

    for state in ("uniaxial", "shear", "random"):
        x = apply_state(state, points, cells)
        f0, K0 = ref.force_and_stiffness(x)
        f1, K1 = mine.force_and_stiffness(x)
        assert _relative(f1, f0) < 1e-12, state
        assert _relative(K1, K0) < 1e-12, state
        assert abs(mine.energy(x) - ref.energy(x)) <= 1e-12 * abs(ref.energy(x))
        np.testing.assert_allclose(
            user.cell_energies(points, cells, x).sum(), ref.energy(x), rtol=1e-12
        )
    # Not vacuous: a 1e-6 change of one parameter is seen.
    p = dict(user.params)
    first = names[builtin][0]
    p[first] *= 1 + 1e-6
    shifted = UFLOracle(points, cells, UserEnergy(expression, p))
    x = apply_state("random", points, cells)
    assert _relative(shifted.force(x), ref.force(x)) > 1e-8


@pytest.mark.oracle
def test_a_fibre_energy_through_the_oracle_matches_finite_differences_of_w():
    """Force from UFL differentiation of an I4/I5 energy against central differences of the
    NumPy energy sum(V0 W), node by node, on a jittered small box.
    """
    UFLOracle = _oracle_class()
    e = UserEnergy(
        "k1/(2*k2)*(exp(k2*(I4-1)**2)-1) + c*(I5-1)**2 + mu/2*(I1b-3) + K/2*(J-1)**2",
        {"k1": 2.0, "k2": 0.7, "c": 0.3, "mu": 1.0, "K": 5.0},
        fibre=(1.0, 1.0, 0.5),
    )
    points, cells = box_mesh(2, jitter=0.2)
    x = perturbed(points, np.random.default_rng(3), 0.05)
    oracle = UFLOracle(points, cells, e)
    f = oracle.force(x)
    assert abs(oracle.energy(x) - e.cell_energies(points, cells, x).sum()) <= 1e-12 * abs(
        oracle.energy(x)
    )
    h = 1e-6
    f_fd = np.zeros_like(f)
    for node in range(points.shape[0]):
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[node, c] += h
            xm[node, c] -= h
            f_fd[node, c] = -(
                e.cell_energies(points, cells, xp).sum() - e.cell_energies(points, cells, xm).sum()
            ) / (2 * h)
    assert np.linalg.norm(f - f_fd) <= 1e-7 * np.linalg.norm(f)
    # The stiffness is the derivative of the force: a directional central difference.
    K = oracle.stiffness(x)
    d = np.random.default_rng(4).standard_normal(x.shape)
    df = (oracle.force(x + h * d) - oracle.force(x - h * d)) / (2 * h)
    assert np.linalg.norm(-K @ d.ravel() - df.ravel()) <= 1e-7 * np.linalg.norm(df)


@pytest.mark.oracle
def test_a_prestressed_energy_has_a_force_at_rest_in_the_oracle():
    UFLOracle = _oracle_class()
    points, cells = box_mesh(1)
    with pytest.warns(PrestressWarning):
        e = UserEnergy("p*(J-1) + mu/2*(I1b-3)", {"p": 10.0, "mu": 1.0})
    f = UFLOracle(points, cells, e).force(points)
    # P(I) = p I: the boundary nodes are pulled, total force zero.
    assert np.linalg.norm(f) > 1.0 and np.allclose(f.sum(axis=0), 0.0, atol=1e-12)


def test_a_frame_per_cell_gives_each_cell_its_own_fibre():
    """I4 and I5 with a frame per cell (first column the fibre): NumPy and the oracle, cell by cell,
    against energies built with that cell's fibre alone; equality and hashing see the frame.
    """
    import dataclasses

    from common.frames import helix_frames

    UFLOracle = _oracle_class()
    expression = "k1/(2*k2)*(exp(k2*(I4-1)**2)-1) + c*(I5-1)**2 + mu/2*(I1b-3) + K/2*(J-1)**2"
    params = {"k1": 2.0, "k2": 0.7, "c": 0.3, "mu": 1.0, "K": 5.0}
    points, cells = box_mesh(2, jitter=0.2)
    R = helix_frames(points, cells)
    e = UserEnergy(expression, params, frame=R)
    x = perturbed(points, np.random.default_rng(3), 0.05)
    alone = [UserEnergy(expression, params, fibre=tuple(R[k][:, 0])) for k in range(len(cells))]
    one_by_one = np.array([e_k.cell_energies(points, cells, x)[k] for k, e_k in enumerate(alone)])
    np.testing.assert_allclose(e.cell_energies(points, cells, x), one_by_one, rtol=1e-13)
    assert np.ptp(R[:, :, 0], axis=0).max() > 0.5  # the fibres really differ from cell to cell
    oracle = UFLOracle(points, cells, e)
    assert abs(oracle.energy(x) - one_by_one.sum()) <= 1e-12 * abs(one_by_one.sum())
    h = 1e-6
    d = np.random.default_rng(5).standard_normal(x.shape)
    plus, minus = (e.cell_energies(points, cells, x + s * h * d).sum() for s in (1.0, -1.0))
    dW = (plus - minus) / (2 * h)
    assert abs(-np.vdot(oracle.force(x), d) - dW) <= 1e-7 * abs(dW)
    same = dataclasses.replace(e, frame=R.copy())
    assert same == e and hash(same) == hash(e)
    assert dataclasses.replace(e, frame=np.swapaxes(R, 1, 2).copy()) != e
    with pytest.raises(ValueError, match="cells evaluated with a frame of"):
        e.density(np.eye(3)[None])
