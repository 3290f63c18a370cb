"""mjed-verify check: compare an engine's forces and stiffness with the oracle, case by case, and
diagnose each failure (docs/conventions.md).
"""

from __future__ import annotations

import os
import sys

NAME = "check"
ORDER = 61
HELP = (
    "check an engine against the oracle (a kit it computed, or a command run per case) and "
    "diagnose failures"
)
EXAMPLES = """examples:
  mjed-verify check kit/             # outputs already written into kit/cases/<id>/output
  mjed-verify check --command './my_engine {input} {output}' --material NeoHookean --mesh cube-small
  mjed-verify check kit/ --command './my_engine {input} {output}' --timeout 30
  mjed-verify check --command 'julia engine.jl {input} {output}' \\
                    --energy "mu/2*(I1b-3) + K/2*(J-1)**2" --param mu=1e3 --param K=1e4
exit codes: 0 every case passes, 1 a case fails, 2 bad input (the other cases still run and are
reported).
The report (index.html, report.md, results.json, per-node error fields as .vtu) goes to a new
directory under --out.
"""


def configure(parser) -> None:
    from common import options as opt
    from conformance.kit.options import add_model_options

    parser.add_argument(
        "dir",
        metavar="DIR",
        nargs="?",
        help="a kit written by 'mjed-verify export' (optional with --command)",
    )
    parser.add_argument(
        "--command",
        dest="engine_command",
        metavar="CMD",
        help="run CMD per case; {input} and {output} are replaced by the case's directories",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=60.0,
        help="time limit per case for --command, seconds (default 60)",
    )
    add_model_options(parser)
    opt.add_out_option(parser, "reports")
    opt.add_json_option(parser)
    parser.add_argument(
        "--precision",
        choices=("auto", "double", "single"),
        default="auto",
        help="tolerances: 'double' (1e-10), 'single' (from float32 round-off and "
        "each case's conditioning) or 'auto' (the kit's declaration, else "
        "single for .f32 outputs)",
    )
    parser.add_argument(
        "--verdict-only",
        action="store_true",
        help="judge only: each case's verdict and errors, without the readings that name a "
        "failed case's cause (faster where many cases fail, e.g. an engine's CI)",
    )
    parser.add_argument("--quiet", action="store_true", help="print only the summary line")


def run(args) -> int:
    from common.options import InputError
    from conformance.engine.command import command_words
    from conformance.kit.exchange import FormatError

    if args.dir is None and args.engine_command is None:
        raise InputError("give a kit DIR, a --command, or both")
    if args.engine_command is not None:
        try:
            command_words(args.engine_command)
        except ValueError as exc:
            raise InputError(str(exc)) from None
    if args.timeout <= 0:
        raise InputError(f"--timeout must be > 0, got {args.timeout}")
    if args.dir is not None:
        from conformance.kit.read import read_kit

        given = [k for k in ("material", "energy", "fibre") if getattr(args, k) is not None] + (
            ["param"] if args.param else []
        )
        given += [
            k
            for k, default in (("mesh", "single-tet"), ("states", "all"))
            if getattr(args, k) != default
        ]
        if given:
            raise InputError(
                f"--{given[0]} is not used with a kit: the kit's manifest says what to compute"
            )
        try:
            kit = read_kit(args.dir)
        except FormatError as exc:
            raise InputError(str(exc)) from None
        cases, input_errors = list(kit.cases), dict(kit.errors)
        if args.precision == "auto":
            args.precision = kit.precision
    else:
        from conformance.kit.cases import PROBES
        from conformance.kit.options import cases_from_args

        cases, input_errors = cases_from_args(args, probes=PROBES), {}

    from conformance.judge.oracle import oracle_available

    if not oracle_available():
        print(
            "mjed-verify check: the oracle needs dolfinx (Debian: apt install python3-dolfinx)",
            file=sys.stderr,
        )
        return 3
    return _run(args, cases, input_errors)


def _evaluator(args, cases, folder: str, command: str):
    """Case -> engine output: the outputs in the kit, or the engine run on each case."""
    from conformance.kit.exchange import read_output
    from conformance.kit.write import write_kit

    if args.engine_command is None:
        return lambda c: read_output(
            c.output_dir, c.input.n_nodes, c.case_id, n_cells=c.input.n_cells, within=args.dir
        )
    from conformance.engine.command import command_evaluator

    base = args.dir
    if base is None:  # the inputs are written into the report directory, then run through it
        base = os.path.join(folder, "kit")
        write_kit(base, cases, command=command)
    os.makedirs(os.path.join(folder, "outputs"))
    # A kit's case carries the input directory its hashes were checked on: the engine gets
    # exactly that one. Generated cases live in the report's own kit/.
    return command_evaluator(
        args.engine_command,
        lambda c: c.input_dir or os.path.join(base, "cases", c.case_id, "input"),
        os.path.join(folder, "outputs"),
        args.timeout,
    )


def _run(args, cases, input_errors) -> int:
    from conformance.kit.options import reproduce
    from conformance.report import new_report_dir, write_error_field, write_report
    from conformance.run import run_check

    folder = new_report_dir(args.out)
    command = reproduce(NAME, args, args.dir or "")
    evaluate = _evaluator(args, cases, folder, command)
    fields = {}

    def on_case(case, out, ref, diag):
        if diag.passed:
            return
        rel = os.path.join("fields", f"{case.case_id}.vtu")
        os.makedirs(os.path.join(folder, "fields"), exist_ok=True)
        write_error_field(os.path.join(folder, rel), case, out.force, ref.force, diag.node_error)
        fields[case.case_id] = rel

    from common.progress import Progress

    # A bar on a terminal (a check of a large mesh runs for minutes); one line per case otherwise.
    bar = Progress(sum(c.role == "case" for c in cases), "check")
    progress = (
        None
        if args.quiet
        else (
            bar.advance
            if bar.enabled
            else (lambda cid: print(f"  ... {cid}", file=sys.stderr, flush=True))
        )
    )
    result = run_check(
        cases,
        evaluate,
        input_errors=input_errors,
        progress=progress,
        on_case=on_case,
        precision=args.precision,
        read_causes=not args.verdict_only,
    )
    bar.close()
    paths = write_report(folder, result, command=command, fields=fields)
    if not args.quiet:
        print(result.text())
    else:
        print(result.summary())
    print(f"report: {paths['html']}")
    if args.json:
        import shutil

        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        shutil.copyfile(paths["json"], args.json)  # the same results.json, where the user asked
    return result.exit_code
