"""The compiled classical Galerkin against the NumPy one, for every material."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS, box_mesh, perturbed

import mjed
from mjed.compiled import numba_available
from mjed.materials import declarations

pytestmark = pytest.mark.skipif(
    not numba_available(),
    reason="the compiled backend needs Numba (Debian: python3-numba; PyPI: numba)",
)


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


def test_costa_with_one_frame_per_cell(cube):
    from scipy.spatial.transform import Rotation

    from reference_fem.classical import ClassicalGalerkin
    from reference_fem.classical_compiled import CompiledClassicalGalerkin

    mesh, x = cube
    frame = Rotation.random(mesh.n_cells, random_state=3).as_matrix()
    material = mjed.materials.Costa(
        a=0.9, k0=3.0, b_ff=1.0, b_fs=0.3, b_ss=0.8, b_fn=0.2, b_sn=0.1, b_nn=0.5, frame=frame
    )
    comp = CompiledClassicalGalerkin(mesh, None, material)
    assert comp.shape.per_cell_T
    (f_r, K_r), (f_c, K_c) = (
        ClassicalGalerkin(mesh, None, material).force_and_stiffness(x),
        comp.force_and_stiffness(x),
    )
    assert np.linalg.norm(f_c - f_r) <= 1e-13 * np.linalg.norm(f_r)
    assert abs(K_c - K_r).max() <= 1e-12 * abs(K_r).max()


def test_every_default_material_has_its_own_kernel_shape():
    from reference_fem.classical_compiled import lower_law
    from reference_fem.classical_materials import classical_law

    shapes = {name: lower_law(classical_law(m))[0] for name, m in MATERIALS.items()}
    assert (
        shapes["Ogden"] == shapes["OgdenNegative"] and shapes["Costa"] == shapes["CostaIndefinite"]
    )
    names = [d.name for d in declarations()]
    assert len({shapes[n] for n in names}) == len(names)
    # a shape prints the same in every process (it names the generated source): no addresses
    assert all(" at 0x" not in repr(shapes[n]) for n in names)


def test_unknown_law_is_refused():
    from reference_fem.classical_compiled import lower_law
    from reference_fem.classical_materials import ClassicalLaw

    with pytest.raises(NotImplementedError, match="no compiled classical kernel"):
        lower_law(ClassicalLaw())
