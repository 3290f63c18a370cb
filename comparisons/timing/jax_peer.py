"""A GPU peer on the same card: the element written as an energy and differentiated by JAX.

This is how a JAX finite-element code (JAX-FEM and most research codes on JAX) builds force
and stiffness: one function gives a cell's energy V0 W(F) from its four vertex positions, and
``jax.grad`` and ``jax.hessian`` of it, mapped over the cells with ``jax.vmap`` and compiled by
XLA, give the element vectors and 12x12 element matrices, summed into nodal forces and into
the values of the same CSR pattern the project's kernels fill (``mjed.sparse.CSRPattern``),
by scatter-adds. The energy is the project's compressible Neo-Hookean, written here from its
formula (not from mjed's terms):

    W(F) = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2,   I1 = tr(F^T F),  J = det F

Before any timing, each precision is checked against mjed's NumPy engine on the first cube
(force and stiffness, relative to their largest entries): FP64 must agree to 1e-10 or nothing
is timed; FP32 is timed with its accuracy printed beside it, marked where it is outside the
1e-4 the project's own FP32 kernels meet (JAX's FP32 determinant and logarithm near J = 1 lose
more digits than the hand-written kernels).
The timings are taken on the same structured cubes and deformed state as
comparisons.timing.gpu (positions, forces and CSR values on the device; best of repeated
calls after a warm-up that compiles), so that with ``--against`` the figures of the project's
MJED and classical GPU kernels measured in the same device session are set beside them.

    python -m comparisons.timing.jax_peer --json peer.json --against hardware_bench.json

Without JAX, or with JAX but no GPU, it says so and exits 3 (never times a CPU as the peer).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import sys
from dataclasses import asdict, dataclass
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np
import scipy.sparse as sp

__all__ = ["PeerTiming", "neo_hookean_density", "element_functions", "JaxPeer", "main"]

#: relative agreement with mjed's NumPy engine required before a precision is timed
VERIFY_TOL = {"float64": 1e-10, "float32": 1e-4}
DTYPES = ("float64", "float32")
#: 1e7 tets is left out by default: its host set-up (mesh, a 1.4e9-entry scatter map) takes
#: minutes, more than a device session's share
DEFAULT_SIZES = (10_000, 100_000, 1_000_000)


@dataclass(frozen=True)
class PeerTiming:
    """One figure: ``cells`` tets, precision, "f" or "f+K", best and median seconds per call."""

    cells: int
    dtype: str
    quantity: str
    best_s: float
    median_s: float
    repeats: int
    tets_per_s: float


def neo_hookean_density(F, mu: float, lam: float):
    """W(F) of one cell (Pa): F (3, 3) -> scalar, in jax.numpy."""
    import jax.numpy as jnp

    J = jnp.linalg.det(F)
    lnJ = jnp.log(J)
    return 0.5 * mu * (jnp.sum(F * F) - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2


def element_functions(mu: float, lam: float):
    """(gradient, hessian) of one cell's energy V0 W(F), each mapped over cells.

    Each takes x (m, 4, 3) vertex positions, D (m, 4, 3) shape-function gradients and V0 (m,)
    rest volumes; the gradient is (m, 4, 3) and the hessian (m, 4, 3, 4, 3), so that its
    reshape to (m, 12, 12) is in the dof order 3 a + i of mjed.sparse.CSRPattern.scatter.
    """
    import jax
    import jax.numpy as jnp

    def cell_energy(x, D, V0):
        F = jnp.einsum("ai,aj->ij", x, D)  # F = sum_a x_a (x) grad N_a
        return V0 * neo_hookean_density(F, mu, lam)

    grad = jax.vmap(jax.grad(cell_energy))
    hess = jax.vmap(jax.hessian(cell_energy))
    return grad, hess


class JaxPeer:
    """Force and stiffness values of one mesh in one precision, compiled by XLA on the GPU.

    Args:
        mesh: an mjed.TetMesh.
        material: an mjed NeoHookean (its ``mu`` and ``lam``, Pa).
        pattern: the mesh's mjed.sparse.CSRPattern (the layout of the stiffness values).
        dtype: "float64" or "float32".
    """

    def __init__(self, mesh, material, pattern, dtype: str):
        import jax
        import jax.numpy as jnp

        from mjed.mesh import shape_vectors

        self.dtype, self.n_nodes, self.nnz = dtype, mesh.n_nodes, pattern.nnz
        volumes, D = shape_vectors(mesh.points, mesh.cells)
        put = jax.device_put
        self.cells = put(jnp.asarray(mesh.cells, dtype=jnp.int32))
        self.D = put(jnp.asarray(D, dtype=dtype))
        self.V0 = put(jnp.asarray(np.abs(volumes), dtype=dtype))
        self.dofs = put(jnp.asarray(pattern.force_scatter, dtype=jnp.int32))
        self.slots = put(jnp.asarray(pattern.scatter, dtype=jnp.int32))
        grad, hess = element_functions(material.mu, material.lam)
        n3, nnz = 3 * mesh.n_nodes, pattern.nnz

        def force(x, cells, D, V0, dofs):
            g = grad(x[cells], D, V0)
            return jnp.zeros(n3, x.dtype).at[dofs].add(-g.reshape(-1)).reshape(-1, 3)

        def force_and_stiffness(x, cells, D, V0, dofs, slots):
            xe = x[cells]
            g = grad(xe, D, V0)
            f = jnp.zeros(n3, x.dtype).at[dofs].add(-g.reshape(-1)).reshape(-1, 3)
            K = jnp.zeros(nnz, x.dtype).at[slots].add(hess(xe, D, V0).reshape(-1))
            return f, K

        self._force = jax.jit(force)
        self._force_and_stiffness = jax.jit(force_and_stiffness)

    def to_device(self, x: np.ndarray):
        import jax
        import jax.numpy as jnp

        return jax.device_put(jnp.asarray(x, dtype=self.dtype))

    def force(self, x_d):
        return self._force(x_d, self.cells, self.D, self.V0, self.dofs)

    def force_and_stiffness(self, x_d):
        return self._force_and_stiffness(x_d, self.cells, self.D, self.V0, self.dofs, self.slots)


def verify(mesh, material, pattern) -> Dict[str, dict]:
    """Each precision's force and stiffness against mjed's NumPy engine (relative errors)."""
    import mjed
    from comparisons.timing.gpu import bench_state

    x = bench_state(mesh.points)
    f_ref, K_ref = mjed.make_force_field(mesh, material).force_and_stiffness(x)
    K_ref = K_ref.tocsr()
    out = {}
    for dtype in DTYPES:
        peer = JaxPeer(mesh, material, pattern, dtype)
        f, vals = peer.force_and_stiffness(peer.to_device(x))
        f = np.asarray(f, dtype=np.float64)
        K = sp.csr_matrix(
            (np.asarray(vals, dtype=np.float64), pattern.indices, pattern.indptr), pattern.shape
        )
        ef = float(np.abs(f - f_ref).max() / np.abs(f_ref).max())
        eK = float(abs(K - K_ref).max() / abs(K_ref).max())
        out[dtype] = {
            "force_err": ef,
            "stiffness_err": eK,
            "tol": VERIFY_TOL[dtype],
            "passed": max(ef, eK) <= VERIFY_TOL[dtype],
        }
    return out


def _time_size(mesh, material, pattern, dtypes, min_time, timings, skipped) -> None:
    """Force and force + stiffness of one cube in each of ``dtypes``, appended to ``timings``;
    a precision that does not fit the device is appended to ``skipped``, with the error.
    """
    import jax

    from comparisons.timing.gpu import bench_state, timed_repeats

    x = bench_state(mesh.points)
    for dtype in dtypes:
        try:
            peer = JaxPeer(mesh, material, pattern, dtype)
            x_d = peer.to_device(x)
            for quantity, call in (
                ("f", lambda: peer.force(x_d)),
                ("f+K", lambda: peer.force_and_stiffness(x_d)),
            ):
                best, median, repeats = timed_repeats(
                    lambda call=call: jax.block_until_ready(call()), min_time
                )
                timings.append(
                    PeerTiming(
                        mesh.n_cells, dtype, quantity, best, median, repeats, mesh.n_cells / best
                    )
                )
        except Exception as exc:  # device memory: XLA's RESOURCE_EXHAUSTED, said, not hidden
            skipped.append(f"{mesh.n_cells:,} tets {dtype}: {type(exc).__name__}: {exc}"[:300])
        finally:
            peer = x_d = None


def measure(
    sizes: Sequence[int] = DEFAULT_SIZES,
    min_time: float = 0.25,
    say: Callable[[str], None] = lambda s: None,
    partial: Callable[[dict], None] = lambda fig: None,
) -> dict:
    """The peer's figures (see the module docstring) as a JSON-ready dict; ``partial`` is
    given the figures so far after each size (a run stopped at its time limit keeps them).
    """
    import jax

    import mjed
    from common.cases import default_material
    from meshes.structured import cube_with_cells
    from mjed.sparse import CSRPattern

    jax.config.update("jax_enable_x64", True)
    material = default_material("NeoHookean")
    checks: Optional[Dict[str, dict]] = None
    timings: List[PeerTiming] = []
    skipped: List[str] = []
    device = jax.devices()[0]
    fig = {
        "peer": "JAX autodiff per element (jax.vmap of jax.grad / jax.hessian, XLA)",
        "jax": jax.__version__,
        "device": getattr(device, "device_kind", str(device)),
        "date": f"{_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC",
        "material": "NeoHookean",
        "verification": checks,
        "timings": [],
        "skipped": skipped,
    }
    for target in sorted(sizes):
        say(f"size {target:,}")
        mesh = mjed.TetMesh(*cube_with_cells(target))
        pattern = CSRPattern(mesh.cells, mesh.n_nodes)
        if checks is None:
            fig["verification"] = checks = verify(mesh, material, pattern)
            say(f"checked against mjed's NumPy engine: {checks}")
        timed = DTYPES if checks["float64"]["passed"] else ()
        _time_size(mesh, material, pattern, timed, min_time, timings, skipped)
        fig["timings"] = [asdict(t) for t in timings]
        partial(fig)
    return fig


def _project_figures(path: str) -> Dict[tuple, float]:
    """(cells, method, dtype, quantity) -> tets/s from a comparisons.timing.hardware JSON."""
    data = json.loads(open(path).read())
    gpu = data.get("gpu", data)
    out = {}
    for size in gpu.get("sizes", []):
        for t in size.get("timings", []):
            out[(size["cells"], t["method"], t["dtype"], t["quantity"])] = t["tets_per_s"]
    return out


def print_figures(fig: dict, against: Optional[str] = None, out=print) -> None:
    """One line per figure; with ``against``, the project's kernels beside it (ratio =
    their tets/s over the peer's).
    """
    out(f"JAX peer ({fig['peer']}), JAX {fig['jax']} on {fig['device']}, {fig['date']}")
    for dtype, v in (fig["verification"] or {}).items():
        out(
            f"  {dtype}: against mjed's NumPy engine force {v['force_err']:.1e}, stiffness "
            f"{v['stiffness_err']:.1e} (tolerance {v['tol']:.0e}): "
            + (
                "checked"
                if v["passed"]
                else ("outside it, timed as it is" if dtype == "float32" else "FAILED, not timed")
            )
        )
    ours = _project_figures(against) if against else {}
    for t in fig["timings"]:
        line = (
            f"  {t['cells']:>10,} tets {t['dtype']} {t['quantity']:4s} {t['best_s'] * 1e3:9.3f} ms"
            f"  {t['tets_per_s']:.3e} tets/s"
        )
        for method in ("mjed", "classical"):
            v = ours.get((t["cells"], method, t["dtype"], t["quantity"]))
            if v:
                line += f"  {method} {v / t['tets_per_s']:.1f}x"
        out(line)
    for s in fig["skipped"]:
        out(f"  skipped: {s}")


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m comparisons.timing.jax_peer", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument(
        "--sizes",
        default=",".join(str(s) for s in DEFAULT_SIZES),
        help="tets of the cubes (default 1e4 to 1e6)",
    )
    ap.add_argument("--min-time", type=float, default=0.25, help="seconds of calls per figure")
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument(
        "--against", help="a comparisons.timing.hardware --json file of the same device session"
    )
    args = ap.parse_args(argv)
    try:
        import jax
    except ImportError:
        print("not run: JAX is not installed", file=sys.stderr)
        return 3
    if jax.default_backend() != "gpu":
        print(f"not run: JAX's backend is {jax.default_backend()!r}, not a GPU", file=sys.stderr)
        return 3
    sizes = [int(float(s)) for s in args.sizes.split(",") if s]

    def write(fig: dict) -> None:
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(fig, fh, indent=1)

    say = lambda s: print(f"  {s}", file=sys.stderr, flush=True)  # noqa: E731
    fig = measure(sizes, args.min_time, say=say, partial=write)
    print_figures(fig, args.against)
    return 0 if fig["verification"]["float64"]["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
