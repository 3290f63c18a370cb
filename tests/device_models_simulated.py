"""The viscous and the porous models with their state on the device
(mjed.cuda.device_models, in mjed.cuda.integrator.DeviceImplicitEuler) against the host-built
step (mjed.integrator.ImplicitEuler with the device CG) with the same cuda force field, on
Numba's CUDA simulator; printed as JSON (tests/test_device_euler.py runs this in a
subprocess: NUMBA_ENABLE_CUDASIM must be set before Numba is first imported).

    NUMBA_ENABLE_CUDASIM=1 python tests/device_models_simulated.py
"""

from __future__ import annotations

import json
import os

import numpy as np
from cuda_support import max_relative


class _Counted:
    """A cuda field whose host calls (force, stiffness, stress) are counted: the device step
    must make none.
    """

    def __init__(self, field):
        self.field, self.host_calls = field, 0

    def __getattr__(self, name):
        return getattr(self.field, name)

    def _counted(self, name, x):
        self.host_calls += 1
        return getattr(self.field, name)(x)

    def force(self, x):
        return self._counted("force", x)

    def stiffness(self, x):
        return self._counted("stiffness", x)

    def force_and_stiffness(self, x):
        return self._counted("force_and_stiffness", x)

    def stress(self, x):
        return self._counted("stress", x)

    def force_stiffness_and_stress(self, x):
        return self._counted("force_stiffness_and_stress", x)


def _models(kind: str, mesh, field, drained):
    """Fresh host models of ``kind`` over ``field`` (a new set for each integrator: the host
    one changes its models' state).
    """
    from mjed.darcy import DarcyParameters, FluidPressureForce
    from mjed.porous import PorousVolume
    from mjed.viscous import Prony, ViscoHyperelasticForceField

    visco = ViscoHyperelasticForceField(field, prony=Prony((0.235, 0.333), (0.27, 0.03)))
    if kind == "visco":
        return [visco], None
    fluid = FluidPressureForce(
        mesh,
        DarcyParameters(K_lim=2200.0, kappa=0.05),
        solid=PorousVolume(0.5, 400.0, 2200.0),
        drained_nodes=drained,
    )
    return [visco, fluid], fluid


def _pair(kind: str, mesh, field, steps: int, drained, reference=None, **options) -> dict:
    """The host-built and the device step from the same state, each with its own models;
    with ``reference`` (an FP64 field) also the device run against the host run in FP64.
    """
    from mjed.cuda.integrator import DeviceImplicitEuler
    from mjed.integrator import ImplicitEuler

    host_models, host_fluid = _models(kind, mesh, field, drained)
    counted = _Counted(field)
    dev_models, dev_fluid = _models(kind, mesh, counted, drained)
    host = ImplicitEuler(mesh, host_models, 1.0, **options)
    dev = DeviceImplicitEuler(mesh, dev_models, 1.0, **options)
    rh, rd = host.run(steps), dev.run(steps)
    host_calls = counted.host_calls  # before sync_models, which reads nothing from the field
    # the host models keep their state until sync_models (all zero here)
    untouched = not np.any(dev_models[0].gammas) and dev_models[0].steps == 0
    if dev_fluid is not None:
        untouched = untouched and not np.any(dev_fluid.P)
    dev.sync_models()
    u = host.x - mesh.points
    out = {
        "x": max_relative(dev.x - mesh.points, u),
        "v": max_relative(dev.v, host.v),
        "reaction": max(max_relative(a.reaction, b.reaction) for a, b in zip(rd, rh)),
        "gammas": max_relative(dev_models[0].gammas, host_models[0].gammas),
        "history_steps": [dev_models[0].steps, host_models[0].steps],
        "peak": host.max_displacement(),
        "time": [dev.t, host.t],
        "cg": [[r.cg_iterations for r in rd], [r.cg_iterations for r in rh]],
        "solves": [[r.newton_iterations for r in rd], [r.newton_iterations for r in rh]],
        "substeps": [[r.substeps for r in rd], [r.substeps for r in rh]],
        "retries": [[list(r.retries) for r in rd], [list(r.retries) for r in rh]],
        "host_calls": host_calls,
        "untouched_before_sync": bool(untouched),
        "device_type": type(dev).__name__,
        "on_device": [type(a).__name__ for a in dev.device_models],
    }
    if reference is not None:
        ref_models, ref_fluid = _models(kind, mesh, reference, drained)
        ref = ImplicitEuler(mesh, ref_models, 1.0, **options)
        ref.run(steps)
        out["x_fp64"] = max_relative(dev.x - mesh.points, ref.x - mesh.points)
        if ref_fluid is not None:
            out["P_fp64"] = max_relative(dev_fluid.P, ref_fluid.P)
    if host_fluid is not None:
        out["P"] = max_relative(dev_fluid.P, host_fluid.P)
        out["P_peak"] = float(np.abs(host_fluid.P).max())
        out["J_accepted"] = max_relative(dev_fluid.J_accepted, host_fluid.J_accepted)
    return out


def _refusals(mesh, field, drained) -> dict:
    """What device_refusal says for the models that stay on the host."""
    from mjed.cuda.integrator import device_refusal
    from mjed.darcy import DarcyParameters, FluidPressureForce
    from mjed.solvers import LinearSolverOptions

    device_cg = LinearSolverOptions(solver="cuda-cg")
    visco = _models("visco", mesh, field, drained)[0]
    porous = _models("porous", mesh, field, drained)[0]
    numpy_body = _models("visco", mesh, mjed_numpy_field(mesh), drained)[0]
    odd_solid = FluidPressureForce(
        mesh, DarcyParameters(2200.0, 0.05), solid=lambda J: (0.0 * J, 0.0 * J, 0.0 * J)
    )
    return {
        name: device_refusal(models, device_cg)
        for name, models in {
            "visco": visco,
            "porous": porous,
            "numpy_body": numpy_body,
            "odd_solid": [field, odd_solid],
            "fluid_alone": [porous[1]],
        }.items()
    }


def mjed_numpy_field(mesh):
    from conftest import MATERIALS

    import mjed

    return mjed.HyperelasticForceField(mesh, MATERIALS["NeoHookean"])


def main() -> dict:
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1", "run with NUMBA_ENABLE_CUDASIM=1"
    from conftest import MATERIALS, box_mesh

    import mjed
    from mjed.solvers import LinearSolverOptions

    points, cells = box_mesh(1)  # 6 cells, 8 nodes
    mesh = mjed.TetMesh(points, cells)
    material = MATERIALS["NeoHookean"]
    field = mjed.make_force_field(mesh, material, backend="cuda")
    field32 = mjed.make_force_field(mesh, material, backend="cuda", dtype=np.float32)
    bottom = np.flatnonzero(points[:, 2] == 0.0)
    top = np.flatnonzero(points[:, 2] == 1.0)
    solver = LinearSolverOptions(solver="cuda-cg", cg_tol=1e-12)
    loaded = dict(
        dt=0.05,
        fixed_nodes=bottom,
        gravity=(0.0, 0.0, -1.0),
        external_force=lambda t: np.tile([0.4 + t, -0.2, -0.3], (mesh.n_nodes, 1)),
        rayleigh_mass=0.1,
        rayleigh_stiffness=0.01,
        solver=solver,
    )
    return {
        "visco": _pair("visco", mesh, field, 3, top, **loaded),
        "visco_fp32": _pair("visco", mesh, field32, 2, top, field, **loaded),
        "porous": _pair("porous", mesh, field, 3, top, **loaded),
        "porous_fp32": _pair("porous", mesh, field32, 2, top, field, **loaded),
        "porous_halving": _pair(
            "porous", mesh, field, 2, top, **{**loaded, "dt": 0.2, "max_volume_change": 1.05}
        ),
        "refusals": _refusals(mesh, field, top),
    }


if __name__ == "__main__":
    print(json.dumps(main()))
