"""The compiled MJED kernels are generated per term-table shape (mjed.compiled.shape,
codegen, specialise): these tests would fail if a kernel baked in a number it should read,
dropped a term kind, mixed up two shapes, or recompiled in a second process.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import MATERIALS, box_mesh, deformed_cube, relative_difference

import mjed
from mjed.compiled import numba_available
from mjed.materials.base import Material

pytestmark = pytest.mark.skipif(
    not numba_available(),
    reason="the compiled backend needs Numba (Debian: python3-numba; PyPI: numba)",
)
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cube():
    return deformed_cube(2, seed=11, scale=0.05)


def _agree(mesh, material, x, **kw):
    ref = mjed.make_force_field(mesh, material, **kw)
    comp = mjed.make_force_field(mesh, material, backend="numba", **kw)
    (f_r, K_r), (f_c, K_c) = ref.force_and_stiffness(x), comp.force_and_stiffness(x)
    assert relative_difference(f_c, f_r) < 1e-13
    assert abs(K_c - K_r).max() <= 1e-13 * abs(K_r).max()
    assert comp.energy(x) == pytest.approx(ref.energy(x), rel=1e-13)
    assert relative_difference(comp.stress(x), ref.stress(x)) < 1e-13
    return comp


@dataclass(frozen=True)
class EveryKind(Material):
    """A made-up energy with every compiled kind of f(J) and g(C), a plain group and one group
    of each function of a sum (exp, log, power), identity, constant and per-cell slot matrices
    and both eigen tangents. (The NumPy
    engine cannot yet add a constant S, I1Power(n=1) times a constant f, to a per-cell one in
    one group, so the constant f multiplies LinearI2 here.)
    """

    frame: object = None

    def decomposition(self):
        from mjed.fibre import FibreQuadratic
        from mjed.spectral import EigenPowerSum
        from mjed.terms import (
            GreenLagrangeQuadratic,
            I1Power,
            JLogJ,
            JPower,
            LinearI2,
            Log,
            LogPolynomial,
            Power,
            Term,
            TermGroup,
            Unity,
        )

        B = np.array([[1.0, 0.3, 0.2], [0.3, 0.8, 0.1], [0.2, 0.1, 0.5]])
        R = np.eye(3) if self.frame is None else self.frame
        plain = TermGroup(
            (
                Term(JPower(-2.0 / 3.0), I1Power(0.4)),
                Term(JPower(-2.0 / 3.0), I1Power(0.05, 3)),
                Term(JPower(0.0), LinearI2(0.2)),
                Term(JPower(0.5), GreenLagrangeQuadratic(0.3, 0.2)),
                Term(JPower(-0.4), EigenPowerSum(0.1, 0.75)),
                Term(JPower(0.0), EigenPowerSum(0.05, 1.5, "sofa")),
                Term(LogPolynomial(1.5, -0.7, 0.1), Unity()),
                Term(JLogJ(0.8, 0.2), Unity()),
            )
        )
        fibre = TermGroup(
            (Term(JPower(-4.0 / 3.0), FibreQuadratic(B, R)),), exponential=True, coefficient=0.3
        )
        # shift + u stays positive for any J > 0: both sums are >= 0
        log = TermGroup(
            (Term(JPower(-2.0 / 3.0), I1Power(0.05)), Term(JPower(0.3), LinearI2(0.02))),
            coefficient=-0.7,
            function=Log(0.9),
        )
        power = TermGroup(
            (Term(JPower(-4.0 / 3.0), LinearI2(0.03)),), coefficient=0.4, function=Power(1.5, 0.2)
        )
        return plain, fibre, log, power


@pytest.mark.parametrize("regularize", [False, True])
@pytest.mark.parametrize("per_cell", [False, True])
def test_a_material_with_every_term_kind(cube, regularize, per_cell):
    from scipy.spatial.transform import Rotation

    mesh, x = cube
    x = mesh.points + 0.8 * (x - mesh.points)
    x[:, 2] *= 0.85  # compressed cells, where the regularised tangent differs
    frame = Rotation.random(mesh.n_cells, random_state=5).as_matrix() if per_cell else None
    comp = _agree(mesh, EveryKind(frame), x, regularize=regularize)
    assert comp.shape.per_cell_R == per_cell and comp.shape.per_cell_M == per_cell
    kinds = {(t.j, t.g, t.n, t.coaxial) for t in comp.shape.terms}
    assert {j for j, *_ in kinds} == {"one", "power", "logpoly", "jlogj"}
    assert {g for _, g, *_ in kinds} == {
        "unity",
        "i1power",
        "linear_i2",
        "green_lagrange",
        "fibre",
        "eigen",
    }
    assert {c for *_, c in kinds} == {False, True}
    assert {k for k, _ in comp.shape.slots} == {"first", "second", "spectral"}
    assert {fn for *_, fn in comp.shape.groups} == {"plain", "exp", "log", "power"}


def test_one_shape_two_parameter_sets_share_a_kernel_and_keep_their_numbers(cube):
    # If a parameter were baked into the generated source, the second material would get the
    # first one's numbers (or a second kernel).
    mesh, x = cube
    soft, stiff = (
        mjed.materials.NeoHookean(mu=1.3, lam=2.1),
        mjed.materials.NeoHookean(mu=40.0, lam=0.25),
    )
    a, b = _agree(mesh, soft, x), _agree(mesh, stiff, x)
    assert a.shape == b.shape and a._kernel is b._kernel
    assert abs(a.energy(x) - b.energy(x)) > 1e-3 * abs(a.energy(x))


def test_shapes_that_differ_get_different_kernels(cube):
    mesh, _ = cube
    fields = {
        name: mjed.make_force_field(mesh, MATERIALS[name], backend="numba")
        for name in (
            "NeoHookean",
            "MooneyRivlin",
            "Ogden",
            "OgdenNegative",
            "Costa",
            "CostaIndefinite",
        )
    }
    kernels = {name: f._kernel for name, f in fields.items()}
    # same structure, other numbers: one kernel
    assert (
        kernels["Ogden"] is kernels["OgdenNegative"]
        and kernels["Costa"] is kernels["CostaIndefinite"]
    )
    distinct = {id(kernels[n]) for n in ("NeoHookean", "MooneyRivlin", "Ogden", "Costa")}
    assert len(distinct) == 4
    files = {Path(sys.modules[k.__module__].__file__).name for k in kernels.values()}
    assert len(files) == 4
    # a constant J-power is structure (f' = f'' = 0), its exponent otherwise is not
    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape
    from mjed.terms import I1Power, JPower, Term, TermGroup

    def shape(p):
        return kernel_shape(lower_groups((TermGroup((Term(JPower(p), I1Power(1.0)),)),), mesh.D))

    assert shape(0.0) != shape(-2.0 / 3.0) and shape(-2.0 / 3.0) == shape(-4.0 / 3.0)


def test_a_damaged_generated_file_is_rewritten_not_trusted(tmp_path, monkeypatch):
    from mjed.compiled import specialise

    monkeypatch.setenv("MJED_KERNEL_CACHE", str(tmp_path))
    monkeypatch.setattr(specialise, "_MODULES", {})
    source = '"""test module"""\nVALUE = 1\n'
    module = specialise.generated_module(source, "mjed_test")
    path = Path(module.__file__)
    assert path.parent == tmp_path and module.VALUE == 1
    path.write_text(path.read_text().replace("VALUE = 1", "VALUE = 2"))
    monkeypatch.setattr(specialise, "_MODULES", {})
    sys.modules.pop(module.__name__, None)
    again = specialise.generated_module(source, "mjed_test")
    assert again.VALUE == 1 and Path(again.__file__) == path


_SECOND_PROCESS = """
import numpy as np, mjed
from mjed.materials import MooneyRivlin
from reference_fem.classical_compiled import CompiledClassicalGalerkin
X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
mesh = mjed.TetMesh(X, np.array([[0, 1, 2, 3]]))
mat = MooneyRivlin(c1=0.7, c2=0.4, k0=5.0)
fields = [
    mjed.make_force_field(mesh, mat, backend="numba"),
    CompiledClassicalGalerkin(mesh, None, mat),
]
for f in fields:
    f.force_and_stiffness(X * 1.1)
print(sum(sum(f._kernel.stats.cache_hits.values()) for f in fields),
      sum(sum(f._kernel.stats.cache_misses.values()) for f in fields))
"""


@pytest.mark.slow
def test_a_second_process_loads_the_compiled_kernels_from_the_cache(tmp_path):
    env = dict(os.environ, MJED_KERNEL_CACHE=str(tmp_path), PYTHONPATH=str(ROOT))
    runs = [
        subprocess.run(
            [sys.executable, "-c", _SECOND_PROCESS],
            env=env,
            capture_output=True,
            text=True,
            check=True,
            cwd=ROOT,
        ).stdout.split()
        for _ in range(2)
    ]
    (hits1, misses1), (hits2, misses2) = [tuple(map(int, r)) for r in runs]
    assert misses1 == 2 and hits1 == 0  # compiled once each
    assert hits2 == 2 and misses2 == 0  # then loaded, not compiled
    assert not any(p.suffix == ".py" for p in ROOT.rglob("mjed_kernel_*.py")), (
        "generated files in the repository"
    )


def test_classical_kernels_are_one_per_law_shape_and_keep_their_numbers(cube):
    # The classical kernel is generated per law shape too: laws of one shape share a module
    # and read their own numbers; laws of different shapes never share one.
    from reference_fem.classical import ClassicalGalerkin
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    mesh, x = cube
    names = (
        "StVenantKirchhoff",
        "NeoHookean",
        "MooneyRivlin",
        "Ogden",
        "OgdenNegative",
        "Costa",
        "CostaIndefinite",
    )
    fields = {name: CompiledClassicalGalerkin(mesh, None, MATERIALS[name]) for name in names}
    kernels = {name: f._kernel for name, f in fields.items()}
    assert (
        kernels["Ogden"] is kernels["OgdenNegative"]
        and kernels["Costa"] is kernels["CostaIndefinite"]
    )
    distinct = ("StVenantKirchhoff", "NeoHookean", "MooneyRivlin", "Ogden", "Costa")
    assert len({Path(sys.modules[kernels[n].__module__].__file__).name for n in distinct}) == len(
        distinct
    )
    for name in ("OgdenNegative", "CostaIndefinite"):  # the second of a shape gets its own numbers
        f_r = ClassicalGalerkin(mesh, None, MATERIALS[name]).force(x)
        assert relative_difference(fields[name].force(x), f_r) < 1e-13


def test_a_log_group_beyond_its_domain_gives_nan_in_the_kernel_too():
    """The kernel's ln(a + u) group, like the NumPy engine's, has NaN derivatives where a + u <= 0
    (Gent past its locking stretch), not a finite force.
    """
    points, cells = box_mesh(1)
    mesh = mjed.TetMesh(points, cells)
    gent = mjed.materials.Gent(mu=1.0, Jm=0.5, k0=3.0)
    field = mjed.make_force_field(mesh, gent, backend="numba")
    f, K = field.force_and_stiffness(points * np.array([2.0, 0.7, 0.7]))
    assert np.isnan(f).all() and np.isnan(K.data).all()
    assert np.isfinite(field.force(points * np.array([1.1, 0.95, 0.95]))).all()
