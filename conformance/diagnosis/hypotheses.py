"""Convention mistakes as corrections: each hypothesis maps the engine's output back to what it
would
be without the mistake. A hypothesis is named only when its correction brings the force and the
stiffness within tolerance of the oracle (or it is reported as partly explaining, with the
residual).

All functions are pure: arrays in, arrays out. f is (n, 3), K scipy sparse (3n, 3n),
dof = 3 * node + component.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, Optional, Tuple

import numpy as np
import scipy.sparse as sp

__all__ = [
    "Correction",
    "convention_corrections",
    "component_major_to_node_major",
    "permute_nodes",
    "transpose_blocks",
    "fit_scale",
    "match_nodes",
    "describe_permutation",
    "common_factor_name",
]

Output = Tuple[np.ndarray, sp.csr_matrix, Optional[float]]


@dataclass(frozen=True)
class Correction:
    """code, title: the mistake; apply: engine output -> corrected output (None when not
    applicable).
    """

    code: str
    title: str
    apply: Callable[[np.ndarray, sp.csr_matrix, Optional[float]], Optional[Output]]


def component_major_to_node_major(n: int) -> np.ndarray:
    """P with node-major index i = p-th entry read: engine wrote value of dof 3a+c at c*n+a."""
    a, c = np.divmod(np.arange(3 * n), 3)
    return c * n + a


def _reindex_vector(f: np.ndarray, p: np.ndarray) -> np.ndarray:
    return f.ravel()[p].reshape(-1, 3)


def _reindex_matrix(K: sp.csr_matrix, p: np.ndarray) -> sp.csr_matrix:
    """K'[i, j] = K[p[i], p[j]]."""
    return sp.csr_matrix(K)[p][:, p].tocsr()


def permute_nodes(q: np.ndarray) -> np.ndarray:
    """Dof map for a node map q (oracle node a's values sit at engine node q[a])."""
    return (3 * q[:, None] + np.arange(3)).ravel()


def transpose_blocks(K: sp.csr_matrix) -> sp.csr_matrix:
    """Each 3x3 node-pair block transposed: K'[3a+i, 3b+j] = K[3a+j, 3b+i]."""
    C = sp.coo_matrix(K)
    r_node, r_c = np.divmod(C.row, 3)
    c_node, c_c = np.divmod(C.col, 3)
    return sp.csr_matrix((C.data, (3 * r_node + c_c, 3 * c_node + r_c)), shape=K.shape)


def fit_scale(engine, oracle) -> Optional[float]:
    """S minimising ||s engine - oracle|| (arrays of one shape, or sparse matrices; None if
    engine is zero).
    """
    if sp.issparse(engine):
        ee, eo = _sparse_dot(engine, engine), _sparse_dot(engine, oracle)
    else:
        ee, eo = float(np.vdot(engine, engine)), float(np.vdot(engine, oracle))
    return None if ee == 0 else eo / ee


def _sparse_dot(A: sp.spmatrix, B: sp.spmatrix) -> float:
    return float(sp.csr_matrix(A).multiply(B).sum())


def match_nodes(
    f_e: np.ndarray, K_e: sp.csr_matrix, f_o: np.ndarray, K_o: sp.csr_matrix
) -> Optional[np.ndarray]:
    """Q with engine node q[a] carrying oracle node a's values, matched on force and diagonal block;
    None when the match is not one to one (symmetric nodes) or is the identity.
    """
    from scipy.spatial import cKDTree

    def features(f, K):
        d = K.diagonal().reshape(-1, 3)
        nf, nd = np.linalg.norm(f), np.linalg.norm(d)
        return np.hstack([f / nf if nf > 0 else f, d / nd if nd > 0 else d])

    fo, fe = features(f_o, K_o), features(f_e, K_e)
    _, q = cKDTree(fe).query(fo)
    q = np.asarray(q, dtype=np.int64)
    if np.unique(q).size != q.size or np.array_equal(q, np.arange(q.size)):
        return None
    return q


def describe_permutation(q: np.ndarray) -> str:
    n = q.size
    shift = (q - np.arange(n)) % n
    values, counts = np.unique(shift, return_counts=True)
    k = int(values[np.argmax(counts)])
    if counts.max() >= n - 2 and k != 0:
        k_signed = k if k <= n // 2 else k - n
        hint = " (1-based node numbers?)" if k_signed == 1 else ""
        return (
            f"node index offset by {k_signed:+d}: node a's values sit at index a{k_signed:+d}{hint}"
        )
    moved = np.flatnonzero(q != np.arange(n))
    pairs = ", ".join(f"{a}->{q[a]}" for a in moved[:6])
    more = ", ..." if moved.size > 6 else ""
    return f"nodes permuted: {moved.size} of {n} nodes moved ({pairs}{more})"


def common_factor_name(ratio: float, mean_volume: float, uniform_volume: bool) -> str:
    """Words for an engine/oracle ratio: the usual suspects, else the number."""
    named = {
        2.0: "factor 2 (e.g. energy counted twice, or C - I used for E = (C - I)/2)",
        0.5: "factor 1/2 (e.g. a missing 2 in S = 2 dW/dC)",
        6.0: "factor 6 (the 1/6 of the tetrahedron volume missing)",
        1.0 / 6.0: "factor 1/6",
    }
    # A power of 1000 is a unit conversion applied where it does not belong (or missing): a
    # length or a difference step in mm against m, a modulus in kPa against Pa.
    for k in (1, 2, 3):
        words_k = {1: "1000", 2: "10^6", 3: "10^9"}[k]
        named[1000.0**k] = f"factor {words_k} (units: a length, a step or a modulus converted"
        named[1000.0**k] += " where it should not be, or not converted, e.g. mm against m)"
        named[1000.0**-k] = f"factor 1/{words_k} (units: a length, a step or a modulus converted"
        named[1000.0**-k] += " where it should not be, or not converted, e.g. mm against m)"
    words = [name for value, name in named.items() if abs(ratio / value - 1.0) < 1e-6]
    if uniform_volume and abs(ratio * mean_volume - 1.0) < 1e-6:
        words.append(f"volume weighting missing (engine = oracle / V0, V0 = {mean_volume:.3e} m^3)")
    if uniform_volume and abs(ratio / mean_volume - 1.0) < 1e-6:
        words.append(f"volume applied twice (engine = oracle x V0, V0 = {mean_volume:.3e} m^3)")
    if words:  # on a mesh where two explanations give the same number, both are said
        return " or ".join(words)
    return f"factor {ratio:.6g}"


def convention_corrections(
    f_o: np.ndarray, K_o: sp.csr_matrix, f_e: np.ndarray, K_e: sp.csr_matrix
) -> List[Correction]:
    """The convention hypotheses for one case, most specific first."""
    n = f_o.shape[0]
    cm = component_major_to_node_major(n)
    out = [
        Correction(
            "force-sign",
            "force sign flipped (f = +dW/dx, the residual, instead of -dW/dx)",
            lambda f, K, W: (-f, K, W),
        ),
        Correction(
            "stiffness-sign",
            "stiffness sign flipped (df/dx = -K given instead of K = d2W/dx2)",
            lambda f, K, W: (f, -K, W),
        ),
        Correction(
            "both-signs",
            "force and stiffness signs flipped (the stress negated: the residual's sign "
            "convention, or a sign inside the stress, e.g. the strain written (I - C)/2)",
            lambda f, K, W: (-f, -K, W),
        ),
        Correction(
            "dof-order",
            "component-major dof order (c*n + node) instead of node-major (3*node + c)",
            lambda f, K, W: (_reindex_vector(f, cm), _reindex_matrix(K, cm), W),
        ),
        Correction(
            "dof-order-force",
            "force in component-major dof order (stiffness node-major)",
            lambda f, K, W: (_reindex_vector(f, cm), K, W),
        ),
        Correction(
            "dof-order-stiffness",
            "stiffness in component-major dof order (force node-major)",
            lambda f, K, W: (f, _reindex_matrix(K, cm), W),
        ),
        Correction(
            "block-transpose",
            "each 3x3 node block of K transposed (K_ab^T written for K_ab)",
            lambda f, K, W: (f, transpose_blocks(K), W),
        ),
        Correction(
            "unsymmetric",
            "K is not symmetric: its symmetric part is right",
            lambda f, K, W: (f, (0.5 * (K + K.T)).tocsr(), W),
        ),
        Correction(
            "one-triangle",
            "only one triangle of the symmetric K written (upper or lower "
            "storage read as a full matrix)",
            lambda f, K, W: (f, _full_from_triangle(K), W),
        ),
        Correction(
            "mirror-blocks",
            "each node pair's 3x3 block written on one side only: K_ab at (a, b), its mirror "
            "K_ba = K_ab^T at (b, a) never written (an edge loop over a < b without the "
            "symmetric half)",
            lambda f, K, W: (f, _mirrored_blocks(K), W),
        ),
        Correction(
            "both-triangles",
            "both triangles summed: every off-diagonal entry counted "
            "twice "
            "(a full K added to its transpose, the diagonal once)",
            lambda f, K, W: (f, (0.5 * (K + sp.diags(K.diagonal()))).tocsr(), W),
        ),
    ]
    for k in (1, -1, 2, -2):
        q = (np.arange(n) + k) % n
        p = permute_nodes(q)
        out.append(
            Correction(
                f"node-offset{k:+d}",
                describe_permutation(q),
                lambda f, K, W, p=p: (_reindex_vector(f, p), _reindex_matrix(K, p), W),
            )
        )
    q = match_nodes(f_e, K_e, f_o, K_o)
    if q is not None and not any(np.array_equal(q, (np.arange(n) + k) % n) for k in (1, -1, 2, -2)):
        p = permute_nodes(q)
        out.append(
            Correction(
                "node-permutation",
                describe_permutation(q),
                lambda f, K, W, p=p: (_reindex_vector(f, p), _reindex_matrix(K, p), W),
            )
        )
    return out


def _full_from_triangle(K: sp.csr_matrix) -> sp.csr_matrix:
    """K + K^T - diag K when one strict triangle of K is empty, else K unchanged (then the
    correction explains nothing and is not named). K: (3n, 3n).
    """
    K = sp.csr_matrix(K)
    if sp.tril(K, -1).count_nonzero() and sp.triu(K, 1).count_nonzero():
        return K
    return (K + K.T - sp.diags(K.diagonal())).tocsr()


def _mirrored_blocks(K: sp.csr_matrix) -> sp.csr_matrix:
    """K + K^T less K's node-diagonal 3x3 blocks once, K (3n, 3n): where each off-diagonal node
    block was written on one side only (either side, cell by cell) this is the full matrix; a
    shared node pair's blocks from cells that wrote opposite sides add up as they should.
    """
    K = sp.coo_matrix(K)
    same = (K.row // 3) == (K.col // 3)
    node = sp.csr_matrix((K.data[same], (K.row[same], K.col[same])), shape=K.shape)
    return (K.tocsr() + K.T.tocsr() - node).tocsr()


#: Relative distance from 1 below which a fitted global factor is round-off, not a scaling.
SCALE_NOISE = 1e-8


def scale_corrections(f_o, K_o, f_e, K_e, W_o, W_e) -> List[Tuple[str, str, float, Output]]:
    """Global factors fitted on force and stiffness: (code, which, engine/oracle ratio, corrected
    output).
    """
    out = []
    s_f = fit_scale(f_e, f_o)
    kk = _sparse_dot(K_e, K_e)
    s_K = _sparse_dot(K_e, K_o) / kk if kk > 0 else None
    # A factor within round-off of 1 is no cause: "scaled by 1" once "explained" a case whose
    # stiffness error (1.04e-10, a sliver in mm) sat at the tolerance (SOFA's classical field).
    if s_K is not None and abs(s_K - 1.0) <= SCALE_NOISE:
        s_K = None
    if s_f is not None and abs(s_f - 1.0) <= SCALE_NOISE:
        s_f = None
    if s_K is not None and s_K > 0:
        # One factor for both: a force scaled differently is left unexplained.
        W = None if W_e is None else W_e * s_K
        out.append(("scale", "force and stiffness", 1.0 / s_K, (f_e * s_K, (K_e * s_K).tocsr(), W)))
        out.append(
            ("scale-stiffness", "stiffness only", 1.0 / s_K, (f_e, (K_e * s_K).tocsr(), W_e))
        )
    if s_f is not None and s_f > 0:
        out.append(("scale-force", "force only", 1.0 / s_f, (f_e * s_f, K_e, W_e)))
    return out
