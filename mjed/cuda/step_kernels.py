"""The small kernels of a device-resident implicit Euler step
(:class:`mjed.cuda.integrator.DeviceImplicitEuler`), FP64.

Vectors are flat (3n,) dof arrays; matrices are value arrays (nnz,) on the one CSR pattern of
the force field's stiffness (:class:`mjed.sparse.CSRPattern`): the stiffness K (in the
field's dtype), the mass M laid on it once per mesh (:func:`mjed.linear_system.values_on_pattern`)
and the step matrix A. Every kernel but :func:`clear` is a grid-stride loop
(:mod:`mjed.cuda.threads`): the row kernels over the rows, one a thread on a GPU; the
reductions add one atomic per thread into a few float64 scalars, the only numbers read back.
Importing this module imports numba.cuda.
"""

from __future__ import annotations

import math

from numba import cuda

from mjed.cuda.threads import THREADS_PER_BLOCK

__all__ = [
    "THREADS",
    "advance_velocity",
    "clear",
    "fill_zero",
    "jacobians",
    "max_displacement",
    "new_positions",
    "non_finite",
    "norm_and_non_finite",
    "positions",
    "prescribe",
    "reaction",
    "right_hand_side",
    "start_velocity",
    "system_matrix",
]

#: Threads per block of every kernel here (mjed.cuda.threads).
THREADS = THREADS_PER_BLOCK


@cuda.jit
def clear(out):
    """Out[:] = 0 (one thread: out holds a few scalars)."""
    if cuda.grid(1) == 0:
        for i in range(out.shape[0]):
            out[i] = 0.0


@cuda.jit
def fill_zero(a):
    """A = 0, grid-stride: one thread per entry, or fewer threads each taking several (the
    force field's launcher caps its blocks; the simulator caps every launch's).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, a.shape[0], stride):
        a[i] = 0


@cuda.jit
def start_velocity(v0, constrained, vref, ue):
    """Vref = v0 on the free dofs and 0 on the constrained ones; ue = 0 (the first
    linearisation point is x0).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, vref.shape[0], stride):
        vref[i] = 0.0 if constrained[i] else v0[i]
        ue[i] = 0.0


@cuda.jit
def prescribe(nodes, target, x0, dt, vref):
    """Vref at prescribed node a = nodes[k]: (target[k] - x0[a]) / dt, which brings it to its
    prescribed position at the end of the step.
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for k in range(start, nodes.shape[0], stride):
        a = nodes[k]
        for c in range(3):
            vref[3 * a + c] = (target[k, c] - x0[3 * a + c]) / dt


@cuda.jit
def positions(x0, ue, out):
    """Out = x0 + ue, out in the force field's dtype (rounded as a host copy to it would be)."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, out.shape[0], stride):
        out[i] = x0[i] + ue[i]


@cuda.jit
def right_hand_side(
    indptr, indices, mass, stiff, f, fext, vref, v0, ue, constrained, dt, c_mass, c_stiff, rhs, b
):
    """Rhs = dt (f + fext) - M (c_mass vref - v0) - K (c_stiff vref - dt ue), with c_mass =
    1 + dt r_M and c_stiff = dt (dt + r_K): ImplicitEuler's dt (f + f_ext - D vref -
    K (dt vref - ue)) - M (vref - v0) regrouped; b = rhs on the free rows, 0 on the
    constrained ones (the CG's right-hand side).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, rhs.shape[0], stride):
        acc = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            acc += mass[k] * (c_mass * vref[j] - v0[j])
            acc += stiff[k] * (c_stiff * vref[j] - dt * ue[j])
        r = dt * (f[i] + fext[i]) - acc
        rhs[i] = r
        b[i] = 0.0 if constrained[i] else r


@cuda.jit
def norm_and_non_finite(b, f, out):
    """Out[0] += b.b; out[1] += the number of non-finite entries of f."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    s = 0.0
    bad = 0.0
    for i in range(start, b.shape[0], stride):
        s += b[i] * b[i]
    for i in range(start, f.shape[0], stride):
        if not math.isfinite(f[i]):
            bad += 1.0
    cuda.atomic.add(out, 0, s)
    cuda.atomic.add(out, 1, bad)


@cuda.jit
def non_finite(a, out):
    """Out[0] += the number of non-finite entries of a."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    bad = 0.0
    for i in range(start, a.shape[0], stride):
        if not math.isfinite(a[i]):
            bad += 1.0
    cuda.atomic.add(out, 0, bad)


@cuda.jit
def system_matrix(indptr, indices, mass, stiff, constrained, a, b, out):
    """Out = a M + b K on the free rows and columns; the constrained rows and columns are
    those of the identity, so that CG on the whole system runs the iterations of CG on the free
    block (its right-hand side and first guess being 0 on the constrained dofs).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, constrained.shape[0], stride):
        ci = constrained[i]
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if ci or constrained[j]:
                out[k] = 1.0 if (ci and j == i) else 0.0
            else:
                out[k] = b * stiff[k] + a * mass[k]


@cuda.jit
def reaction(dofs, indptr, indices, mass, stiff, a, b, dv, rhs, dt, out):
    """Out[k] = (a (M dv)_i + b (K dv)_i - rhs_i) / dt at the constrained dof i = dofs[k]:
    what the constraint must add for row i to balance (a = b = 0: -rhs_i / dt).
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for k in range(start, dofs.shape[0], stride):
        i = dofs[k]
        m = 0.0
        s = 0.0
        if a != 0.0 or b != 0.0:
            for q in range(indptr[i], indptr[i + 1]):
                j = indices[q]
                m += mass[q] * dv[j]
                s += stiff[q] * dv[j]
        out[k] = (a * m + b * s - rhs[i]) / dt


@cuda.jit
def advance_velocity(vref, dv, ue, dt):
    """Vref += dv; ue = dt vref (the next linearisation point)."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    for i in range(start, vref.shape[0], stride):
        v = vref[i] + dv[i]
        vref[i] = v
        ue[i] = dt * v


@cuda.jit
def new_positions(x0, vref, dt, x1, out):
    """X1 = x0 + dt vref; out[0] += the number of non-finite entries of x1 or vref."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    bad = 0.0
    for i in range(start, x1.shape[0], stride):
        v = vref[i]
        x = x0[i] + dt * v
        x1[i] = x
        if not (math.isfinite(x) and math.isfinite(v)):
            bad += 1.0
    cuda.atomic.add(out, 0, bad)


@cuda.jit
def jacobians(cells, six_volume, x, J0, c, J1, out):
    """J1[e] = det(x1 - x0, x2 - x0, x3 - x0) / (6 V_e) for the cells' nodes (x flat);
    out[0] += the cells with J1 <= 0 (or NaN); if c > 0, out[1] += the cells with J0, J1 > 0
    whose J1 / J0 lies outside [1 / c, c].
    """
    start, stride = cuda.grid(1), cuda.gridsize(1)
    inverted = 0.0
    jumps = 0.0
    for e in range(start, J1.shape[0], stride):
        p = 3 * cells[e, 0]
        q1 = 3 * cells[e, 1]
        q2 = 3 * cells[e, 2]
        q3 = 3 * cells[e, 3]
        ax, ay, az = x[q1] - x[p], x[q1 + 1] - x[p + 1], x[q1 + 2] - x[p + 2]
        bx, by, bz = x[q2] - x[p], x[q2 + 1] - x[p + 1], x[q2 + 2] - x[p + 2]
        cx, cy, cz = x[q3] - x[p], x[q3 + 1] - x[p + 1], x[q3 + 2] - x[p + 2]
        det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
        J = det / six_volume[e]
        J1[e] = J
        if not J > 0.0:
            inverted += 1.0
        elif c > 0.0 and J0[e] > 0.0:
            ratio = J / J0[e]
            if ratio > c or ratio < 1.0 / c:
                jumps += 1.0
    cuda.atomic.add(out, 0, inverted)
    cuda.atomic.add(out, 1, jumps)


@cuda.jit
def max_displacement(x, X, out):
    """Out[0] = max(out[0], max over the nodes of |x_a - X_a|) (x, X flat (3n,))."""
    start, stride = cuda.grid(1), cuda.gridsize(1)
    hi = 0.0
    for a in range(start, x.shape[0] // 3, stride):
        dx = x[3 * a] - X[3 * a]
        dy = x[3 * a + 1] - X[3 * a + 1]
        dz = x[3 * a + 2] - X[3 * a + 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d > hi:
            hi = d
    cuda.atomic.max(out, 0, hi)
