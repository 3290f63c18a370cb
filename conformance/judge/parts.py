"""The oracle's stiffness split into named parts, for the diagnosis.

Every part is a bilinear form typed in UFL from the energy W and differentiated by UFL, never
taken from an implementation. With C written through its six independent components
c = (C00, C11, C22, C01, C12, C02) (a Voigt vector of C), the Hessian of the total energy is

    K(du, v) = int  g . d2c[du, v]   +   dc[v] . H dc[du]   dx
                    geometric part        material part

where g = dW/dc and H = d2W/dc2; dc[v] = (F^T grad v + grad v^T F) in Voigt order and
d2c[du, v] = grad v^T grad du + grad du^T grad v. The geometric part is the second variation
with the stress frozen; the material part is split further by the Voigt blocks of H
(normal-normal, normal-shear, shear-shear), which is where a factor 2 on shear entries shows.
The energy's J-only terms (the volumetric energy, :data:`VOLUMETRIC`) give the same two
parts for the volumetric energy; the isochoric ones are the differences.

W is a function of C only, so it is evaluated at F = U(c), the upper-triangular Cholesky
factor of C (U^T U = C, det U = J > 0): every energy of :mod:`reference_fem.energies` is
then a function of the six independent components, which UFL differentiates exactly.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, Callable, Dict, Optional

import numpy as np
import scipy.sparse as sp

__all__ = [
    "PART_NAMES",
    "StiffnessParts",
    "PartsOracle",
    "volumetric_energy",
    "register_volumetric",
]

#: Parts assembled separately, each a sparse (3n, 3n) matrix in input dof order.
PART_NAMES = (
    "geometric_volumetric",
    "geometric",
    "material_volumetric",
    "material_normal_normal",
    "material_normal_shear",
    "material_shear_shear",
)

# Voigt components of C: which pairs (i, j) are independent unknowns, normal ones first.
_VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
_NORMAL = (0, 1, 2)
_SHEAR = (3, 4, 5)

# Volumetric (J-only) energies per material type: the declared materials' and user energies'.
_VOLUMETRIC: Dict[type, Callable[[Any, Any, Callable[[str], Any]], Any]] = {}


def register_volumetric(cls: type):
    """Decorator: ``fn(material, F, p) -> UFL`` gives the J-only terms of ``cls``'s energy (None if
    none);
    ``p(name)`` is a parameter as it enters the form (a dolfinx Constant).
    """

    def deco(fn):
        _VOLUMETRIC[cls] = fn
        return fn

    return deco


def _register_builtin() -> None:
    from mjed.materials import declarations
    from reference_fem.energies import UFLNamespace

    def volumetric_of(formula):
        if formula is None:  # e.g. St Venant-Kirchhoff: every term depends on E
            return lambda m, F, p: None
        return lambda m, F, p: formula(p, UFLNamespace(F))

    for declaration in declarations():  # the J-only parts, as each material declares them
        register_volumetric(declaration.material)(volumetric_of(declaration.volumetric))

    try:
        from reference_fem.user_energy import UserEnergy
    except ImportError:  # user energies not installed: built-in materials only
        return

    @register_volumetric(UserEnergy)
    def _user(m, F, p):
        vol = volumetric_user_energy(m)
        return None if vol is None else vol.ufl_density(F, constant=p.constant)


_J_ONLY = frozenset({"J", "I3"})


def _additive_terms(node, sign: int = 1):
    """Top-level terms of a sum, with their signs: a - (b + c) -> (+a), (-b), (-c)."""
    import ast

    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
        yield from _additive_terms(node.left, sign)
        yield from _additive_terms(node.right, sign if isinstance(node.op, ast.Add) else -sign)
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        yield from _additive_terms(node.operand, -sign)
    else:
        yield sign, node


def volumetric_user_energy(energy):
    """The J-only top-level terms of a user energy as a UserEnergy of their own (None if none).

    A term is J-only when the only kinematic variables it uses are J and I3 = J^2.
    """
    import ast
    import warnings

    from reference_fem.user_energy import VARIABLES, UserEnergy

    tree = ast.parse(energy.expression, mode="eval").body
    kept, params = [], set()
    for sign, term in _additive_terms(tree):
        names = {n.id for n in ast.walk(term) if isinstance(n, ast.Name)}
        if names & set(VARIABLES) <= _J_ONLY and names & set(VARIABLES):
            kept.append(("-" if sign < 0 else "+") + "(" + ast.unparse(term) + ")")
            params |= names & set(energy.params)
    if not kept:
        return None
    with (
        warnings.catch_warnings()
    ):  # e.g. -mu ln J alone is pre-stressed at rest; that is expected here
        warnings.simplefilter("ignore")
        return UserEnergy(
            " ".join(kept),
            {k: energy.params[k] for k in sorted(params)},
            None,
            energy.name + " (J-only)",
        )


def volumetric_energy(model: Any, F, p: Callable[[str], Any]):
    """The J-only part of ``model``'s energy as UFL (None when it has none).

    Raises:
        KeyError: no volumetric split is known for this model's type.
    """
    if not _VOLUMETRIC:
        _register_builtin()
    for cls in type(model).__mro__:
        if cls in _VOLUMETRIC:
            return _VOLUMETRIC[cls](model, F, p)
    raise KeyError(f"no volumetric split known for {type(model).__name__}")


def _cholesky_factor(c):
    """Upper-triangular U with U^T U = C for the Voigt vector c of an SPD C (UFL)."""
    import ufl

    c00, c11, c22, c01, c12, c02 = (c[k] for k in range(6))
    u00 = ufl.sqrt(c00)
    u01 = c01 / u00
    u02 = c02 / u00
    u11 = ufl.sqrt(c11 - u01**2)
    u12 = (c12 - u01 * u02) / u11
    u22 = ufl.sqrt(c22 - u02**2 - u12**2)
    return ufl.as_matrix([[u00, u01, u02], [0.0, u11, u12], [0.0, 0.0, u22]])


def _voigt(T):
    import ufl

    return ufl.as_vector([T[i, j] for i, j in _VOIGT])


@dataclass(frozen=True)
class StiffnessParts:
    """The oracle's stiffness split into parts (scipy CSR, (3n, 3n), input dof order).

    geometric + material_normal_normal + material_normal_shear + material_shear_shear = K;
    the ``*_volumetric`` parts are those of the J-only energy terms (None when the energy has
    none or no split is known), the isochoric ones the differences.
    """

    parts: Dict[str, Optional[sp.csr_matrix]]

    def __getitem__(self, name: str) -> Optional[sp.csr_matrix]:
        return self.parts[name]

    def total(self) -> sp.csr_matrix:
        return (
            self.parts["geometric"]
            + self.parts["material_normal_normal"]
            + self.parts["material_normal_shear"]
            + self.parts["material_shear_shear"]
        ).tocsr()


class PartsOracle:
    """Assembles the parts of the oracle's stiffness for one mesh and one energy (serial).

    Args:
        points: (n, 3) rest positions; cells: (m, 4) positively oriented tetrahedra.
        model: a material of :mod:`mjed.materials` or a user energy (anything the energy
            function accepts).
        energy: ``(model, F, frame, constant) -> UFL`` W(F) per unit rest volume; by default
            :func:`conformance.judge.oracle.energy_density`.
    """

    def __init__(
        self,
        points: np.ndarray,
        cells: np.ndarray,
        model: Any,
        energy: Optional[Callable[..., Any]] = None,
    ):
        import ufl

        from reference_fem import compat
        from reference_fem.numbering import build_mesh, compute_numbering
        from reference_fem.sparse_map import CSRRenumbering

        if energy is None:
            from conformance.judge.energy import energy_density as energy
        X = np.ascontiguousarray(points, dtype=np.float64)
        cells = np.ascontiguousarray(cells, dtype=np.int64)
        self._X = X
        self._mesh = build_mesh(X, cells)
        V = compat.vector_p1_space(self._mesh)
        self._numbering = compute_numbering(self._mesh, V, X, cells)
        self._u = compat.function(V, "u")
        du, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        dx = ufl.Measure("dx", domain=self._mesh, metadata={"quadrature_degree": 1})
        const = functools.partial(compat.constant, self._mesh)
        frame = _cellwise_frame(model, self._mesh, self._numbering, cells.shape[0])

        F = ufl.Identity(3) + ufl.grad(self._u)
        c = ufl.variable(_voigt(F.T * F))
        U = _cholesky_factor(c)
        W = energy(model, U, frame, const)
        W_vol = volumetric_energy_or_none(model, U, const)

        Gv, Gu = ufl.grad(v), ufl.grad(du)
        dc_v = _voigt(F.T * Gv + Gv.T * F)
        dc_u = _voigt(F.T * Gu + Gu.T * F)
        d2c = _voigt(Gv.T * Gu + Gu.T * Gv)

        def geometric(w):
            return ufl.inner(ufl.diff(w, c), d2c) * dx

        def material(w, rows, cols):
            H = ufl.diff(ufl.diff(w, c), c)
            return sum(dc_v[i] * H[i, j] * dc_u[j] for i in rows for j in cols) * dx

        forms = {
            "geometric": geometric(W),
            "material_normal_normal": material(W, _NORMAL, _NORMAL),
            # Both off-diagonal blocks in one part: K's symmetry keeps them together.
            "material_normal_shear": material(W, _NORMAL, _SHEAR) + material(W, _SHEAR, _NORMAL),
            "material_shear_shear": material(W, _SHEAR, _SHEAR),
        }
        if W_vol is not None:
            forms["geometric_volumetric"] = geometric(W_vol)
            forms["material_volumetric"] = material(W_vol, range(6), range(6))
        self._forms = {k: compat.compile_form(f) for k, f in forms.items()}
        self._mats = {k: compat.create_matrix(f) for k, f in self._forms.items()}
        n_owned = self._numbering.n_owned_dof_nodes
        self._renumber = CSRRenumbering(
            self._numbering.input_dof_of_dof[: 3 * n_owned], 3 * X.shape[0]
        )

    def parts(self, x: np.ndarray) -> StiffnessParts:
        """Every part at current positions ``x`` (n, 3)."""
        from reference_fem import compat

        self._u.x.array[:] = self._numbering.to_dof_order(np.asarray(x, dtype=np.float64) - self._X)
        compat.scatter_forward(self._u)
        out: Dict[str, Optional[sp.csr_matrix]] = {k: None for k in PART_NAMES}
        for name, form in self._forms.items():
            A = self._mats[name]
            compat.assemble_matrix_into(A, form)
            out[name] = self._renumber(*A.getValuesCSR())
        return StiffnessParts(out)


class _Constants:
    """p(name): the model's parameter as a dolfinx Constant; p.value(name): as a float (what a
    declared formula may read for a check); p.constant: the factory itself.
    """

    def __init__(self, model: Any, constant: Callable[[Any], Any]):
        self.model, self.constant = model, constant

    def value(self, name: str) -> float:
        return float(getattr(self.model, name))

    def __call__(self, name: str):
        return self.constant(self.value(name))


def volumetric_energy_or_none(model: Any, F, constant: Callable[[Any], Any]):
    """:func:`volumetric_energy` with parameters as constants; None if no split is known."""
    try:
        return volumetric_energy(model, F, _Constants(model, constant))
    except KeyError:
        return None


def _cellwise_frame(model: Any, mesh, numbering, m: int):
    """A per-cell Costa frame as a DG0 tensor Function (None for a constant or no frame)."""
    frame = getattr(model, "frame", None)
    if frame is None or np.asarray(frame).shape == (3, 3):
        return None
    from reference_fem import compat

    R = np.asarray(frame, dtype=np.float64).reshape(m, 3, 3)
    Q = compat.tensor_dg0_space(mesh)
    Rf = compat.function(Q, "frame")
    m_rank = numbering.input_cell_of_cell.size
    block = compat.cell_dofs(Q, 1)[:m_rank, 0]
    Rf.x.array.reshape(-1, 9)[block] = R[numbering.input_cell_of_cell].reshape(-1, 9)
    compat.scatter_forward(Rf)
    return Rf
