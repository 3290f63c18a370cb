"""The studies of the report, in the order they appear, each turned into report blocks.

Each ``_run_*`` function calls the same Python function as its subcommand, so the report and
the command line cannot drift apart, and returns a StudyResult (payload for results.json,
blocks for the page, pass/fail).
"""

from __future__ import annotations

from typing import List

from comparisons.blocks import Figure, Paragraph, Preformatted, Table
from comparisons.report.runner import Study, StudyContext, StudyResult

__all__ = ["all_studies"]


def _with_status(ctx: StudyContext, label: str, study, *args, **kwargs):
    """Run ``study(*args, progress=..., **kwargs)`` with a status line (terminal only)."""
    status = ctx.status(label)
    try:
        return study(*args, progress=status, **kwargs)
    finally:
        status.close()


# ----------------------------------------------------------------------------- equivalence
def _run_equivalence(ctx: StudyContext) -> StudyResult:
    from comparisons.closed_form import uniaxial_checks
    from comparisons.equivalence import run_cases
    from comparisons.progress import Progress

    bar = Progress(len(ctx.meshes) * len(ctx.materials), "equivalence", enabled=None if ctx.show_progress else False)
    results = list(run_cases(ctx.meshes, ctx.materials, ctx.states, progress=lambda msg: bar.advance(msg)))
    bar.close()
    cases = [r.to_dict() for r in results]
    rows = [(r.material, r.mesh, r.state, r.n_cells, r.force_rel_err, r.stiffness_rel_err, r.symmetry_err, r.passed)
            for r in results]
    blocks: List = [Table(("material", "mesh", "state", "cells", "force error", "stiffness error", "symmetry", "verdict"), rows,
                          caption="Relative errors of MJED against the UFL oracle (tolerance 1e-10 force and stiffness, 1e-12 symmetry)")]
    cubes = [m for m in ctx.meshes if m[0].startswith("cube")]
    uniaxial = []
    if cubes:
        label, points, cells = cubes[-1]
        uniaxial = uniaxial_checks(ctx.materials, label, points, cells)
        blocks.append(Paragraph(
            f"Uniaxial stress closed form on {label}: the cube is given the homogeneous stretch that frees its sides "
            "(lateral stretch from the analytic principal Cauchy stresses of our compressible energies); MJED's reaction "
            "on the loaded face over the current area must equal the analytic sigma_11, with no reaction on the sides."))
        blocks.append(Table(("material", "stretch", "lateral stretch", "sigma analytic (Pa)", "sigma MJED (Pa)", "rel. error",
                             "side reaction", "verdict"),
                            [(u["material"], u["stretch"], u["lateral_stretch"], u["sigma_analytic"], u["sigma_mjed"], u["rel_err"],
                              u["lateral_reaction_rel"], u["passed"]) for u in uniaxial]))
    n_fail = sum(not c["passed"] for c in cases) + sum(not u["passed"] for u in uniaxial)
    blocks.insert(0, _equivalence_digest(cases))
    headline = (f"{sum(c['passed'] for c in cases)}/{len(cases)} cases pass; worst force error "
                f"{max(c['force_rel_err'] for c in cases):.1e}, stiffness {max(c['stiffness_rel_err'] for c in cases):.1e}")
    if uniaxial:
        headline += (f"; uniaxial closed form {sum(u['passed'] for u in uniaxial)}/{len(uniaxial)}, "
                     f"worst {max(u['rel_err'] for u in uniaxial):.1e}")
    return StudyResult({"cases": cases, "uniaxial_closed_form": uniaxial}, blocks, passed=n_fail == 0,
                       message="" if n_fail == 0 else f"{n_fail} check(s) failed", headline=headline)


def _equivalence_digest(cases: list) -> Table:
    """Worst errors per material and mesh: the full table follows."""
    keys = list(dict.fromkeys((c["material"], c["mesh"]) for c in cases))
    rows = []
    for material, mesh in keys:
        cs = [c for c in cases if c["material"] == material and c["mesh"] == mesh]
        rows.append((material, mesh, cs[0]["n_cells"], len(cs), max(c["force_rel_err"] for c in cs),
                     max(c["stiffness_rel_err"] for c in cs), all(c["passed"] for c in cs)))
    return Table(("material", "mesh", "cells", "states", "worst force error", "worst stiffness error", "verdict"), rows,
                 caption="Worst relative errors over the states, per material and mesh")


# ----------------------------------------------------------------------------- timing
def _targets_table(targets: list) -> Table:
    return Table(("target", "material", "measured", "required", "verdict"),
                 [(t["target"], t.get("material", ""), t["measured"], t["required"], _target_verdict(t)) for t in targets],
                 caption="The speed targets of the timing study (ratios are medians of per-repeat ratios)")


def _target_verdict(t: dict) -> str:
    if t["measured"] is None:
        return "not measured (this run's sizes do not span the range)"
    return "met" if t["met"] else "MISSED"


def _missed(targets: list) -> list:
    return [t for t in targets if t["measured"] is not None and not t["met"]]


def _run_timing(ctx: StudyContext) -> StudyResult:
    from comparisons.timing import run_timing

    names = [m.name for m in ctx.materials]
    res = _with_status(ctx, "timing", run_timing, names, "cube-small" if ctx.quick else "cube-paper",
                       out_dir=ctx.figure_path("timing"), quick=ctx.quick)
    med = {(r["material"], r["method"], r["what"]): r["median_s"] for r in res["results"]}
    ratio = {(r["material"], r["ratio"], r["what"]): r for r in res["ratios"]}
    methods = res["settings"]["methods"]
    rows = []
    for name in names:
        for what in ("force+stiffness", "force", "stiffness"):
            row = [name, what] + [1e3 * med[(name, m, what)] if (name, m, what) in med else None for m in methods]
            for other in ("classical", "dolfinx"):
                r = ratio.get((name, f"{other}/mjed", what))
                row.append(f"{r['median']:.2f} ({r['min']:.2f}-{r['max']:.2f})" if r else "")
            rows.append(row)
    mesh = res["mesh"]
    blocks = [Figure(ctx.relative(p), "Force + stiffness assembly time per material and method, in the style of the paper's Fig. 2")
              for p in res["figures"]]
    blocks.append(Paragraph(
        f"Mesh {mesh['name']}: {mesh['n_cells']} cells, {mesh['n_nodes']} nodes; each time is the mean of "
        f"{res['settings']['iterations']} calls, median over {res['settings']['repeats']} interleaved repeats; ratios are "
        "formed per repeat (median, then the range). Measured on the machine of the provenance section."))
    blocks.append(Table(("material", "what", *[f"{m} (ms)" for m in methods], "classical/mjed", "dolfinx/mjed"), rows))
    if res.get("targets"):
        blocks.append(_targets_table(res["targets"]))
    if res.get("memory"):
        blocks.append(Table(("material", "method", "peak memory (MiB)"),
                            [(m["material"], m["method"], (m.get("peak_bytes") or 0) / 2**20 if not m.get("error") else m["error"])
                             for m in res["memory"]], caption=res.get("memory_note", "")))
    missed = _missed(res.get("targets", []))
    note = f"{len(missed)} speed target(s) missed (see the table)" if missed else ""
    fk = [r for r in res["ratios"] if r["what"] == "force+stiffness"]
    parts = []
    for other in ("classical", "dolfinx"):
        vals = [r["median"] for r in fk if r["ratio"] == f"{other}/mjed"]
        if vals:
            parts.append(f"{other}/mjed {min(vals):.2f} to {max(vals):.2f}")
    headline = f"force+stiffness on {mesh['name']}: " + ", ".join(parts) if parts else ""
    return StudyResult(res, blocks, passed=True, message=note, headline=headline)


def _run_scaling(ctx: StudyContext) -> StudyResult:
    from comparisons.timing import run_scaling

    res = _with_status(ctx, "scaling", run_scaling, quick=ctx.quick, out_dir=ctx.figure_path("scaling"))
    blocks = [Figure(ctx.relative(p), "Time and peak memory per cell against mesh size (log axes)") for p in res["figures"]]
    blocks.append(Table(("method", "cells", "nodes", "f+K (s)", "us per cell", "peak MiB", "bytes per cell"),
                        [(r["method"], r["n_cells"], r["n_nodes"], r["seconds"], 1e6 * r["seconds_per_cell"],
                          r["peak_bytes"] / 2**20, r["peak_bytes_per_cell"]) for r in res["rows"]],
                        caption=f"{res['material']} on {res['settings']['mesh']}"))
    blocks.append(Table(("method", "how far it went"), sorted(res["stopped"].items())))
    if res.get("targets"):
        blocks.append(_targets_table(res["targets"]))
    missed = _missed(res.get("targets", []))
    per = [1e6 * r["seconds_per_cell"] for r in res["rows"] if r["method"] == "mjed"]
    top = max((r["n_cells"] for r in res["rows"]), default=0)
    headline = f"mjed {min(per):.2f} to {max(per):.2f} us per cell up to {top:,} cells" if per else ""
    return StudyResult(res, blocks, passed=True, message=f"{len(missed)} flatness target(s) missed" if missed else "",
                       headline=headline)


# ----------------------------------------------------------------------------- regularisation
def _run_regularization(ctx: StudyContext) -> StudyResult:
    import meshes
    import mjed
    from comparisons.regularization import run_study

    points, cells, label = meshes.resolve("cube-small")
    mesh = mjed.TetMesh(points, cells)
    out = [run_study(mesh, m) for m in ctx.materials]
    rows = []
    for o in out:
        for tag, neg, solve in (("off", o.negative_eigenvalues_off, o.solve_off), ("on", o.negative_eigenvalues_on, o.solve_on)):
            rows.append((o.material, tag, neg, "solved" if solve.converged else "failed", solve.newton_iterations,
                         solve.cg_iterations, solve.message if not solve.converged else ""))
    blocks = [Table(("material", "regularise", "negative eigenvalues", "static solve", "Newton its", "CG its", "why it failed"), rows,
                    caption=f"{label}, compressed to half its height")]
    cleared = sum(o.negative_eigenvalues_off > 0 and o.negative_eigenvalues_on == 0 for o in out)
    solved_on = sum(o.solve_on.converged for o in out)
    solved_off = sum(o.solve_off.converged for o in out)
    headline = (f"negative eigenvalues removed for {cleared}/{len(out)} materials; static solve succeeds for "
                f"{solved_on}/{len(out)} with it, {solved_off}/{len(out)} without")
    return StudyResult({"mesh": label, "results": [o.to_dict() for o in out]}, blocks, headline=headline)


# ----------------------------------------------------------------------------- Ogden tangent
def _run_ogden_tangent(ctx: StudyContext) -> StudyResult:
    from dataclasses import replace

    import mjed
    from comparisons.cases import DEFAULT_MATERIALS
    from comparisons.ogden_tangent import sofa_tangent_errors

    ogden = next((m for m in ctx.materials if type(m).__name__ == "Ogden"), DEFAULT_MATERIALS["Ogden"])
    rows, payload = [], {}
    for alpha in (ogden.alpha, -2.0, 6.0):
        material = replace(ogden, alpha=alpha)
        for label, points, cells in ctx.meshes[:2]:
            errs = sofa_tangent_errors(mjed.TetMesh(points, cells), material, ctx.states)
            payload[f"{label}, alpha={alpha:g}"] = errs
            rows.append((label, alpha, *(errs[s] for s in ctx.states)))
    blocks = [Table(("mesh", "alpha", *ctx.states), rows,
                    caption="||K_sofa - K_exact||_F / ||K_exact||_F: SOFA's coaxial Ogden tangent against the exact Hessian"),
              Paragraph("Forces are identical; only the stiffness differs. Zero at rest, where C = I commutes with every "
                        "perturbation; a few 1e-4 in the deformed states. Enough to slow Newton's convergence from quadratic "
                        "to linear, not enough to change a converged answer.")]
    worst = max(max(e.values()) for e in payload.values())
    return StudyResult(payload, blocks, headline=f"largest relative stiffness difference {worst:.1e}")


# ----------------------------------------------------------------------------- rheometer
def _run_rheometer(ctx: StudyContext) -> StudyResult:
    from comparisons.commands.dma import DISCRETE_TOL
    from comparisons.rheometer import run_rheometer

    res = _with_status(ctx, "rheometer", run_rheometer, quick=ctx.quick, out=ctx.figure_path("rheometer"))
    spec, e = res["spec"], res["errors"]
    rows = [(f["frequency_hz"], f["omega"], f["G_storage"], f["continuous"][0], f["discrete"][0], f["G_loss"],
             f["continuous"][1], f["discrete"][1], max(f["rel_err_discrete"])) for f in res["frequencies"]]
    blocks = [Figure(ctx.relative(p), "G' and G'' of the simulated rheometer (markers) against the continuous generalised "
                     "Maxwell moduli and the exact backward-Euler response (lines), as in the paper's Fig. 3") for p in res["figures"]]
    blocks += [
        Paragraph(f"Cylinder {2e3 * spec['radius']:g} mm across and {1e3 * spec['height']:g} mm high "
                  f"({res['mesh']['n_cells']} cells), lower face clamped, upper face twisted by {spec['amplitude']:g} rad; "
                  f"St Venant-Kirchhoff G0 = {spec['G0']:g} Pa with Prony alphas {spec['alphas']} and taus {spec['taus']} s; "
                  f"{spec['samples_per_period']} backward-Euler steps per period."),
        Table(("reference", "mean relative error", "max relative error"),
              [("continuous generalised Maxwell", e["continuous"]["mean"], e["continuous"]["max"]),
               ("exact discrete (backward Euler)", e["discrete"]["mean"], e["discrete"]["max"])],
              caption=f"Pass criterion: max error against the exact discrete response <= {DISCRETE_TOL:g}. The gap to the "
                      "continuous moduli is the time step's own error (the paper reports 5 % against experiment)."),
        Table(("f (Hz)", "omega (rad/s)", "G' (Pa)", "G' Maxwell", "G' discrete", "G'' (Pa)", "G'' Maxwell", "G'' discrete",
               "error vs discrete"), rows),
    ]
    ok = e["discrete"]["max"] <= DISCRETE_TOL
    headline = (f"against Maxwell mean {100 * e['continuous']['mean']:.1f} %, max {100 * e['continuous']['max']:.1f} %; "
                f"against the exact discrete response max {e['discrete']['max']:.1e}")
    return StudyResult(res, blocks, passed=ok, headline=headline, message="" if ok else
                       f"max error against the discrete response {e['discrete']['max']:.1e} > {DISCRETE_TOL:g}")


# ----------------------------------------------------------------------------- liver
_LIVER_CAPTIONS = {
    "fig1_left_porous_stress": "Fig. 1 left: porous volumetric stress sigma(J) before and after the tangent substitution below J0",
    "fig1_right_pressure": "Fig. 1 right: fluid pressure in the liver at the time of its largest magnitude",
    "fig4_max_displacement": "Fig. 4: maximum displacement amplitude over time for the three models",
    "terzaghi": "Terzaghi consolidation: the pressure solver against the series solution",
}


def _run_liver(ctx: StudyContext) -> StudyResult:
    import os

    from comparisons.liver import run_liver

    res = _with_status(ctx, "liver", run_liver, quick=ctx.quick, out=ctx.figure_path("liver"), series=not ctx.quick)
    blocks: List = []
    for path in res["figures"]:
        stem = os.path.splitext(os.path.basename(path))[0]
        blocks.append(Figure(ctx.relative(path), _LIVER_CAPTIONS.get(stem, stem)))
    blocks.append(Paragraph(
        f"Mesh {res['mesh']} ({res['n_nodes']} nodes, {res['n_cells']} tetrahedra), {res['n_fixed']} fixed nodes "
        f"({'; '.join(res['fixed_regions'])}), gravity, {res['duration']:g} s simulated. Frames per second are time steps "
        "per wall-clock second of stepping (assembly + CG), on this machine."))
    blocks.append(Table(("model", "dt (s)", "steps", "mean CG its", "final max |u| (m)", "FPS", "paper FPS", "target", "error"),
                        [(r["model"], r["dt"], r["steps"], r["cg_iterations_mean"], r["final_max_displacement"], r["fps"],
                          r["paper_fps"], "met" if t["meets_target"] else "missed", r["error"] or "")
                         for r, t in zip(res["runs"], res["fps_table"])],
                        caption=f"Target: {res['fps_table'][0]['target_fps']} FPS (interactive rate)" if res["fps_table"] else ""))
    tz = res["terzaghi"]
    blocks.append(Table(("Terzaghi time factor", "relative L2 pressure error"),
                        [(t["T_v"], t["relative_l2_error"]) for t in tz["times"]]))
    if res.get("series"):
        blocks.append(Paragraph("ParaView time series (displacement, J, pressure): "
                                + ", ".join(ctx.relative(p) for p in res["series"])))
    failed = [r for r in res["runs"] if r["error"]]
    message = "; ".join(f"{r['model']}: {r['error']}" for r in failed)
    fps = ", ".join(f"{t['model']} {t['fps']:.0f}" for t in res["fps_table"] if t["fps"] is not None)
    headline = (f"FPS on {res['mesh']}: {fps} (paper 7.5 / 7 / 6; target {res['fps_table'][0]['target_fps']:g})"
                if res["fps_table"] else "")
    return StudyResult(res, blocks, passed=bool(res["passed"]), message=message if not res["passed"] else "",
                       headline=headline)


# ----------------------------------------------------------------------------- provenance
def _run_cross_release(ctx: StudyContext) -> StudyResult:
    import os

    from comparisons.cross_release import REPO, cross_release_check, format_check

    modern = REPO / ".venv-modern" / "bin" / "python"
    res = cross_release_check(quick=True)
    rows = [(s["label"], s["ranks"], s["versions"].get("dolfinx"), s["versions"].get("ufl"), s["versions"].get("petsc"),
             s["versions"].get("numpy"), s["versions"].get("python"), s["seconds"]) for s in res["stacks"]]
    blocks = [Table(("stack", "ranks", "dolfinx", "ufl", "petsc", "numpy", "python", "seconds"), rows),
              Table(("against " + str(res["reference"]), "energy", "force", "stiffness", "verdict"),
                    [(c["label"], c["energy_rel_diff"], c["force_rel_diff"], c["stiffness_rel_diff"], c["passed"])
                     for c in res["comparisons"]],
                    caption=f"Relative differences of the oracle's results (tolerance {res['tolerance']:g})"),
              Preformatted(format_check(res))]
    if not os.path.exists(modern):
        return StudyResult(res, blocks, passed=res["passed"], message="the modern dolfinx stack is not installed here "
                           "(make test-modern installs it); only the Debian stack, serial against 2 ranks, was compared")
    worst = max((max(c["energy_rel_diff"], c["force_rel_diff"], c["stiffness_rel_diff"]) for c in res["comparisons"]),
                default=float("nan"))
    headline = f"{len(res['stacks'])} stacks; largest relative difference {worst:.1e}"
    return StudyResult(res, blocks, passed=res["passed"], headline=headline,
                       message="" if res["passed"] else "the stacks disagree or one failed")


def _run_provenance(ctx: StudyContext) -> StudyResult:
    from comparisons.provenance import provenance

    info = provenance()
    try:
        from reference_fem import compat

        info["oracle_stack"] = compat.stack_versions()
    except Exception as exc:  # dolfinx missing: say so, the rest of the record stands
        info["oracle_stack"] = f"unavailable: {type(exc).__name__}: {exc}"
    return StudyResult(info, [Table(("item", "value"), _flat_rows(info))],
                       headline=f"{info.get('cpu')}, {info.get('usable_cores')} cores; commit {str(info.get('git_commit'))[:10]}")


def _flat_rows(info: dict, prefix: str = "") -> list:
    """Nested records as (dotted key, readable value) rows; booleans as yes/no, not pass/FAIL."""
    rows = []
    for k, v in info.items():
        if isinstance(v, dict):
            rows += _flat_rows(v, f"{prefix}{k}.")
        elif isinstance(v, bool):
            rows.append((prefix + k, "yes" if v else "no"))
        else:
            rows.append((prefix + k, "not available" if v is None else str(v).replace("\x00", "").strip()))
    return rows


def all_studies(quick: bool) -> List[Study]:
    """The report's studies in order (the verdict section is added by the runner)."""
    q = " --quick" if quick else ""
    return [
        Study("equivalence", "Equivalence: MJED against the UFL oracle",
              "Every material on every mesh and deformation state: nodal forces and tangent stiffness of MJED against "
              "the UFL Galerkin oracle, plus the uniaxial closed form.",
              "mjed-verify equivalence --material all --mesh all --json eq.json", _run_equivalence),
        Study("timing", "Timing: MJED, classical FEM and dolfinx (paper Fig. 2)",
              "Force and stiffness assembly time per material for MJED, the classical Galerkin comparator (S and the "
              "elasticity tensor, the paper's standard FEM) and dolfinx's compiled assembly, with the ratios and targets.",
              f"mjed-verify timing{q} --json timing.json", _run_timing),
        Study("scaling", "Scaling from 1e3 to 1e6 cells",
              "Force + stiffness time and peak memory per cell on structured cubes of growing size, for the three methods.",
              f"mjed-verify timing --scaling{q}", _run_scaling),
        Study("regularization", "Compressed-element regularisation (paper section 2.3)",
              "Negative eigenvalues of K with the cube at half its height, and whether a static Newton + CG solve "
              "succeeds, with and without the regularisation.",
              "mjed-verify regularization --json reg.json", _run_regularization),
        Study("ogden_tangent", "Ogden: SOFA's approximate tangent against the exact one",
              "How far the coaxial approximation of SOFA's MJED Ogden stiffness is from the exact Hessian.",
              "mjed-verify equivalence --material Ogden", _run_ogden_tangent),
        Study("rheometer", "Rheometer frequency sweep (paper Fig. 3)",
              "A simulated rheometer twists a visco-hyperelastic cylinder sinusoidally; the storage and loss moduli fitted "
              "from the torque are compared with the generalised Maxwell model and with the exact response of the "
              "backward-Euler Prony recursion.",
              f"mjed-verify dma{q} --json dma.json", _run_rheometer),
        Study("liver", "The liver under gravity (paper Fig. 1 and Fig. 4)",
              "A liver-shaped organ hanging from the vena cava and the suspensive ligament, simulated with implicit Euler "
              "and CG as hyperelastic, visco-hyperelastic and visco-poro-hyperelastic; displacement over time, the fluid "
              "pressure, frame rates against the paper's, and the pressure solver's Terzaghi check.",
              f"mjed-verify liver{q} --json liver.json", _run_liver),
        Study("cross_release", "The oracle across dolfinx releases and MPI ranks",
              "The same oracle cases (all seven materials on cube-small) on Debian's dolfinx and a current dolfinx, "
              "serially and on 2 MPI ranks, compared with the first stack.",
              "make cross-release", _run_cross_release),
        Study("provenance", "Provenance",
              "The machine, the versions and the commit the numbers above were measured with.",
              f"mjed-verify all{q}", _run_provenance),
    ]
