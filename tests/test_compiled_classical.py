"""The compiled classical Galerkin against the NumPy one, for every material."""

from __future__ import annotations

import numpy as np
import pytest

import mjed
from conftest import MATERIALS, box_mesh, perturbed
from mjed.compiled import numba_available

pytestmark = pytest.mark.skipif(not numba_available(), reason="the compiled backend needs Numba "
                                "(Debian: python3-numba; PyPI: numba)")


@pytest.fixture(scope="module")
def cube():
    points, cells = box_mesh(3, jitter=0.3)
    return mjed.TetMesh(points, cells), perturbed(points, np.random.default_rng(7), 0.06)


def test_compiled_classical_equals_numpy_classical(material, cube):
    from reference_fem.classical import ClassicalGalerkin
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    mesh, x = cube
    ref = ClassicalGalerkin(mesh, None, material)
    comp = CompiledClassicalGalerkin(mesh, None, material)
    f_r, K_r = ref.force_and_stiffness(x)
    f_c, K_c = comp.force_and_stiffness(x)
    assert np.linalg.norm(f_c - f_r) <= 1e-13 * np.linalg.norm(f_r)
    assert abs(K_c - K_r).max() <= 1e-12 * abs(K_r).max()
    assert comp.energy(x) == pytest.approx(ref.energy(x), rel=1e-13)
    assert np.array_equal(comp.force(x), f_c) and abs(comp.stiffness(x) - K_c).max() == 0.0


def test_law_codes_match_the_kernel_module():
    from reference_fem import classical_compiled as cc
    from reference_fem import classical_kernels as ck

    for name in ("LAW_SVK", "LAW_NEOHOOKE", "LAW_DECOUPLED", "LAW_OGDEN", "LAW_COSTA",
                 "PSI_MOONEY", "PSI_VERONDA", "PSI_ARRUDA"):
        assert getattr(cc, name) == getattr(ck, name), name


def test_unknown_law_is_refused():
    from reference_fem.classical_compiled import lower_law
    from reference_fem.classical_materials import ClassicalLaw

    with pytest.raises(NotImplementedError, match="no compiled classical kernel"):
        lower_law(ClassicalLaw())
