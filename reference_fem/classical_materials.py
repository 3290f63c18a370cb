"""Constitutive laws of the classical ("standard FEM") formulation, written from W directly.

Each law maps the right Cauchy-Green tensor C (with J = det F) of a batch of cells to::

    W(C)                        strain energy per unit rest volume,
    S  = 2 dW/dC                second Piola-Kirchhoff stress, (m, 3, 3),
    CC = 2 dS/dC = 4 d2W/dCdC   the material elasticity tensor, stored as a (m, 6, 6) Voigt
                                matrix CC[I, J] = CC_ijkl, I = (i, j), J = (k, l).

This is the textbook route (Holzapfel, "Nonlinear Solid Mechanics", ch. 6; Bonet & Wood):
invariants I1, I2, J and C^-1, the decoupled volumetric/isochoric split with the projection
tensor P = II - 1/3 C^-1 (x) C for the isochoric laws, a spectral (eigenvalue) form for Ogden,
and the Green-Lagrange strain in the fibre frame for Costa. It shares no code with the MJED
term engine (mjed.terms, mjed.engine, mjed.fibre, mjed.spectral): it is the independent
opponent MJED is compared against. From mjed it takes only each material's declared form of
law (:mod:`mjed.materials.classical_forms`: which of these laws, with which parameters, and
for the decoupled law the derivatives of its isochoric Psi), see :func:`classical_law`.

Voigt order: I = 0..5 <-> (xx, yy, zz, xy, yz, xz). A symmetric tensor A is stored as the
6-vector A[VI, VJ]. Fourth-order tensors with minor symmetries are stored as 6x6 matrices
without any factor, so the double contraction T : A of a 4th-order T with a symmetric A is
T_v @ (WEIGHT * A_v) and T : U (two 4th-order tensors) is T_v @ diag(WEIGHT) @ U_v. With the
engineering strain vector dE_eng = WEIGHT * dE_v this gives dS_v = CC_v @ dE_eng.
"""

from __future__ import annotations

import functools

import numpy as np

from mjed.materials import classical_forms as forms
from mjed.materials.declaration import declaration_of

__all__ = [
    "VI",
    "VJ",
    "WEIGHT",
    "voigt",
    "from_voigt",
    "classical_law",
    "law_of_form",
    "ClassicalLaw",
]

VI = np.array([0, 1, 2, 0, 1, 0])
VJ = np.array([0, 1, 2, 1, 2, 2])
WEIGHT = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
_II = np.diag([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])  # symmetric 4th-order identity, Voigt
_I_V = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])  # second-order identity, Voigt
_IXI = np.outer(_I_V, _I_V)
_FULL = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2]])  # Voigt index of entry (i, j)


# ----------------------------------------------------------------------------- tensor algebra
def voigt(A: np.ndarray) -> np.ndarray:
    """(..., 3, 3) symmetric -> (..., 6)."""
    return A[..., VI, VJ]


def from_voigt(a: np.ndarray) -> np.ndarray:
    """(..., 6) -> (..., 3, 3) symmetric."""
    return a[..., _FULL]


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A (x) b of two Voigt vectors, (..., 6, 6)."""
    return a[..., :, None] * b[..., None, :]


def _sym_outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A (x) b + b (x) a."""
    o = _outer(a, b)
    return o + np.swapaxes(o, -1, -2)


def _odot(A: np.ndarray) -> np.ndarray:
    """(A (.) A)_ijkl = (A_ik A_jl + A_il A_jk) / 2 for symmetric A (..., 3, 3), Voigt (..., 6, 6).

    With A = C^-1 this is -d(C^-1)/dC.
    """
    i, j, k, l = VI[:, None], VJ[:, None], VI[None, :], VJ[None, :]
    return 0.5 * (A[..., i, k] * A[..., j, l] + A[..., i, l] * A[..., j, k])


def _ddot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A : B of two symmetric tensors given as Voigt vectors, (...)."""
    return np.einsum("...i,...i->...", a * WEIGHT, b)


def _inverse_sym(C: np.ndarray, det: np.ndarray) -> np.ndarray:
    """Inverse of symmetric (m, 3, 3) matrices by the adjugate, given their determinants."""
    c = C
    adj = np.empty_like(C)
    adj[:, 0, 0] = c[:, 1, 1] * c[:, 2, 2] - c[:, 1, 2] * c[:, 2, 1]
    adj[:, 1, 1] = c[:, 0, 0] * c[:, 2, 2] - c[:, 0, 2] * c[:, 2, 0]
    adj[:, 2, 2] = c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] * c[:, 1, 0]
    adj[:, 0, 1] = adj[:, 1, 0] = c[:, 0, 2] * c[:, 2, 1] - c[:, 0, 1] * c[:, 2, 2]
    adj[:, 1, 2] = adj[:, 2, 1] = c[:, 0, 2] * c[:, 1, 0] - c[:, 0, 0] * c[:, 1, 2]
    adj[:, 0, 2] = adj[:, 2, 0] = c[:, 0, 1] * c[:, 1, 2] - c[:, 0, 2] * c[:, 1, 1]
    return adj / det[:, None, None]


def _jacobian(C: np.ndarray, J) -> np.ndarray:
    if J is None:
        return np.sqrt(np.linalg.det(C))
    return np.asarray(J, dtype=float)


# ----------------------------------------------------------------------------- the laws
class ClassicalLaw:
    """A hyperelastic law on a batch of cells. C: (m, 3, 3); J: (m,) or None for sqrt(det C)."""

    def energy(self, C, J=None) -> np.ndarray:
        raise NotImplementedError

    def stress(self, C, J=None) -> np.ndarray:
        """S, (m, 3, 3)."""
        return self._evaluate(np.asarray(C, float), _jacobian(C, J), tangent=False)[0]

    def stress_and_tangent(self, C, J=None):
        """S (m, 3, 3) and CC (m, 6, 6)."""
        return self._evaluate(np.asarray(C, float), _jacobian(C, J), tangent=True)

    def _evaluate(self, C, J, tangent):
        raise NotImplementedError


class StVenantKirchhoffLaw(ClassicalLaw):
    """S = lam tr(E) I + 2 mu E; CC = lam I (x) I + 2 mu II (constant)."""

    def __init__(self, mu, lam):
        self.mu, self.lam = float(mu), float(lam)
        self._CC = self.lam * _IXI + 2.0 * self.mu * _II

    def energy(self, C, J=None):
        E = 0.5 * (np.asarray(C, float) - np.eye(3))
        trE = np.trace(E, axis1=-2, axis2=-1)
        return 0.5 * self.lam * trE**2 + self.mu * np.einsum("...ij,...ij->...", E, E)

    def _evaluate(self, C, J, tangent):
        E = 0.5 * (C - np.eye(3))
        trE = np.trace(E, axis1=-2, axis2=-1)
        S = 2.0 * self.mu * E
        S[:, [0, 1, 2], [0, 1, 2]] += self.lam * trE[:, None]
        if not tangent:
            return S, None
        return S, np.broadcast_to(self._CC, (len(C), 6, 6))


class NeoHookeanLaw(ClassicalLaw):
    """Compressible neo-Hookean (Bonet & Wood 6.4.3):
    S = mu (I - C^-1) + lam ln J C^-1, CC = lam C^-1 (x) C^-1 + 2 (mu - lam ln J) C^-1 (.) C^-1.
    """

    def __init__(self, mu, lam):
        self.mu, self.lam = float(mu), float(lam)

    def energy(self, C, J=None):
        C = np.asarray(C, float)
        lnJ = np.log(_jacobian(C, J))
        I1 = np.trace(C, axis1=-2, axis2=-1)
        return 0.5 * self.mu * (I1 - 3.0) - self.mu * lnJ + 0.5 * self.lam * lnJ**2

    def _evaluate(self, C, J, tangent):
        Ci = _inverse_sym(C, J * J)
        lnJ = np.log(J)
        S = (self.lam * lnJ - self.mu)[:, None, None] * Ci
        S[:, [0, 1, 2], [0, 1, 2]] += self.mu
        if not tangent:
            return S, None
        ci = voigt(Ci)
        CC = self.lam * _outer(ci, ci) + (2.0 * (self.mu - self.lam * lnJ))[:, None, None] * _odot(
            Ci
        )
        return S, CC


def _log_volumetric(k0, J):
    """U = k0/2 (ln J)^2: U, U', U''."""
    lnJ = np.log(J)
    return 0.5 * k0 * lnJ**2, k0 * lnJ / J, k0 * (1.0 - lnJ) / (J * J)


def _volumetric(J, Ci, ci, dU, ddU, tangent):
    """S_vol = J p C^-1, CC_vol = J (p + J p') C^-1 (x) C^-1 - 2 J p C^-1 (.) C^-1 (Holzapfel
    6.166).
    """
    p = dU
    S = (J * p)[:, None, None] * Ci
    if not tangent:
        return S, None
    CC = (J * (p + J * ddU))[:, None, None] * _outer(ci, ci) - (2.0 * J * p)[:, None, None] * _odot(
        Ci
    )
    return S, CC


class DecoupledInvariantLaw(ClassicalLaw):
    """W = Psi(I1b, I2b) + k0/2 (ln J)^2 in the decoupled form with the isochoric projection.

    Fictitious stress Sb = 2 dPsi/dCb = 2 (Psi1 + I1b Psi2) I - 2 Psi2 Cb, Cb = J^(-2/3) C;
    S_iso = J^(-2/3) DEV(Sb) = J^(-2/3) Sb - 1/3 (J^(-2/3) Sb : C) C^-1;
    CC_iso = P : CCb : P^T + 2/3 tr P~ - 2/3 (C^-1 (x) S_iso + S_iso (x) C^-1), with
    P = II - 1/3 C^-1 (x) C, P~ = C^-1 (.) C^-1 - 1/3 C^-1 (x) C^-1, tr = J^(-2/3) Sb : C, and
    (Holzapfel 6.5-6.6)::

        CCb = J^(-4/3) [4 (Psi11 + 2 I1b Psi12 + Psi2 + I1b^2 Psi22) I (x) I
                        - 4 (Psi12 + I1b Psi22) (I (x) Cb + Cb (x) I)
                        + 4 Psi22 Cb (x) Cb - 4 Psi2 II]

    Subclasses give psi(I1b, I2b) -> (Psi, Psi1, Psi2, Psi11, Psi12, Psi22).
    """

    k0: float

    def psi(self, I1b, I2b):
        raise NotImplementedError

    @staticmethod
    def _invariants(C, J):
        I1 = np.trace(C, axis1=-2, axis2=-1)
        I2 = 0.5 * (I1**2 - np.einsum("...ij,...ji->...", C, C))
        j23 = J ** (-2.0 / 3.0)
        return I1, I2, j23

    def energy(self, C, J=None):
        C = np.asarray(C, float)
        J = _jacobian(C, J)
        I1, I2, j23 = self._invariants(C, J)
        return self.psi(j23 * I1, j23 * j23 * I2)[0] + _log_volumetric(self.k0, J)[0]

    def _evaluate(self, C, J, tangent):
        I1, I2, j23 = self._invariants(C, J)
        I1b, I2b = j23 * I1, j23 * j23 * I2
        _, p1, p2, p11, p12, p22 = self.psi(I1b, I2b)
        Ci = _inverse_sym(C, J * J)
        ci, cv = voigt(Ci), voigt(C)
        cbv = j23[:, None] * cv

        Sb = (-2.0 * p2)[:, None] * cbv
        Sb[:, :3] += (2.0 * (p1 + I1b * p2))[:, None]
        jSb = j23[:, None] * Sb
        tr = _ddot(jSb, cv)
        S_iso = jSb - (tr / 3.0)[:, None] * ci
        _, dU, ddU = _log_volumetric(self.k0, J)
        S_vol, CC_vol = _volumetric(J, Ci, ci, dU, ddU, tangent)
        S = from_voigt(S_iso) + S_vol
        if not tangent:
            return S, None

        j43 = (j23 * j23)[:, None, None]
        a = (4.0 * (p11 + 2.0 * I1b * p12 + p2 + I1b**2 * p22))[:, None, None]
        b = (-4.0 * (p12 + I1b * p22))[:, None, None]
        CCb = j43 * (
            a * _IXI
            + b * _sym_outer(np.broadcast_to(_I_V, cbv.shape), cbv)
            + (4.0 * p22)[:, None, None] * _outer(cbv, cbv)
            - (4.0 * p2)[:, None, None] * _II
        )
        # P : CCb : P^T with the Voigt contraction weights; P = II - 1/3 C^-1 (x) C.
        Pw = (
            np.broadcast_to(np.eye(6), CCb.shape) - _outer(ci, cv * WEIGHT) / 3.0
        )  # P_v diag(WEIGHT)
        CC_iso = Pw @ CCb @ np.swapaxes(Pw, -1, -2)
        odot = _odot(Ci)
        cixci = _outer(ci, ci)
        CC_iso += (2.0 / 3.0 * tr)[:, None, None] * (odot - cixci / 3.0) - (2.0 / 3.0) * _sym_outer(
            ci, S_iso
        )
        return S, CC_iso + CC_vol


class DeclaredDecoupledLaw(DecoupledInvariantLaw):
    """The decoupled law of a :class:`mjed.materials.classical_forms.Decoupled` form: Psi and
    its derivatives are the form's function, evaluated with NumPy.
    """

    def __init__(self, form: forms.Decoupled):
        self.form = form
        self.k0 = float(form.k0)
        self.parameters = _Named(form.parameters)

    def psi(self, I1b, I2b):
        z = np.zeros_like(I1b)
        return tuple(v + z for v in self.form.psi.function(self.parameters, I1b, I2b, np))


class _Named:
    """Parameters read by attribute (p.mu) from (name, value) pairs."""

    def __init__(self, pairs):
        for name, value in pairs:
            setattr(self, name, float(value))


def _power_divided_difference(a, b, p):
    """(a^p - b^p) / (a - b) for a, b > 0, continuous (= p b^(p-1)) at a = b and free of
    cancellation near it: b^(p-1) expm1(p t) / expm1(t) with t = ln(a/b).
    """
    t = np.log(a / b)
    same = t == 0.0
    ts = np.where(same, 1.0, t)
    ratio = np.where(same, p, np.expm1(p * ts) / np.expm1(ts))
    return b ** (p - 1.0) * ratio


_PAIRS = ((0, 1), (1, 2), (0, 2))


class OgdenLaw(ClassicalLaw):
    """W = c (J^(-alpha/3) sum_i lam_i^q - 3) + k0/2 (ln J)^2, c = mu/alpha^2, q = alpha/2, lam_i
    the eigenvalues of C (eigenvectors N_i, M_i = N_i (x) N_i).

    The isochoric part is a function of the eigenvalues, W_iso = c (P Sigma - 3) with
    P = (lam_1 lam_2 lam_3)^r = J^(-alpha/3), r = -alpha/6, Sigma = sum lam_k^q. Spectral form::

        S_iso = sum_i 2 w_i M_i, w_i = dW/dlam_i = c P (q lam_i^(q-1) + r Sigma / lam_i);
        CC_iso = sum_ij 4 w_ij M_i (x) M_j + sum_{i<j} theta_ij G_ij (x) G_ij,
        G_ij = N_i (x) N_j + N_j (x) N_i, theta_ij = 2 (w_i - w_j) / (lam_i - lam_j)
               = 2 c P (q DD(lam^(q-1))_ij - r Sigma / (lam_i lam_j)),

    with DD the divided difference of a power, evaluated without cancellation at (near-)repeated
    eigenvalues. The volumetric part goes through the C^-1 formulas.
    """

    def __init__(self, mu, alpha, k0):
        self.mu, self.alpha, self.k0 = float(mu), float(alpha), float(k0)
        self.c = self.mu / self.alpha**2
        self.q = 0.5 * self.alpha
        self.r = -self.alpha / 6.0

    def energy(self, C, J=None):
        C = np.asarray(C, float)
        J = _jacobian(C, J)
        lam = np.linalg.eigvalsh(C)
        W = self.c * (J ** (-self.alpha / 3.0) * (lam**self.q).sum(axis=-1) - 3.0)
        return W + _log_volumetric(self.k0, J)[0]

    def _evaluate(self, C, J, tangent):
        c, q, r = self.c, self.q, self.r
        lam, N = np.linalg.eigh(C)  # lam (m, 3) ascending; N[:, :, i] = N_i
        P = J ** (-self.alpha / 3.0)
        lq1 = lam ** (q - 1.0)
        sigma = (lq1 * lam).sum(axis=-1)
        cP = (c * P)[:, None]
        w = cP * (q * lq1 + r * sigma[:, None] / lam)  # (m, 3)
        M = N[:, VI, :] * N[:, VJ, :]  # (m, 6, 3): Voigt of M_i in column i
        S_iso = np.einsum("mIi,mi->mI", M, 2.0 * w)

        Ci = _inverse_sym(C, J * J)
        ci = voigt(Ci)
        _, dU, ddU = _log_volumetric(self.k0, J)
        S_vol, CC_vol = _volumetric(J, Ci, ci, dU, ddU, tangent)
        S = from_voigt(S_iso) + S_vol
        if not tangent:
            return S, None

        inv = 1.0 / lam
        sig = sigma[:, None, None]
        x = q * lq1[:, :, None] * inv[:, None, :]  # q lam_i^(q-1) / lam_j
        H = r * (x + np.swapaxes(x, 1, 2)) + r * r * sig * inv[:, :, None] * inv[:, None, :]
        d = np.arange(3)
        H[:, d, d] += q * (q - 1.0) * lam ** (q - 2.0) - r * sigma[:, None] * inv**2
        H *= cP[:, :, None]
        CC = M @ (4.0 * H) @ np.swapaxes(M, 1, 2)

        i, j = np.array(_PAIRS).T
        G = (
            N[:, VI][:, :, i] * N[:, VJ][:, :, j] + N[:, VI][:, :, j] * N[:, VJ][:, :, i]
        )  # (m, 6, 3)
        theta = (
            2.0
            * cP
            * (
                q * _power_divided_difference(lam[:, i], lam[:, j], q - 1.0)
                - r * sigma[:, None] * inv[:, i] * inv[:, j]
            )
        )
        CC += (G * theta[:, None, :]) @ np.swapaxes(G, 1, 2)
        return S, CC + CC_vol


class CostaLaw(ClassicalLaw):
    """W = a/2 (exp(J^(-4/3) Q) - 1) + k0 (J ln J - J + 1), Q = sum_ij B_ij Ef_ij^2, Ef = R^T E R.

    Q is a quadratic form in E: in the fibre frame dQ/dEf = 2 B o Ef (entrywise), so
    d2Q/dEf dEf = T_f with T_f,pqrs = 2 B_pq II_pqrs; T = R R T_f R^T R^T is pushed to the global
    axes once (per cell if the frame is per cell). Then Q = 1/2 E : T : E, q = dQ/dE = T : E and,
    with Psi(J, Q)::

        S  = Psi_Q q + J Psi_J C^-1,
        CC = Psi_QQ q (x) q + J Psi_QJ (q (x) C^-1 + C^-1 (x) q) + Psi_Q T
             + J (J Psi_JJ + Psi_J) C^-1 (x) C^-1 - 2 J Psi_J C^-1 (.) C^-1.
    """

    def __init__(self, a, k0, B, frame=None):
        self.a, self.k0 = float(a), float(k0)
        self.B = np.asarray(B, dtype=float)
        R = np.eye(3) if frame is None else np.asarray(frame, dtype=float)
        R = R.reshape(-1, 3, 3)
        Id = np.eye(3)
        II4 = 0.5 * (np.einsum("pr,qs->pqrs", Id, Id) + np.einsum("ps,qr->pqrs", Id, Id))
        Tf = 2.0 * self.B[:, :, None, None] * II4
        T4 = np.einsum("nip,njq,nkr,nls,pqrs->nijkl", R, R, R, R, Tf, optimize=True)
        self.T = T4[:, VI, VJ][:, :, VI, VJ]  # (1 or m, 6, 6)

    def _quadratic(self, C):
        e_eng = voigt(0.5 * (C - np.eye(3))) * WEIGHT
        q = np.einsum("mIJ,mJ->mI", np.broadcast_to(self.T, (len(C), 6, 6)), e_eng)
        return 0.5 * np.einsum("mI,mI->m", e_eng, q), q

    def energy(self, C, J=None):
        C = np.asarray(C, float).reshape(-1, 3, 3)
        J = _jacobian(C, J)
        Q, _ = self._quadratic(C)
        return 0.5 * self.a * np.expm1(J ** (-4.0 / 3.0) * Q) + self.k0 * (J * np.log(J) - J + 1.0)

    def _evaluate(self, C, J, tangent):
        Q, q = self._quadratic(C)
        j43 = J ** (-4.0 / 3.0)
        e = 0.5 * self.a * np.exp(j43 * Q)
        lnJ = np.log(J)
        pQ = e * j43
        pJ = -4.0 / 3.0 * e * Q * j43 / J + self.k0 * lnJ
        Ci = _inverse_sym(C, J * J)
        ci = voigt(Ci)
        S = from_voigt(pQ[:, None] * q + (J * pJ)[:, None] * ci)
        if not tangent:
            return S, None
        pQQ = e * j43 * j43
        pQJ = -4.0 / 3.0 * e * j43 / J * (1.0 + j43 * Q)
        pJJ = e * (16.0 / 9.0 * Q * Q * j43 * j43 + 28.0 / 9.0 * Q * j43) / (J * J) + self.k0 / J
        s = lambda v: v[:, None, None]  # noqa: E731
        CC = (
            s(pQQ) * _outer(q, q)
            + s(J * pQJ) * _sym_outer(q, ci)
            + s(pQ) * self.T
            + s(J * (J * pJJ + pJ)) * _outer(ci, ci)
            - s(2.0 * J * pJ) * _odot(Ci)
        )
        return S, CC


def classical_law(material) -> ClassicalLaw:
    """The classical law of a declared material: the law of the form its declaration gives
    (``Declaration.classical``), built by :func:`law_of_form`.

    Raises:
        TypeError: naming the type when it is not declared, or when its form has no law here.
    """
    try:
        declaration = declaration_of(type(material))
    except LookupError:
        cls = type(material)
        raise TypeError(
            f"no classical law for material type {cls.__module__}.{cls.__qualname__}: "
            "it is not declared (mjed.materials.declaration.declare, with its "
            "classical form)"
        ) from None
    return law_of_form(declaration.classical(material))


@functools.singledispatch
def law_of_form(form) -> ClassicalLaw:
    """The classical law of a form of :mod:`mjed.materials.classical_forms`, by its type."""
    raise TypeError(
        f"the classical element has no law for the form {type(form).__qualname__}; "
        "register one with reference_fem.classical_materials.law_of_form.register"
    )


@law_of_form.register
def _(form: forms.GreenLagrangeQuadratic) -> ClassicalLaw:
    return StVenantKirchhoffLaw(form.mu, form.lam)


@law_of_form.register
def _(form: forms.CompressibleNeoHookean) -> ClassicalLaw:
    return NeoHookeanLaw(form.mu, form.lam)


@law_of_form.register
def _(form: forms.Decoupled) -> ClassicalLaw:
    return DeclaredDecoupledLaw(form)


@law_of_form.register
def _(form: forms.SpectralOgden) -> ClassicalLaw:
    return OgdenLaw(form.mu, form.alpha, form.k0)


@law_of_form.register
def _(form: forms.FibreExponential) -> ClassicalLaw:
    return CostaLaw(form.a, form.k0, form.B, form.frame)
