"""FElupe (PyPI ``felupe``, read and checked at version 11.3.0) in this project's conventions.

What FElupe computes, from its source (``felupe/constitution/hyperelasticity``):

* ``NeoHookeCompressible(mu, lmbda)``: W = mu (tr C / 2 - ln J) + lmbda/2 (ln J)^2. This is
  the project's ``NeoHookean`` (mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2) plus the constant
  3 mu / 2: the same forces and stiffness, a total energy larger by 3 mu / 2 times the mesh
  volume. With ``lmbda=None`` the ln J term is absent.
* ``NeoHooke(mu, bulk)``: W = mu/2 (I1b - 3) + bulk/2 (J - 1)^2 (isochoric Neo-Hookean with
  a (J - 1)^2 penalty; no built-in material of this project has it, so it is checked as a
  :class:`~reference_fem.user_energy.UserEnergy`). ``Volumetric(bulk)`` is NeoHooke without mu.
* ``LinearElasticLargeStrain(E, nu)`` is NeoHookeCompressible with the Lamé constants of
  (E, nu); pass it as a FElupe object.

FElupe's stresses and tangents for these are hand-written closed forms (not automatic
differentiation); the check compares them with UFL's derivative of the stated energy.

With the optional ``tensortrax`` package (scripts/bootstrap.sh installs 0.29.0), FElupe's
automatic-differentiation route ``Hyperelastic(fun)`` (fun a strain energy of C; stress and
tangent by tensortrax, with C treated as symmetric) covers more models:

* ``StVenantKirchhoff`` -> FElupe's ``saint_venant_kirchhoff(C, mu, lmbda=lam)``, the same W;
* ``MooneyRivlin``, ``ArrudaBoyce``, ``Ogden`` -> FElupe's isochoric ``mooney_rivlin(C10=c1,
  C01=c2)``, ``arruda_boyce(C1=mu, limit=sqrt(N))``, ``ogden(mu=[mu/2], alpha=[alpha])``
  (its 2 mu_i / alpha_i^2 convention), plus the project's k0/2 (ln J)^2 written here in
  tensortrax (FElupe has no ln J volumetric model): the same W as the built-in;
* any other :class:`~reference_fem.user_energy.UserEnergy`: the expression itself, translated
  to tensortrax operations on C (I1 = tr C, J = sqrt(det C), ...), so FElupe's automatic
  differentiation is checked on the user's own energy.

What the check finds is in tests/test_adapters_felupe.py: everything to round-off except the
energy constant of NeoHookeCompressible and the Ogden route, whose eigenvalues tensortrax
computes from C perturbed by about 1.5e-8 relative (errors of 1e-10 to 2e-9).

The discretisation: ``RegionTetra`` (P1 tetrahedra, VTK node order, the same as this
project's positively oriented cells) with ``TetrahedronQuadrature(order=1)`` (exact for P1),
one displacement ``Field`` of dimension 3 in a ``FieldContainer``, a ``SolidBody``.
FElupe's assembled vector is the internal force dW/du and its matrix the tangent
d2W/du2, both with dof index 3*node + component: f = -vector, K = matrix.
"""

from __future__ import annotations

import functools
import re
from typing import Any, Dict, Tuple

import numpy as np

from conformance.adapters import MeshAdapter, Unsupported
from mjed.materials import ArrudaBoyce, MooneyRivlin, NeoHookean, Ogden, StVenantKirchhoff
from reference_fem.user_energy import UserEnergy

__all__ = [
    "FElupeAdapter",
    "available",
    "autodiff_available",
    "supports",
    "library_energy",
    "FELUPE_ENERGIES",
    "CHECKED_VERSION",
    "CHECKED_TENSORTRAX",
]

#: The FElupe release whose source these energies were read from (scripts/bootstrap.sh pins it).
CHECKED_VERSION = "11.3.0"
#: The tensortrax release used for FElupe's automatic-differentiation route.
CHECKED_TENSORTRAX = "0.29.0"

#: FElupe model -> its energy as this project's expression syntax, parameter names as FElupe's.
FELUPE_ENERGIES: Dict[str, Dict[Tuple[str, ...], str]] = {
    "NeoHookeCompressible": {
        ("lmbda", "mu"): "mu*(I1/2 - ln(J)) + lmbda/2*ln(J)**2",
        ("mu",): "mu*(I1/2 - ln(J))",
    },
    "NeoHooke": {
        ("bulk", "mu"): "mu/2*(I1b - 3) + bulk/2*(J - 1)**2",
        ("mu",): "mu/2*(I1b - 3)",
        ("bulk",): "bulk/2*(J - 1)**2",
    },
}


def available() -> Tuple[bool, str]:
    """(True, version) if FElupe imports, else (False, why)."""
    try:
        import felupe
    except Exception as e:  # ImportError, or a broken dependency
        return (
            False,
            f"FElupe is not installed ({e}); scripts/bootstrap.sh installs "
            f"felupe=={CHECKED_VERSION}",
        )
    return True, felupe.__version__


def _felupe():
    ok, why = available()
    if not ok:
        raise Unsupported(why)
    import felupe

    return felupe


def autodiff_available() -> Tuple[bool, str]:
    """(True, version) if FElupe's Hyperelastic (tensortrax) can be used, else (False, why)."""
    ok, why = available()
    if not ok:
        return ok, why
    try:
        import tensortrax
    except Exception as e:
        return False, (
            f"tensortrax is not installed ({e}); scripts/bootstrap.sh installs "
            f"tensortrax=={CHECKED_TENSORTRAX} for FElupe's automatic differentiation"
        )
    return True, tensortrax.__version__


def _tensortrax():
    ok, why = autodiff_available()
    if not ok:
        raise Unsupported(why)
    import tensortrax.math as tm

    return tm


def _ln_j_bulk(k0: float):
    """The project's volumetric term k0/2 (ln J)^2 as a function of C (ln J = ln(det C) / 2)."""
    tm = _tensortrax()
    return lambda C: 0.5 * k0 * (0.5 * tm.log(tm.linalg.det(C))) ** 2


def _hyperelastic(fun, why: str, model) -> Tuple[Any, Any, str]:
    fe = _felupe()
    return fe.Hyperelastic(fun), model, why


def _tensortrax_variable(C, a, tm):
    """Variable name -> its tensortrax value for C (3, 3, ...) (see user_energy.VARIABLES)."""

    def variable(name: str):
        if name[0] in "CE" and len(name) == 3:
            i, j = int(name[1]) - 1, int(name[2]) - 1
            return C[i, j] if name[0] == "C" else 0.5 * (C[i, j] - (1.0 if i == j else 0.0))
        I3 = tm.linalg.det(C)
        I1 = tm.trace(C)
        if name == "I1":
            return I1
        if name == "I3":
            return I3
        if name == "J":
            return tm.sqrt(I3)
        if name == "I1b":
            return I3 ** (-1.0 / 3.0) * I1
        if name in ("I2", "I2b"):
            I2 = 0.5 * (I1**2 - tm.trace(C @ C))
            return I2 if name == "I2" else I3 ** (-2.0 / 3.0) * I2
        Ca = tm.einsum("ij...,j->i...", C, a)
        if name == "I4":
            return tm.einsum("i,i...->...", a, Ca)
        if name == "I5":
            return tm.einsum("i...,i...->...", Ca, Ca)
        raise AssertionError(name)

    return variable


def _user_energy_function(energy: UserEnergy):
    """W(C) of a user energy in tensortrax operations, for FElupe's Hyperelastic."""
    tm = _tensortrax()
    a = energy.directions()  # one direction: a frame per cell is refused by _match

    def fun(C):
        return energy.evaluate(_tensortrax_variable(C, a, tm), tm.log, tm.exp, tm.sqrt)

    return fun


def _squash(expression: str) -> str:
    return re.sub(r"\s+", "", expression)


# -- the FElupe object and the exact energy for each kind of model ------------------------------


def _felupe_params(umat) -> Dict[str, float]:
    """The parameters a FElupe NeoHooke-family object was built with (None ones left out)."""
    names = ("mu", "lmbda") if _class_name(umat) == "NeoHookeCompressible" else ("mu", "bulk")
    return {n: float(getattr(umat, n)) for n in names if getattr(umat, n, None) is not None}


def _class_name(umat) -> str:
    fe = _felupe()
    for cls in (fe.NeoHookeCompressible, fe.NeoHooke):  # Volumetric derives from NeoHooke
        if isinstance(umat, cls):
            return cls.__name__
    raise Unsupported(
        f"FElupe material {type(umat).__name__} is not one this adapter can state the energy of"
    )


def _from_felupe_object(umat) -> Tuple[Any, UserEnergy, str]:
    fe = _felupe()
    if isinstance(umat, fe.LinearElasticLargeStrain):
        inner = umat.material  # a NeoHookeCompressible with the Lamé constants of (E, nu)
        umat_used, why = (
            inner,
            "LinearElasticLargeStrain is FElupe's NeoHookeCompressible with Lamé constants from "
            "(E, nu)",
        )
    else:
        umat_used, why = umat, f"FElupe's {type(umat).__name__}"
    kind = _class_name(umat_used)
    params = _felupe_params(umat_used)
    expression = FELUPE_ENERGIES[kind][tuple(sorted(params))]
    energy = UserEnergy(expression, params, name=f"FElupe {kind}")
    return umat, energy, f"{why}: W = {expression}"


@functools.singledispatch
def _match(model) -> Tuple[Any, UserEnergy, str]:
    """(FElupe material object, the energy it computes, why they match) for ``model``."""
    fe = _felupe()
    if isinstance(model, fe.constitution.ConstitutiveMaterial):
        return _from_felupe_object(model)
    raise Unsupported(f"FElupe: no FElupe material matches {type(model).__name__}")


@_match.register(UserEnergy)
def _(model):
    if model.direction_missing or (model.frame is not None and model.frame.ndim == 3):
        raise Unsupported(
            "FElupe: this adapter gives tensortrax one fibre direction for I4 and I5,"
            " not one per cell; give the energy one fibre (--fibre X,Y,Z) to check "
            "FElupe with it"
        )
    fe = _felupe()
    names = tuple(sorted(model.params))
    text = _squash(model.expression)
    for kind, variants in FELUPE_ENERGIES.items():
        if variants.get(names) is not None and _squash(variants[names]) == text:
            p = dict(model.params)
            umat = (
                fe.NeoHookeCompressible(**p) if kind == "NeoHookeCompressible" else fe.NeoHooke(**p)
            )
            return umat, model, f"FElupe's {kind}: W = {variants[names]} (the same expression)"
    listed = "; ".join(
        f"{e} (parameters {', '.join(k)})" for v in FELUPE_ENERGIES.values() for k, e in v.items()
    )
    ok, why = autodiff_available()
    if not ok:
        raise Unsupported(
            f"FElupe: the energy {model.expression!r} is not one of FElupe's closed forms "
            f"({listed}), and the automatic-differentiation route is unavailable: {why}"
        )
    return _hyperelastic(
        _user_energy_function(model),
        "FElupe's Hyperelastic (tensortrax automatic differentiation) of the expression "
        f"{model.expression}",
        model,
    )


@_match.register(NeoHookean)
def _(model):
    fe = _felupe()
    umat = fe.NeoHookeCompressible(mu=model.mu, lmbda=model.lam)
    energy = UserEnergy(
        FELUPE_ENERGIES["NeoHookeCompressible"][("lmbda", "mu")],
        {"mu": model.mu, "lmbda": model.lam},
        name="FElupe NeoHookeCompressible",
    )
    return (
        umat,
        energy,
        (
            "FElupe's NeoHookeCompressible(mu, lmbda=lam): the same W up to the constant 3 mu/2 "
            "(FElupe: mu (I1/2 - ln J) + lmbda/2 (ln J)^2), so equal forces and stiffness; "
            "FElupe's total energy is larger by 3 mu/2 times the mesh volume"
        ),
    )


@_match.register(StVenantKirchhoff)
def _(model):
    from felupe.constitution.tensortrax.models.hyperelastic import saint_venant_kirchhoff

    _tensortrax()
    return _hyperelastic(
        lambda C: saint_venant_kirchhoff(C, mu=model.mu, lmbda=model.lam),
        "FElupe's Hyperelastic(saint_venant_kirchhoff, mu, lmbda=lam): the same W",
        model,
    )


@_match.register(MooneyRivlin)
def _(model):
    from felupe.constitution.tensortrax.models.hyperelastic import mooney_rivlin

    bulk = _ln_j_bulk(model.k0)
    return _hyperelastic(
        lambda C: mooney_rivlin(C, C10=model.c1, C01=model.c2) + bulk(C),
        "FElupe's Hyperelastic(mooney_rivlin, C10=c1, C01=c2) + k0/2 (ln J)^2 in tensortrax: the "
        "same W",
        model,
    )


@_match.register(ArrudaBoyce)
def _(model):
    from felupe.constitution.tensortrax.models.hyperelastic import arruda_boyce

    bulk = _ln_j_bulk(model.k0)
    limit = float(np.sqrt(model.N))  # FElupe's beta = 1 / limit^2 is the project's 1 / N
    return _hyperelastic(
        lambda C: arruda_boyce(C, C1=model.mu, limit=limit) + bulk(C),
        "FElupe's Hyperelastic(arruda_boyce, C1=mu, limit=sqrt(N)) + k0/2 (ln J)^2 in tensortrax: "
        "the same W",
        model,
    )


@_match.register(Ogden)
def _(model):
    from felupe.constitution.tensortrax.models.hyperelastic import ogden

    bulk = _ln_j_bulk(model.k0)
    return _hyperelastic(
        lambda C: ogden(C, mu=[0.5 * model.mu], alpha=[model.alpha]) + bulk(C),
        "FElupe's Hyperelastic(ogden, mu=[mu/2], alpha=[alpha]) (2 mu_i/alpha_i^2 convention) + "
        "k0/2 (ln J)^2 in tensortrax: the same W",
        model,
    )


def supports(model) -> Tuple[bool, str]:
    """(True, how FElupe's energy relates to ``model``) or (False, why not)."""
    try:
        return True, _match(model)[2]
    except Unsupported as e:
        return False, str(e)


def library_energy(model):
    """The energy FElupe computes for ``model``, as a model the UFL oracle accepts: a
    UserEnergy, or the built-in material itself when FElupe's W equals it (raises Unsupported).
    """
    return _match(model)[1]


class FElupeAdapter(MeshAdapter):
    """FElupe's force, tangent and energy for ``model`` on the P1 mesh (points, cells).

    Args:
        points: (n, 3) rest positions. cells: (m, 4) positively oriented tetrahedra.
        model: the project's NeoHookean, a UserEnergy equal to one of
            :data:`FELUPE_ENERGIES`, or a FElupe NeoHookeCompressible / NeoHooke /
            Volumetric / LinearElasticLargeStrain object.

    Raises:
        Unsupported: FElupe is missing or has no matching energy (the message says which).
    """

    library = "FElupe"

    def __init__(self, points, cells, model):
        super().__init__(points, cells)
        fe = _felupe()
        self.model = model
        self.library_material, self.library_energy, self.match_reason = _match(model)
        mesh = fe.Mesh(self.points.copy(), self.cells.copy(), "tetra")
        self._region = fe.RegionTetra(mesh, quadrature=fe.TetrahedronQuadrature(order=1))
        self._field = fe.FieldContainer([fe.Field(self._region, dim=3)])
        self._solid = fe.SolidBody(self.library_material, self._field)
        self.version = fe.__version__

    def _density(self, F: np.ndarray) -> np.ndarray:
        """W at each quadrature point of each cell, (q, m), as FElupe evaluates it."""
        umat = self.library_material
        hyperelastic = getattr(_felupe(), "Hyperelastic", None)  # only with tensortrax
        if hyperelastic is not None and isinstance(umat, hyperelastic):
            import tensortrax as tr

            C = np.einsum("ki...,kj...->ij...", F, F)
            return tr.function(umat.fun, wrt=0, ntrax=2)(C)
        return umat.function([F, None])[0]

    def _set(self, u: np.ndarray) -> None:
        self._field[0].values[:] = u

    def _evaluate(self, u, want_force, want_stiffness):
        self._set(u)
        f = K = None
        if want_force:
            r = self._solid.assemble.vector(self._field)  # dW/du, sparse (3n, 1)
            f = -np.asarray(r.toarray()).ravel()
        if want_stiffness:
            K = self._solid.assemble.matrix(self._field)  # d2W/du2, sparse (3n, 3n)
        return f, K

    def energy(self, x) -> float:
        """FElupe's total energy sum over quadrature points of W(F) dV (its own ``function``)."""
        self._set(self._displacement(x))
        F = self._field.extract()[0]  # (3, 3, quadrature points, cells)
        W = self._density(F)
        value = float(np.sum(W * self._region.dV))
        self._require_finite(np.array([value]), "energy")
        return value
