r"""MJED itself as an engine of the exchange format, on any of its backends: what
``mjed-verify check`` judges when it checks the NumPy engine, the compiled kernel or the GPU.

One case (the ``--command`` way, one process per case)::

    mjed-verify check --command \
        'python -m conformance.adapters.mjed_backend {input} {output} --backend cuda'

A whole kit in one process (the kernels compiled once, one force field per mesh and material;
what a GPU session does, scripts/gpu_session.sh)::

    mjed-verify export kit/ --mesh cube-paper --material all --precision single
    python -m conformance.adapters.mjed_backend --kit kit/ --backend cuda --dtype float32
    mjed-verify check kit/

``--backend`` is one of mjed.backends.ALL_BACKENDS (numpy, numba, cuda; default numpy) and
``--dtype`` the arithmetic, float64 (default) or float32, which only the cuda backend offers.
A float32 field's results are written as float32 ``.f32`` files, which declare the output
single precision: the check then judges it at single precision (conformance.judge.precision). A
kit's own declaration comes first, so float32 refuses to fill a kit exported with
``--precision double`` (the default): it would be judged, and failed, at double precision. The
stiffness is written in CSR, the force field's own pattern; the energy too. The field is
built with mjed's defaults (no regularisation, inverted cells refused), as the oracle's
energies are defined.

Exit codes: 0 every case written; 1 a case could not be computed (the others are still
written, the failures named on stderr); 2 bad arguments, a kit declared double for float32,
or a backend that cannot run here (no Numba, no GPU: said so, never replaced by another
backend).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

import numpy as np

__all__ = ["MJEDBackendEngine", "main"]

DTYPES = {"float64": np.float64, "float32": np.float32}


class MJEDBackendEngine:
    """Computes cases of the exchange format with ``mjed.make_force_field(backend=...)``.

    ``engine(case)`` for a :class:`conformance.kit.spec.CaseInput` returns (force (n, 3),
    stiffness CSR (3n, 3n), energy) in float64 (a float32 field's values, exactly); one field
    is kept per mesh and material. ``precision`` is "single" for float32, else "double".

    Raises:
        ValueError: an unknown backend or dtype, or float32 asked of a CPU backend.
        mjed.compiled.BackendUnavailable: the backend cannot run here (building the first
            field finds it out; :meth:`require` asks at once).
    """

    def __init__(self, backend: str = "numpy", dtype: str = "float64"):
        from mjed.backends import ALL_BACKENDS

        if backend not in ALL_BACKENDS:
            raise ValueError(
                f"unknown backend {backend!r}; choose one of {', '.join(ALL_BACKENDS)}"
            )
        if dtype not in DTYPES:
            raise ValueError(f"unknown dtype {dtype!r}; choose float64 or float32")
        if dtype == "float32" and backend != "cuda":
            raise ValueError(
                f"the {backend} backend computes in float64 only; float32 is the cuda backend's"
            )
        self.backend = backend
        self.dtype = dtype
        self.precision = "single" if dtype == "float32" else "double"
        self._fields: Dict[Any, Any] = {}

    def require(self) -> None:
        """BackendUnavailable, saying why, when the backend cannot run on this machine."""
        if self.backend == "numba":
            from mjed.compiled import BackendUnavailable, numba_available

            if not numba_available():
                raise BackendUnavailable(
                    "the numba backend needs Numba (Debian: python3-numba; PyPI: numba)"
                )
        elif self.backend == "cuda":
            from mjed.cuda import require_cuda

            require_cuda()

    def field(self, points: np.ndarray, cells: np.ndarray, model):
        """The force field of this mesh and material (built once, then reused)."""
        from mjed.materials.base import Material

        if not isinstance(model, Material):
            raise TypeError(
                f"MJED computes the materials declared in mjed.materials; this case's model is "
                f"a {type(model).__name__} (a user energy has no MJED decomposition)"
            )
        try:
            key = (points.tobytes(), cells.tobytes(), model)
            hash(key)
        except TypeError:  # a model holding an array (a fibre frame per cell): built afresh
            return self._build(points, cells, model)
        if key not in self._fields:
            self._fields[key] = self._build(points, cells, model)
        return self._fields[key]

    def _build(self, points, cells, model):
        import mjed

        options = {"dtype": DTYPES[self.dtype]} if self.backend == "cuda" else {}
        mesh = mjed.TetMesh(points, cells)
        return mjed.make_force_field(mesh, model, backend=self.backend, **options)

    def __call__(self, case):
        field = self.field(case.points, case.cells, case.model)
        f, K = field.force_and_stiffness(case.positions)
        return f, K, field.energy(case.positions)

    def write(self, case, folder: str) -> None:
        """Compute ``case`` and write its output directory (float32 ``.f32`` files for
        float32).
        """
        from conformance.kit.exchange import write_output

        f, K, W = self(case)
        write_output(folder, f, K, W, layout="csr", precision=self.precision)


def _fill_kit(engine: MJEDBackendEngine, kit: str, say: Callable[[str], None]) -> int:
    """Write every case's output of the kit; 0, or 1 when some case failed (named)."""
    from conformance.kit.read import read_kit

    manifest = read_kit(kit)
    if engine.precision == "single" and manifest.precision == "double":
        print(
            f"mjed_backend: not run: {kit} declares double precision, and float32 results would "
            "be judged (and failed) at double precision; export the kit with --precision single",
            file=sys.stderr,
        )
        return 2
    failed: List[str] = [f"{cid}: {why}" for cid, why in manifest.errors.items()]
    clock, written = time.perf_counter(), 0
    for i, case in enumerate(manifest.cases):
        try:
            engine.write(case.input, case.output_dir)
            written += 1
        except Exception as exc:  # noqa: BLE001 - one case's failure is reported, not fatal
            failed.append(f"{case.case_id}: {type(exc).__name__}: {exc}")
        if (i + 1) % 50 == 0:
            say(f"  ... {i + 1} of {len(manifest.cases)} cases")
    seconds = time.perf_counter() - clock
    say(
        f"{kit}: {written} of {len(manifest.cases) + len(manifest.errors)} cases written by MJED "
        f"({engine.backend}, {engine.dtype}) in {seconds:.1f} s; then: mjed-verify check {kit}"
    )
    for line in failed:
        print(f"failed: {line}", file=sys.stderr)
    return 1 if failed else 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m conformance.adapters.mjed_backend",
        description="Compute conformance cases with MJED on a chosen backend (numpy, numba, "
        "cuda) and precision: one case (INPUT OUTPUT) or every case of a kit (--kit KIT).",
    )
    p.add_argument("input", nargs="?", help="a case's input directory")
    p.add_argument("output", nargs="?", help="the case's output directory (created)")
    p.add_argument("--kit", help="fill every case's output of this kit instead")
    p.add_argument("--backend", default="numpy", help="numpy (default), numba or cuda")
    p.add_argument("--dtype", default="float64", choices=tuple(DTYPES), help="cuda only: float32")
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if (args.kit is None) == (args.input is None or args.output is None):
        parser.error("give INPUT and OUTPUT (one case) or --kit KIT (every case), not both")
    from mjed.compiled import BackendUnavailable

    try:
        engine = MJEDBackendEngine(args.backend, args.dtype)
        engine.require()
    except (ValueError, BackendUnavailable) as exc:
        print(f"mjed_backend: not run: {exc}", file=sys.stderr)
        return 2
    if args.kit is not None:
        return _fill_kit(engine, args.kit, print)
    from conformance.kit.exchange import read_case_input

    try:
        engine.write(read_case_input(args.input), args.output)
    except Exception as exc:  # noqa: BLE001 - the checker quotes stderr for this case
        print(
            f"mjed_backend ({args.backend}, {args.dtype}): {type(exc).__name__}: {exc}",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
