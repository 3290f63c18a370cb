"""A stiffness off by round-off alone (conformance.diagnosis.stiffness_noise): node blocks in
float32, or a tangent by differences whose step is too small. MJED stands in for the oracle,
at the case and at its probes.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from conftest import box_mesh

import mjed
from common.cases import default_material
from conformance.diagnosis.stiffness_noise import noise_finding, single_precision_blocks_finding


def _setup(material="NeoHookean", seed=0):
    points, cells = box_mesh(2, jitter=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    x = points @ np.diag([1.1, 0.95, 0.92]).T + 0.02 * rng.standard_normal(points.shape)
    probes = [x + 1e-4 / 3 * 2.0**-k * rng.standard_normal(x.shape) for k in range(3)]
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), default_material(material))
    return field, x, probes


def _forward_difference_tangent(field, x, h):
    """K by forward differences of the assembled force, one dof at a time, step h."""
    f0 = field.force(x).ravel()
    cols = []
    for j in range(f0.size):
        y = x.copy().ravel()
        y[j] += h
        cols.append(-(field.force(y.reshape(x.shape)).ravel() - f0) / h)
    return sp.csr_matrix(np.array(cols).T)


def _f32(a):
    return a.astype(np.float32).astype(np.float64)


def test_edge_blocks_in_float32_are_named_from_their_values():
    field, x, _ = _setup()
    K_o = sp.coo_matrix(field.stiffness(x))
    edge = K_o.row // 3 != K_o.col // 3
    data = np.where(edge, _f32(K_o.data), K_o.data)
    K = sp.csr_matrix((data, (K_o.row, K_o.col)), shape=K_o.shape)
    found = single_precision_blocks_finding(K, K_o)
    assert found is not None and "off-diagonal node blocks" in found.title, found
    assert "float32" in found.title and "diagonal node blocks" in found.title
    whole = sp.csr_matrix((_f32(K_o.data), (K_o.row, K_o.col)), shape=K_o.shape)
    assert "all of K's entries" in single_precision_blocks_finding(whole, K_o).title
    # the same size of error from a factor: no class of float32 numbers
    assert single_precision_blocks_finding(sp.csr_matrix(K_o) * (1 + 3e-8), K_o) is None


def test_a_tangent_by_differences_with_a_tiny_step_is_round_off_noise():
    """Forward differences of the force, h = 1e-11 (noise about 6e-6 of K) and 1e-9 (about
    7e-8): float32 arithmetic (or float32 inputs, amplified) leaves the same noise, so both are
    said, as ambiguous; the broken symmetry points to first differences.
    """
    field, x, probes = _setup("MooneyRivlin", 1)
    K_o = sp.csr_matrix(field.stiffness(x))
    probe_K_o = [field.stiffness(y) for y in probes]
    for h in (1e-11, 1e-9):
        K = _forward_difference_tangent(field, x, h)
        probe_K = [_forward_difference_tangent(field, y, h) for y in probes]
        found = noise_finding(K, K_o, probe_K, probe_K_o)
        assert found is not None and "finite differences" in found.title, found
        assert "float32" in found.title and found.strength == "partly explains", found
        assert "first differences" in found.evidence  # forward differences break K's symmetry
    # symmetric noise: second differences of W
    sym = [0.5 * (k + k.T) for k in (K, *probe_K)]
    found = noise_finding(sym[0], K_o, sym[1:], probe_K_o)
    assert found is not None and "second differences" in found.evidence


def test_a_smooth_error_of_the_same_size_is_not_noise():
    field, x, probes = _setup("Gent", 2)
    K_o = sp.csr_matrix(field.stiffness(x))
    probe_K_o = [sp.csr_matrix(field.stiffness(y)) for y in probes]
    scaled = [k * (1 + 1e-7) for k in (K_o, *probe_K_o)]
    assert noise_finding(scaled[0], K_o, scaled[1:], probe_K_o) is None
    assert noise_finding(scaled[0], K_o, [], []) is None  # no probes: nothing said


def test_repeated_stretches_are_told_from_a_general_state():
    from conftest import stretched_state

    from conformance.diagnosis.stiffness_noise import repeated_stretches

    assert repeated_stretches(*stretched_state(0, uniaxial=True))  # diag(1.2, 0.95, 0.95)
    assert not repeated_stretches(*stretched_state(0))
