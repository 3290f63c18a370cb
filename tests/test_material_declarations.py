"""Every declared material appears everywhere it must, and a declaration that misses a piece
is refused with an error naming it.

Everywhere: the oracle (its UFL energy, the J-only part for the diagnosis), the classical
element (its law, NumPy and the compiled kernel's shape), the compiled MJED kernel (its term
table and shape), the checker and the exchange format (names, manifest round trip), the
command line's names and defaults, the test parameter sets and the table that the site
build writes into docs/conventions.md. Nothing here lists the materials: a new declaration is
covered by being declared.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import MATERIALS, random_tetrahedron

import mjed
from mjed.materials import declarations
from mjed.materials.declaration import (
    Declaration,
    declaration_of,
    declare,
    docs_table,
    docs_table_row,
)

ROOT = Path(__file__).resolve().parents[1]
DECLARED = {d.name: d for d in declarations()}


@pytest.fixture(params=sorted(DECLARED))
def declared(request) -> Declaration:
    return DECLARED[request.param]


def test_the_package_exports_every_declared_material(declared):
    assert getattr(mjed.materials, declared.name) is declared.material
    assert declaration_of(declared.material) is declared


def test_command_line_names_and_defaults(declared):
    from common.cases import DEFAULT_MATERIALS, default_material, parse_materials

    assert DEFAULT_MATERIALS[declared.name] is declared.default
    for spelling in (declared.name, declared.name.lower(), *declared.aliases):
        assert default_material(spelling) is declared.default
    assert declared.default in parse_materials("all")


def test_exchange_format_round_trip(declared):
    from conformance.kit.spec import MATERIAL_TYPES, model_from_manifest, model_to_manifest

    assert MATERIAL_TYPES[declared.name] is declared.material
    entry = model_to_manifest(declared.default)
    assert entry["name"] == declared.name
    assert (
        model_from_manifest(entry) == declared.default or declared.name == "Costa"
    )  # Costa: eq=False
    assert model_to_manifest(model_from_manifest(entry)) == entry


def test_classical_element_agrees_with_the_engine_on_energy_and_stress(declared):
    """Its classical law exists, and at a strained state its W and S = 2 dW/dC are MJED's:
    the two come from different declarations (law form and terms), so this is a check.
    """
    from reference_fem.classical_materials import classical_law

    material = MATERIALS[declared.name]
    P, cells = random_tetrahedron(np.random.default_rng(5))
    x = P @ np.array([[1.1, 0.1, 0.0], [0.05, 0.95, 0.0], [0.0, 0.02, 1.05]]).T
    field = mjed.HyperelasticForceField(mjed.TetMesh(P, cells), material)
    F = x[cells[0]].T @ field.mesh.D[0]
    C, J = (F.T @ F)[None], np.array([np.linalg.det(F)])
    law = classical_law(material)
    V0 = field.mesh.volumes[0]
    assert law.energy(C, J)[0] * V0 == pytest.approx(field.energy(x), rel=1e-12)
    S_mjed = field.stress(x)[0]
    assert np.abs(law.stress(C, J)[0] - S_mjed).max() <= 1e-11 * np.abs(S_mjed).max()


def test_compiled_kernels_have_a_shape(declared):
    """Both compiled kernels can be written for it (lowering only; compiling and running
    them against the oracle is tests/test_compiled_oracle.py's job, on the same list).
    """
    from mjed.compiled.lowering import lower_groups
    from mjed.compiled.shape import kernel_shape
    from reference_fem.classical_codegen import classical_source
    from reference_fem.classical_compiled import lower_law
    from reference_fem.classical_materials import classical_law

    material = declared.default
    shape = kernel_shape(lower_groups(material.decomposition(), np.zeros((1, 4, 3))))
    assert shape.terms
    law_shape = lower_law(classical_law(material))[0]
    assert "def classical_cells(" in classical_source(law_shape)


def test_oracle_has_its_energy_and_its_volumetric_part(declared):
    pytest.importorskip("ufl", reason="the oracle's energies are UFL")
    import ufl

    from conformance.judge.parts import volumetric_energy
    from reference_fem.energies import energy_formula, strain_energy_density

    assert energy_formula(declared.material).material_type is declared.material
    F = ufl.as_matrix([[1.1, 0.05, 0.0], [0.0, 0.95, 0.02], [0.01, 0.0, 1.05]])
    assert strain_energy_density(declared.default, F) is not None
    vol = volumetric_energy(
        declared.default, F, lambda name: float(getattr(declared.default, name))
    )
    assert (vol is None) == (declared.volumetric is None)


def test_the_checker_passes_mjed_and_fails_a_wrong_engine(declared):
    """The conformance check runs the material end to end (model, oracle, comparison)."""
    pytest.importorskip("dolfinx", reason="the checker's oracle needs dolfinx")
    from conformance import check_implementation

    def engine(case, scale=1.0):
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), case.model)
        f, K = field.force_and_stiffness(case.positions)
        return scale * f, scale * K

    kw = dict(material=declared.default, mesh="single-tet", states=("random",), probes=False)
    assert check_implementation(engine, **kw).n_passed == 1
    assert check_implementation(lambda case: engine(case, 1.001), **kw).n_passed == 0


def test_every_declared_material_has_test_parameters(declared):
    assert type(MATERIALS[declared.name]) is declared.material


def test_docs_table_is_generated_from_the_declarations():
    """conventions.md pastes no row: it includes the table the site build writes from the
    declarations (tests/test_docs_site.py reads the built page).
    """
    sys.path.insert(0, str(ROOT / "docs" / "_ext"))
    import site_generation

    text = (ROOT / "docs" / "conventions.md").read_text()
    assert f"```{{include}} generated/{site_generation.MATERIALS_TABLE}\n```" in text
    table = site_generation.materials_table()
    assert table.startswith(docs_table())
    for name, declaration in DECLARED.items():
        assert f"| `{name}` |" not in text, f"conventions.md pastes a row of {name}"
        assert table.count(docs_table_row(declaration)) == 1, name


def _yeoh_fields():
    d = declaration_of(mjed.materials.Yeoh)
    return {f.name: getattr(d, f.name) for f in dataclasses.fields(Declaration)}


@pytest.mark.parametrize(
    "missing, message",
    [
        ("formula", "formula .* missing"),
        ("default", "default must be a Yeoh"),
        ("energy", "energy must be a function"),
        ("classical", "classical must be a function"),
        ("volumetric_formula", "volumetric and volumetric_formula go together"),
    ],
)
def test_a_declaration_missing_a_piece_is_refused(missing, message):
    fields = _yeoh_fields()
    fields[missing] = None
    with pytest.raises(TypeError, match=rf"declaration of Yeoh: {message}"):
        Declaration(**fields)


def test_a_classical_law_that_is_no_known_form_is_refused():
    fields = _yeoh_fields()
    fields["classical"] = lambda m: ("decoupled", m.c10)
    with pytest.raises(TypeError, match="declaration of Yeoh: classical must return a form of "):
        Declaration(**fields)


def test_a_declaration_is_refused_twice_and_an_undeclared_type_everywhere():
    from common.cases import default_material
    from conformance.kit.spec import SpecError, model_from_manifest
    from reference_fem.classical_materials import classical_law

    with pytest.raises(ValueError, match="Yeoh is already declared"):
        declare(declaration_of(mjed.materials.Yeoh))

    @dataclasses.dataclass(frozen=True)
    class Undeclared(mjed.materials.Material):
        mu: float = 1.0

    with pytest.raises(LookupError, match="Undeclared is not declared"):
        declaration_of(Undeclared)
    with pytest.raises(TypeError, match="no classical law for material type .*Undeclared"):
        classical_law(Undeclared())
    with pytest.raises(SpecError, match="unknown material 'Undeclared'"):
        model_from_manifest({"kind": "material", "name": "Undeclared", "parameters": {"mu": 1.0}})
    with pytest.raises(ValueError, match="unknown material 'Undeclared'"):
        default_material("Undeclared")


class _NumPyNamespace:
    """The formula namespace bound to NumPy for one homogeneous F: np.matrix gives the UFL
    meaning of ``*`` (matrix product), ``.T`` and ``[i, j]``.
    """

    exp, ln = staticmethod(np.exp), staticmethod(np.log)

    def __init__(self, F: np.ndarray, frame=None):
        self.C = np.matrix(F.T @ F)
        self.E = 0.5 * (self.C - np.eye(3))
        self.I1 = np.trace(self.C)
        self.I2 = 0.5 * (self.I1**2 - np.trace(self.C * self.C))
        self.J = np.linalg.det(F)
        self.lnJ = np.log(self.J)
        self.I1b, self.I2b = self.J ** (-2 / 3) * self.I1, self.J ** (-4 / 3) * self.I2
        self.frame = np.matrix(np.eye(3) if frame is None else frame)

    @staticmethod
    def tr(A):
        return np.trace(A)

    @staticmethod
    def eigenvalue_power_sum(C, q):
        return float((np.linalg.eigvalsh(np.asarray(C)) ** q).sum())


class _Values:
    def __init__(self, material):
        self.material = material

    def value(self, name):
        return float(getattr(self.material, name))

    __call__ = value


@pytest.mark.filterwarnings("ignore:the matrix subclass:PendingDeprecationWarning")
def test_the_oracles_formula_and_the_engines_terms_give_one_energy(declared):
    """Without dolfinx: the declared formula, evaluated with NumPy, is zero at rest and equals
    the energy of the MJED terms at a strained state (two independent writings of one W).
    """
    material = MATERIALS[declared.name]
    P, cells = random_tetrahedron(np.random.default_rng(3))
    field = mjed.HyperelasticForceField(mjed.TetMesh(P, cells), material)
    A = np.array([[1.15, 0.08, -0.03], [0.02, 0.92, 0.05], [-0.04, 0.01, 1.06]])
    frame = getattr(material, "frame", None)
    W = declared.energy(_Values(material), _NumPyNamespace(A, frame))
    assert W * field.mesh.volumes[0] == pytest.approx(field.energy(P @ A.T), rel=1e-12)
    assert abs(declared.energy(_Values(material), _NumPyNamespace(np.eye(3), frame))) <= 1e-12
    if declared.volumetric is not None:  # a function of J alone: the same for a pure dilation
        vol = declared.volumetric(_Values(material), _NumPyNamespace(A))
        dilation = np.linalg.det(A) ** (1 / 3) * np.eye(3)
        assert declared.volumetric(_Values(material), _NumPyNamespace(dilation)) == pytest.approx(
            vol
        )
