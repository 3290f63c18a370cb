"""The device-resident implicit Euler step (mjed.cuda.integrator.DeviceImplicitEuler) against
the host-built one (mjed.integrator.ImplicitEuler with the device CG) with the same cuda
force field, on Numba's CUDA simulator; printed as JSON (tests/test_device_euler.py runs this
in a subprocess: NUMBA_ENABLE_CUDASIM must be set before Numba is first imported).

    NUMBA_ENABLE_CUDASIM=1 python tests/device_euler_simulated.py
"""

from __future__ import annotations

import json
import os

import numpy as np
from cuda_support import max_relative


class _Counted:
    """A cuda field whose host force_and_stiffness calls are counted (the device step must
    make none).
    """

    def __init__(self, field):
        self.field, self.host_calls = field, 0

    def __getattr__(self, name):
        return getattr(self.field, name)

    def force_and_stiffness(self, x):
        self.host_calls += 1
        return self.field.force_and_stiffness(x)


def _pair(mesh, field, steps: int, **options) -> dict:
    """Run the host-built and the device step from the same state; compare."""
    from mjed.cuda.integrator import DeviceImplicitEuler
    from mjed.integrator import ImplicitEuler

    host = ImplicitEuler(mesh, field, 1.0, **options)
    counted = _Counted(field)
    dev = DeviceImplicitEuler(mesh, counted, 1.0, **options)
    rh, rd = host.run(steps), dev.run(steps)
    u = host.x - mesh.points
    return {
        "x": max_relative(dev.x - mesh.points, u),
        "v": max_relative(dev.v, host.v),
        "reaction": max(max_relative(a.reaction, b.reaction) for a, b in zip(rd, rh)),
        "max_displacement": abs(dev.max_displacement() - host.max_displacement())
        / host.max_displacement(),
        "peak": host.max_displacement(),
        "time": [dev.t, host.t],
        "cg": [[r.cg_iterations for r in rd], [r.cg_iterations for r in rh]],
        "solves": [[r.newton_iterations for r in rd], [r.newton_iterations for r in rh]],
        "newton_residual": [[r.newton_residual for r in rd], [r.newton_residual for r in rh]],
        "substeps": [[r.substeps for r in rd], [r.substeps for r in rh]],
        "retries": [[list(r.retries) for r in rd], [list(r.retries) for r in rh]],
        "host_calls": counted.host_calls,
        "device_type": type(dev).__name__,
    }


def _failure(mesh, field, **options) -> dict:
    """A step that fails at every substep: the same error on both, the state kept."""
    from mjed.cuda.integrator import DeviceImplicitEuler
    from mjed.errors import IntegrationError
    from mjed.integrator import ImplicitEuler

    out = {}
    for name, cls in (("host", ImplicitEuler), ("device", DeviceImplicitEuler)):
        integ = cls(mesh, field, 1.0, **options)
        integ.run(1)
        before = (integ.x.copy(), integ.v.copy(), integ.t, integ.steps)
        integ.external_force = lambda t: np.tile([0.0, 0.0, -1e4], (mesh.n_nodes, 1))
        try:
            integ.step()
            out[name] = {"error": None}
            continue
        except IntegrationError as exc:
            error = {"reason": exc.reason, "message": str(exc)}
        error["kept"] = bool(
            np.array_equal(integ.x, before[0])
            and np.array_equal(integ.v, before[1])
            and (integ.t, integ.steps) == before[2:]
        )
        integ.external_force = None  # the integrator goes on from the kept state
        integ.run(1)
        error["after"] = integ.x.tolist()
        out[name] = error
    out["after"] = max_relative(
        np.array(out["device"].pop("after")) - mesh.points,
        np.array(out["host"].pop("after")) - mesh.points,
    )
    return out


def _fallback(mesh, field) -> dict:
    """Which integrator implicit_euler gives, and why the host one."""
    from conftest import MATERIALS

    import mjed
    from mjed.cuda.integrator import device_refusal, implicit_euler
    from mjed.solvers import LinearSolverOptions
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    visco = ViscoHyperelasticForceField(field, prony=Prony((0.3,), (0.1,)))
    numpy_body = mjed.HyperelasticForceField(field.mesh, MATERIALS["NeoHookean"])
    visco_numpy = ViscoHyperelasticForceField(numpy_body, prony=Prony((0.3,), (0.1,)))
    device_cg = LinearSolverOptions(solver="cuda-cg")
    cases = {
        "cuda": (field, device_cg),
        "visco": (visco, device_cg),
        "visco_numpy": (visco_numpy, device_cg),
        "host_cg": (field, LinearSolverOptions()),
        "two_models": ([field, field], device_cg),
    }
    return {
        name: {
            "type": type(implicit_euler(mesh, models, 1.0, dt=0.05, solver=solver)).__name__,
            "refusal": device_refusal(models, solver),
        }
        for name, (models, solver) in cases.items()
    }


def main() -> dict:
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1", "run with NUMBA_ENABLE_CUDASIM=1"
    from conftest import MATERIALS, box_mesh

    import mjed
    from mjed.integrator import Prescribed
    from mjed.solvers import LinearSolverOptions

    points, cells = box_mesh(1)  # 6 cells, 8 nodes
    mesh = mjed.TetMesh(points, cells)
    material = MATERIALS["NeoHookean"]
    field = mjed.make_force_field(mesh, material, backend="cuda")
    field32 = mjed.make_force_field(mesh, material, backend="cuda", dtype=np.float32)
    bottom = np.flatnonzero(points[:, 2] == 0.0)
    corner = np.flatnonzero((points[:, 2] == 1.0) & (points[:, 0] == 1.0))  # two top nodes
    solver = LinearSolverOptions(solver="cuda-cg", cg_tol=1e-12)
    loaded = dict(
        dt=0.05,
        fixed_nodes=bottom,
        gravity=(0.0, 0.0, -1.0),
        external_force=lambda t: np.tile([0.4 + t, -0.2, 0.1], (mesh.n_nodes, 1)),
        rayleigh_mass=0.1,
        rayleigh_stiffness=0.01,
        solver=solver,
    )
    pulled = Prescribed(corner, lambda t: np.tile([0.2 * t, 0.0, 0.5 * t], (len(corner), 1)))
    return {
        "hyperelastic": _pair(mesh, field, 3, **loaded),
        "fp32": _pair(mesh, field32, 2, **loaded),
        "prescribed_newton": _pair(
            mesh,
            field,
            2,
            dt=0.1,
            mass="consistent",
            fixed_nodes=bottom,
            prescribed=pulled,
            newton_iterations=4,
            newton_tol=1e-9,
            solver=solver,
        ),
        "halving": _pair(mesh, field, 2, **{**loaded, "dt": 0.2, "max_volume_change": 1.05}),
        "failure": _failure(mesh, field, **{**loaded, "max_halvings": 1, "max_volume_change": 1.1}),
        "fallback": _fallback(mesh, field),
    }


if __name__ == "__main__":
    print(json.dumps(main()))
