"""A corpus of hard cases on which a correct engine must pass and every mistake must still fail.

    python -m conformance.corpus                 # the full corpus: prints its figure
    python -m conformance.corpus --small         # the fast subset the tests run
    python -m conformance.corpus --mutants tests/conformance_mutations.py

The meshes are those users bring: caps, slivers and wedges down to quality 1e-3 (and below),
needles and flat cells from anisotropic boxes, a graded box whose cell volumes span more than
six orders of magnitude, millimetre and SI units, and meshes read back from other tools'
formats (gmsh 2.2, VTK XML, Abaqus) through :mod:`meshes`. The states are the named ones plus
stronger seeded random fields (down to J = 0.05). The models are every material of the
registry (:data:`common.cases.DEFAULT_MATERIALS`) and user energies.

The correct engine is the project's MJED; a user energy is computed by MJED with the built-in
material whose energy the formula writes out (the oracle differentiates the formula, MJED its
own terms). The figure: how many cases a correct engine fails (false failures; 0 is the
requirement), and, with a mutation catalogue (a Python file defining ``MUTATIONS``,
``EXPECTED``, ``MATERIAL`` and ``broken_engine``), how many of its mutants are caught (failed)
and named (the expected finding) on every corpus mesh.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from common.cases import DEFAULT_MATERIALS
from common.states import apply_state, smooth_random
from conformance.kit.cases import build_cases
from conformance.run import CheckRun, run_check

__all__ = [
    "CorpusMesh",
    "corpus_meshes",
    "corpus_states",
    "corpus_models",
    "corpus_engine",
    "CorpusFigure",
    "run_corpus",
    "mutant_figure",
    "main",
]

Mesh = Tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class CorpusMesh:
    """label; points (n, 3) [the mesh's length unit]; cells (m, 4); units ("m" or "mm");
    how: how it was made (words).
    """

    label: str
    points: np.ndarray
    cells: np.ndarray
    units: str
    how: str

    def figures(self) -> Dict[str, float]:
        """Smallest quality, smallest and largest cell volume, and their ratio."""
        from meshes.hard import quality
        from meshes.tetra import signed_volumes

        V = signed_volumes(self.points, self.cells)
        return {
            "min_quality": float(quality(self.points, self.cells).min()),
            "min_volume": float(V.min()),
            "max_volume": float(V.max()),
            "volume_ratio": float(V.max() / V.min()),
        }


def _single_sliver(thickness: float) -> Mesh:
    """One sliver: the corners of a unit square, two of them lifted by ``thickness`` (quality
    about ``thickness``).
    """
    P = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, thickness], [0.0, 1.0, thickness]])
    from meshes.tetra import orient_positively

    cells, _ = orient_positively(P, np.array([[0, 1, 2, 3]]))
    return P, cells


def _read_back(folder: str, name: str, mesh: Mesh, **kw) -> Mesh:
    """Write ``mesh`` in another tool's format and read it back through meshes.read_mesh."""
    from meshes import read_mesh, write_mesh

    path = os.path.join(folder, name)
    write_mesh(path, mesh[0], mesh[1], **kw)
    data = read_mesh(path)
    return np.asarray(data.points), np.asarray(data.cells)


def corpus_meshes(small: bool = False, folder: Optional[str] = None) -> List[CorpusMesh]:
    """The hard meshes (seeded, reproducible). small: the three hardest, for the tests.

    folder: where the meshes written in other formats go (a temporary directory by default).
    """
    import meshes
    from meshes.hard import degrade, graded, stretched
    from meshes.structured import structured_box

    P, C, _ = meshes.resolve("cube-small")  # the stored gmsh Delaunay cube, 510 cells
    cap = degrade(P, C, "cap", 1e-3, seed=0)
    sliver = degrade(P, C, "sliver", 1e-3, seed=1)
    box, box_cells = structured_box(4)
    graded_box = graded(box, 4.0)
    out = [
        CorpusMesh(
            "cap-SI", cap * 0.05, C, "m", "cube-small as a 5 cm cube, one cap of quality <= 1e-3"
        ),
        CorpusMesh(
            "sliver-mm", sliver * 50.0, C, "mm", "cube-small as a 50 mm cube, one sliver <= 1e-3"
        ),
        CorpusMesh(
            "graded-SI",
            graded_box * 0.02,
            box_cells,
            "m",
            "4^3 Kuhn box of 2 cm graded by x^4 per axis: volumes over 6.7 orders",
        ),
    ]
    if small:
        return out
    folder = folder or tempfile.mkdtemp(prefix="mjed-corpus-")
    wedge = degrade(P, C, "wedge", 1e-3, seed=2)
    mixed = degrade(
        degrade(degrade(P, C, "cap", 1e-2, seed=3), C, "sliver", 1e-2, seed=4),
        C,
        "wedge",
        1e-2,
        seed=5,
    )
    needles, needle_cells = structured_box((2, 2, 6))
    flat, flat_cells = structured_box((4, 4, 1))
    one = _single_sliver(1e-3)
    out += [
        CorpusMesh("cube-SI", P * 0.05, C, "m", "cube-small as a 5 cm cube"),
        CorpusMesh(
            "wedge-SI", wedge * 0.02, C, "m", "cube-small as a 2 cm cube, one wedge <= 1e-3"
        ),
        CorpusMesh("mixed-mm", mixed * 30.0, C, "mm", "a cap, a sliver and a wedge <= 1e-2, 30 mm"),
        CorpusMesh(
            "needles-mm",
            stretched(needles, (1.0, 1.0, 30.0)) * 2.0,
            needle_cells,
            "mm",
            "2x2x6 Kuhn box stretched 30x along z: needles, quality 0.025",
        ),
        CorpusMesh(
            "flat-SI",
            stretched(flat, (1.0, 1.0, 0.005)) * 0.04,
            flat_cells,
            "m",
            "4x4x1 Kuhn box flattened to 0.5 %: flat cells",
        ),
        CorpusMesh(
            "one-sliver-SI", one[0] * 0.01, one[1], "m", "a single sliver of quality ~1e-3, 1 cm"
        ),
        CorpusMesh(
            "sliver-mm-from-msh",
            *_read_back(folder, "sliver.msh", (sliver * 50.0, C), msh_version="2.2"),
            "mm",
            "sliver-mm written as gmsh 2.2 and read back",
        ),
        CorpusMesh(
            "cap-SI-from-vtu",
            *_read_back(folder, "cap.vtu", (cap * 0.05, C)),
            "m",
            "cap-SI written as VTK XML and read back",
        ),
        CorpusMesh(
            "graded-SI-from-inp",
            *_read_back(folder, "graded.inp", (graded_box * 0.02, box_cells)),
            "m",
            "graded-SI written as Abaqus .inp and read back",
        ),
    ]
    return out


#: Largest principal stretch of any cell in the corpus's random states. A smooth field strains a
#: cap or a sliver far more than the mesh: unbounded, the exponential energies (Veronda-Westmann,
#: Costa) overflow float64 there for any engine, the oracle included. At 3, Costa's
#: exp(b_ff E_ff^2 + ...) still overflowed in 2 of 1,320 cases (the engine wrote inf) and lost
#: ten digits in a third (error 1.7e-10 on a single sliver).
STRETCH_LIMIT = 2.0


def _random(seed: int, min_J: float) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    return lambda X, cells: smooth_random(
        X, cells, seed=seed, min_J=min_J, stretch_limit=STRETCH_LIMIT
    )


def corpus_states(small: bool = False) -> List[Tuple[str, Callable]]:
    """(name, function(X, cells) -> x): the homogeneous named states, the random state and
    stronger random fields (J > 0.05), every random one with stretches up to STRETCH_LIMIT.
    """
    names = ("uniaxial",) if small else ("rest", "uniaxial", "compression", "shear", "triaxial")
    seeds = (1,) if small else (1, 2, 3, 4, 5)
    return (
        [(n, lambda X, c, n=n: apply_state(n, X, c)) for n in names]
        + [("random", _random(0, 0.2))]
        + [(f"strong-random-{s}", _random(s, 0.05)) for s in seeds]
    )


def _user_twins() -> List[Tuple[Any, Any]]:
    """(user energy, the built-in material whose energy it writes out)."""
    from reference_fem.user_energy import UserEnergy

    nh, mr, vw = (DEFAULT_MATERIALS[k] for k in ("NeoHookean", "MooneyRivlin", "VerondaWestmann"))
    return [
        (
            UserEnergy(
                "mu/2*(I1 - 3) - mu*ln(J) + lam/2*ln(J)**2",
                {"mu": nh.mu, "lam": nh.lam},
                name="user-neohookean",
            ),
            nh,
        ),
        (
            UserEnergy(
                "c1*(I1b - 3) + c2*(I2b - 3) + k0/2*ln(J)**2",
                {"c1": mr.c1, "c2": mr.c2, "k0": mr.k0},
                name="user-mooneyrivlin",
            ),
            mr,
        ),
        (
            UserEnergy(
                "c1*(exp(c2*(I1b - 3)) - 1) - c1*c2/2*(I2b - 3) + k0/2*ln(J)**2",
                {"c1": vw.c1, "c2": vw.c2, "k0": vw.k0},
                name="user-verondawestmann",
            ),
            vw,
        ),
    ]


def corpus_models(small: bool = False) -> List[Any]:
    """Every material of the registry, then the user energies (one in the small corpus)."""
    users = [u for u, _ in _user_twins()]
    return list(DEFAULT_MATERIALS.values()) + (users[-1:] if small else users)


def corpus_engine() -> Callable:
    """The correct engine: MJED; a user energy through its built-in twin."""
    import mjed

    twins = {u.name: m for u, m in _user_twins()}

    def engine(case):
        model = twins.get(getattr(case.model, "name", None), case.model)
        field = mjed.HyperelasticForceField(mjed.TetMesh(case.points, case.cells), model)
        f, K = field.force_and_stiffness(case.positions)
        return f, K.copy(), field.energy(case.positions)

    return engine


@dataclass(frozen=True)
class CorpusFigure:
    """n_cases; false: (case id, reason) of every case a correct engine did not pass; worst_excess:
    the largest self-consistency excess over the oracle; worst_floor: the largest floor;
    worst_error: the largest relative force or stiffness error; seconds.
    """

    n_cases: int
    false: Tuple[Tuple[str, str], ...]
    worst_excess: float
    worst_floor: float
    worst_error: float
    seconds: float

    def text(self) -> str:
        lines = [
            f"corpus: {len(self.false)} false failures over {self.n_cases} cases of a correct "
            f"engine (worst relative error {self.worst_error:.1e}; self-consistency: largest "
            f"floor of the fit {self.worst_floor:.1e}, largest excess over it "
            f"{self.worst_excess:.1e}; {self.seconds:.0f} s)"
        ]
        lines += [f"  FALSE FAILURE {cid}: {why}" for cid, why in self.false]
        return "\n".join(lines)


def _engine_evaluator(impl):
    from conformance.protocol import python_evaluator

    return python_evaluator(impl)


def run_corpus(
    meshes_: Sequence[CorpusMesh],
    states,
    models,
    impl,
    *,
    probes: int = 4,
    progress: Optional[Callable[[str], None]] = None,
) -> Tuple[CorpusFigure, CheckRun]:
    """Check ``impl`` (a correct engine) on every mesh x model x state; every case not passed is
    a false failure.
    """
    t0 = time.perf_counter()
    cases = build_cases(
        models, [(m.label, m.points, m.cells) for m in meshes_], states, probes=probes
    )
    run = run_check(cases, _engine_evaluator(impl), progress=progress)
    false, excess, floor, error = [], 0.0, 0.0, 0.0
    for o in run.outcomes:
        d = o.diagnosis
        if o.status != "passed":
            first = d.findings[0].text() if d is not None and d.findings else o.message
            false.append((o.case_id, first[:300]))
        if d is not None:
            error = max(error, d.errors.force, d.errors.stiffness)
            c = d.consistency
            if c is not None and c.stiffness_excess is not None:
                excess, floor = max(excess, c.stiffness_excess), max(floor, c.stiffness_floor)
    return CorpusFigure(
        len(run.outcomes), tuple(false), excess, floor, error, time.perf_counter() - t0
    ), run


def load_catalogue(path: str):
    """A mutation catalogue module from a file (MUTATIONS, EXPECTED, MATERIAL, broken_engine)."""
    spec = importlib.util.spec_from_file_location("mutation_catalogue", path)
    if spec is None or spec.loader is None or not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such mutation catalogue (a Python file)")
    sys.path.insert(0, os.path.dirname(os.path.abspath(path)))
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the file runs
    spec.loader.exec_module(module)
    for name in ("MUTATIONS", "EXPECTED", "MATERIAL", "broken_engine"):
        if not hasattr(module, name):
            raise ValueError(f"{path}: a mutation catalogue defines {name}")
    return module


def mutant_figure(
    catalogue,
    meshes_: Sequence[CorpusMesh],
    state: Tuple[str, Callable],
    progress: Optional[Callable[[str], None]] = None,
    read_causes: bool = True,
) -> Dict[str, Dict[str, List[str]]]:
    """For each mutant: {"missed": meshes where it passed, "unnamed": meshes where it failed
    without the expected finding}. The catalogue's "none" (the correct engine) is left out.

    read_causes: False judges only (no diagnosis of the failed cases); "unnamed" is then left
    out of each mutant's entry rather than claimed empty.
    """
    from conformance.judge.oracle import OracleCache

    out: Dict[str, Dict[str, List[str]]] = {}
    # Every mutant is checked on the same material, meshes and state: one cache of oracles
    # (the reference and the diagnosis's candidate energies) serves them all.
    cache = OracleCache()
    for name, expected in catalogue.EXPECTED.items():
        if expected is None:
            continue
        cases = build_cases(
            [catalogue.MATERIAL], [(m.label, m.points, m.cells) for m in meshes_], [state]
        )
        run = run_check(
            cases,
            _engine_evaluator(catalogue.broken_engine(name)),
            progress=progress,
            cache=cache,
            read_causes=read_causes,
        )
        out[name] = {"missed": [o.mesh for o in run.outcomes if o.status == "passed"]}
        if read_causes:
            out[name]["unnamed"] = [
                o.mesh for o in run.outcomes if o.status != "passed" and not _named(o, expected)
            ]
    return out


def _named(outcome, expected: str) -> bool:
    d = outcome.diagnosis
    return d is not None and any(f.code == expected for f in d.findings)


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m conformance.corpus", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--small", action="store_true", help="the fast subset of the tests")
    p.add_argument(
        "--mutants",
        metavar="FILE",
        help="a mutation catalogue, e.g. tests/conformance_mutations.py",
    )
    a = p.parse_args(argv)
    import logging

    logging.disable(logging.INFO)  # FFCx logs every compilation
    from common.progress import Progress

    meshes_ = corpus_meshes(small=a.small)
    for m in meshes_:
        f = m.figures()
        print(
            f"mesh {m.label}: {len(m.cells)} cells, quality >= {f['min_quality']:.1e}, volumes "
            f"{f['min_volume']:.1e}..{f['max_volume']:.1e} {m.units}^3 ({m.how})"
        )
    states, models = corpus_states(a.small), corpus_models(a.small)
    bar = Progress(len(meshes_) * len(states) * len(models), "corpus")
    figure, _ = run_corpus(meshes_, states, models, corpus_engine(), progress=bar.advance)
    bar.close()
    print(figure.text())
    ok = not figure.false
    if a.mutants:
        catalogue = load_catalogue(a.mutants)
        mutants = mutant_figure(catalogue, meshes_, corpus_states(True)[-1])
        caught = [k for k, v in mutants.items() if not v["missed"]]
        named = [k for k, v in mutants.items() if not v["missed"] and not v["unnamed"]]
        print(
            f"mutants: {len(caught)} of {len(mutants)} caught on every corpus mesh, "
            f"{len(named)} of "
            f"{len(mutants)} named there ({len(meshes_)} meshes, state strong-random-1)"
        )
        for k, v in mutants.items():
            if v["missed"] or v["unnamed"]:
                print(
                    f"  {k}: missed on {', '.join(v['missed']) or '-'}; not named on "
                    f"{', '.join(v['unnamed']) or '-'}"
                )
        ok = ok and len(caught) == len(mutants)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
