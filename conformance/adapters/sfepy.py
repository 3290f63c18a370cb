"""SfePy (Debian ``python3-sfepy``, read and checked at 2021.4) in this project's conventions.

SfePy's total Lagrangian hyperelastic terms each contribute int S : dE(v) over the rest
domain, S = 2 dW/dC the second Piola-Kirchhoff stress that the term's docstring states. The
energies those stresses derive from (``sfepy/terms/terms_hyperelastic_tl.py``):

==========================  =================  =========================================
term                        parameters         W (this project's expression syntax)
==========================  =================  =========================================
``dw_tl_he_neohook``        mu                 ``mu/2*(I1b-3)``
``dw_tl_he_mooney_rivlin``  kappa              ``kappa/2*(I2b-3)``
``dw_tl_bulk_penalty``      K                  ``K/2*(J-1)**2``
``dw_tl_he_genyeoh``        K, p               ``K*(I1b-3)**p``
``dw_tl_he_ogden``          mu, alpha          mu/alpha (sum_k lambda_k^alpha - 3), as documented
==========================  =================  =========================================

A model for this adapter is a :class:`SfePyTerms` (term name -> parameters; its
``energy()`` is the sum above, except Ogden, which is not an expression of invariants), or
a UserEnergy equal to such a sum written as ``SfePyTerms.energy()`` writes it. No built-in
material of this project matches: SfePy's only displacement-based bulk terms are
K/2 (J - 1)^2 (and an active pressure), not the (ln J)^2 of MooneyRivlin or NeoHookean.

The discretisation: a ``'3_4'`` mesh (P1 tetrahedra) from our points and cells, one vector
field of order 1, ``Integral(order=1)`` (exact for P1), the terms in one equation, no
boundary conditions. ``Evaluator.eval_residual`` gives dW/du and
``eval_tangent_matrix`` d2W/du2 in SfePy's field numbering, node-major (3*node +
component); the adapter maps field nodes to our nodes by SfePy's ``vertex_remap``.
SfePy computes no total energy for these terms, so the adapter has no ``energy``.

What the check finds is in tests/test_adapters_sfepy.py: the invariant terms to round-off;
``dw_tl_he_ogden``'s stress is J^((alpha-2)/3) times that of its documented energy, and its
tangent is not the derivative of its stress when J != 1.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from typing import Dict, Mapping, Tuple

import numpy as np
import scipy.sparse as sp

from conformance.adapters import MeshAdapter, Unsupported
from reference_fem.user_energy import UserEnergy

__all__ = ["SfePyAdapter", "SfePyTerms", "available", "supports", "SFEPY_TERMS", "CHECKED_VERSION"]

CHECKED_VERSION = "2021.4"


@dataclass(frozen=True)
class _TermSpec:
    params: Tuple[str, ...]  # parameter names, in the order of SfePy's material array
    energy: str  # W in the project's expression syntax; "" if not an invariant expression


#: term name -> what it computes (see the module docstring).
SFEPY_TERMS: Dict[str, _TermSpec] = {
    "dw_tl_he_neohook": _TermSpec(("mu",), "mu/2*(I1b-3)"),
    "dw_tl_he_mooney_rivlin": _TermSpec(("kappa",), "kappa/2*(I2b-3)"),
    "dw_tl_bulk_penalty": _TermSpec(("K",), "K/2*(J-1)**2"),
    "dw_tl_he_genyeoh": _TermSpec(("K", "p"), "K*(I1b-3)**p"),
    "dw_tl_he_ogden": _TermSpec(("mu", "alpha"), ""),
}


def available() -> Tuple[bool, str]:
    """(True, version) if SfePy imports, else (False, why)."""
    try:
        import sfepy
    except Exception as e:
        return False, f"SfePy is not installed ({e}); Debian: apt-get install python3-sfepy"
    return True, sfepy.__version__


@dataclass(frozen=True)
class SfePyTerms:
    """A sum of SfePy total Lagrangian terms: ``{"dw_tl_he_neohook": {"mu": 1e3}, ...}``
    (each term at most once; parameters as in :data:`SFEPY_TERMS`).
    """

    terms: Mapping[str, Mapping[str, float]]

    def __post_init__(self):
        if not self.terms:
            raise ValueError("SfePyTerms: no term given")
        checked = {}
        for name, params in self.terms.items():
            spec = SFEPY_TERMS.get(name)
            if spec is None:
                raise ValueError(
                    f"SfePyTerms: unknown term {name!r}; known: {', '.join(SFEPY_TERMS)}"
                )
            if set(params) != set(spec.params):
                raise ValueError(
                    f"SfePyTerms: {name} takes parameters {', '.join(spec.params)}, got "
                    f"{', '.join(params) or 'none'}"
                )
            values = {k: float(params[k]) for k in spec.params}
            if not all(np.isfinite(list(values.values()))):
                raise ValueError(f"SfePyTerms: {name} parameters must be finite, got {values}")
            checked[name] = values
        object.__setattr__(self, "terms", checked)

    def __hash__(self):
        return hash(tuple((n, tuple(p.items())) for n, p in self.terms.items()))

    def _names(self, term: str) -> Dict[str, str]:
        """Parameter name of each of the term's parameters in the summed expression (the
        term's own name, suffixed with the term's position when two terms share a name).
        """
        seen = [p for t in self.terms for p in SFEPY_TERMS[t].params]
        index = list(self.terms).index(term)
        return {p: p if seen.count(p) == 1 else f"{p}_{index}" for p in SFEPY_TERMS[term].params}

    def energy(self) -> UserEnergy:
        """The total W as a UserEnergy (raises Unsupported for Ogden, which is a function of
        the principal stretches, not of the invariants the expression syntax offers).
        """
        parts, params = [], {}
        for term, values in self.terms.items():
            spec = SFEPY_TERMS[term]
            if not spec.energy:
                raise Unsupported(
                    f"SfePy: {term} is not an expression of invariants; check it with a built-in "
                    "material"
                )
            names = self._names(term)
            text = spec.energy
            for p, q in names.items():  # whole-word renaming of the parameters
                text = _rename(text, p, q)
            parts.append(text)
            params.update({names[p]: v for p, v in values.items()})
        return UserEnergy(" + ".join(parts), params, name="SfePy " + " + ".join(self.terms))


def _rename(text: str, old: str, new: str) -> str:
    return re.sub(rf"\b{re.escape(old)}\b", new, text)


def _match(model) -> Tuple[SfePyTerms, str]:
    if isinstance(model, SfePyTerms):
        return model, "SfePy terms " + " + ".join(model.terms)
    if isinstance(model, UserEnergy):
        squashed = "".join(model.expression.split())
        # Any ordered choice of the invariant terms, named as SfePyTerms.energy() names them.
        invariant = [t for t, s in SFEPY_TERMS.items() if s.energy]
        for k in range(1, len(invariant) + 1):
            for combo in itertools.permutations(invariant, k):
                template = SfePyTerms({t: {p: 1.0 for p in SFEPY_TERMS[t].params} for t in combo})
                probe = template.energy()
                if "".join(probe.expression.split()) == squashed and set(probe.params) == set(
                    model.params
                ):
                    terms = {
                        t: {p: model.params[n] for p, n in template._names(t).items()}
                        for t in combo
                    }
                    return SfePyTerms(terms), "SfePy terms " + " + ".join(
                        combo
                    ) + f": W = {probe.expression}"
        raise Unsupported(
            f"SfePy: the energy {model.expression!r} is not a sum of SfePy's terms written as "
            "SfePyTerms.energy() writes it: "
            + "; ".join(f"{t}: {s.energy}" for t, s in SFEPY_TERMS.items() if s.energy)
        )
    raise Unsupported(
        f"SfePy: no SfePy term sum matches {type(model).__name__} (SfePy's bulk terms are K/2 "
        "(J-1)^2, not the (ln J)^2 of this project's materials); pass SfePyTerms or a UserEnergy"
    )


def supports(model) -> Tuple[bool, str]:
    """(True, which SfePy terms) or (False, why not)."""
    try:
        return True, _match(model)[1]
    except Unsupported as e:
        return False, str(e)


class SfePyAdapter(MeshAdapter):
    """SfePy's residual and tangent for ``model`` (SfePyTerms or a matching UserEnergy) on
    the P1 mesh (points, cells); see the module docstring.

    Raises:
        Unsupported: SfePy is missing or no sum of its terms matches the model.
    """

    library = "SfePy"

    def __init__(self, points, cells, model):
        super().__init__(points, cells)
        ok, why = available()
        if not ok:
            raise Unsupported(why)
        from sfepy.base.base import output
        from sfepy.discrete import Equation, Equations, FieldVariable, Integral, Material, Problem
        from sfepy.discrete.fem import FEDomain, Field, Mesh
        from sfepy.terms import Term

        output.set_output(quiet=True)  # SfePy prints progress on every step otherwise
        self.model = model
        self.terms, self.match_reason = _match(model)
        n, m = self.points.shape[0], self.cells.shape[0]
        mesh = Mesh.from_data(
            "mesh",
            self.points.copy(),
            None,
            [self.cells.astype(np.int32)],
            [np.zeros(m, dtype=np.int32)],
            ["3_4"],
        )
        omega = FEDomain("domain", mesh).create_region("Omega", "all")
        field = Field.from_args("displacement", np.float64, "vector", omega, approx_order=1)
        # Field node of each of our nodes (P1: one per vertex), checked on the coordinates.
        self._node = np.asarray(field.vertex_remap[np.arange(n)], dtype=np.int64)
        if not np.array_equal(field.get_coor()[self._node], self.points):
            raise RuntimeError("SfePy: the field's nodes do not coincide with the mesh vertices")
        dofs = (3 * self._node[:, None] + np.arange(3)).ravel()  # field dof of our dof 3*node+c
        self._perm = sp.csr_matrix((np.ones(3 * n), (np.arange(3 * n), dofs)), shape=(3 * n, 3 * n))

        u = FieldVariable("u", "unknown", field)
        v = FieldVariable("v", "test", field, primary_var_name="u")
        values = {
            f"c{i}": np.array([[self.terms.terms[t][p] for p in SFEPY_TERMS[t].params]])
            for i, t in enumerate(self.terms.terms)
        }
        mat = Material("m", **values)
        integral = Integral("i", order=1)
        terms = [
            Term.new(f"{t}(m.c{i}, v, u)", integral, omega, m=mat, v=v, u=u)
            for i, t in enumerate(self.terms.terms)
        ]
        self._problem = Problem(
            "mjed",
            equations=Equations([Equation("balance", sum(terms[1:], terms[0]))]),
            active_only=False,
        )
        self._problem.time_update()
        self._problem.update_materials()
        self._evaluator = self._problem.get_evaluator()
        import sfepy

        self.version = sfepy.__version__
        self.library_energy = None if "dw_tl_he_ogden" in self.terms.terms else self.terms.energy()

    def _evaluate(self, u, want_force, want_stiffness):
        vec = np.zeros(u.size)
        vec[3 * self._node[:, None] + np.arange(3)] = u  # our node -> its field node
        f = K = None
        if want_force:
            r = self._evaluator.eval_residual(vec.copy())  # dW/du in field dof order
            f = -(self._perm @ r)
        if want_stiffness:
            Kf = self._evaluator.eval_tangent_matrix(vec.copy(), self._problem.mtx_a)
            K = (self._perm @ Kf @ self._perm.T).tocsr()
        return f, K
