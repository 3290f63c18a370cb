#!/usr/bin/env python3
"""Run the held-out corpus of mistaken engines through `mjed-verify check` and score the diagnosis.

    python tests/heldout_mistakes/run_corpus.py [--corpus DIR] [--out DIR] [--states S] [--jobs N]
                                                [ENGINE ...]

--corpus DIR: the folder holding the engines and their manifest.toml (default: this folder,
tests/heldout_mistakes; the second corpus is tests/heldout_mistakes_2).

For each material of the manifest a kit is exported once (`mjed-verify export`, mesh cube-small,
states uniaxial and random by default, with probes); each engine is then checked against its
material's kit with `mjed-verify check KIT --command 'python ENGINE {input} {output}' --json`.

Scores, per engine (from the check's results.json):

- correct engines (family "correct"): "pass" when every case passes (at single precision for
  the float32 control), else "FAIL";
- mistaken engines: "PASSED" (the worst outcome: a mistake let through) when every case passes;
  otherwise each failing case's *named cause* is the diagnosis' headline, its first finding,
  unless that is "unexplained" or a mere observation (a consistency figure). A case is
  "named" when that cause's title or evidence contains one of the manifest's `match` keywords
  (case-insensitive; "a&b" needs both), "wrongly named" when it names another cause, and
  "unexplained" when it names none. The engine is "wrongly named" if any failing case is,
  "named" if every failing case is named, else "unexplained" (the table shows how many of its
  failing cases were named).

How: the engines of one kit are judged in one process, which reads the kit and builds its oracles
once (``--jobs`` such processes side by side, each taking whole kits); each engine is checked
there exactly as ``mjed-verify check KIT --command 'python ENGINE {input} {output}' --json``
checks it (the same run_check, the same results.json), without starting the command line and
rebuilding the oracle for every engine. ``--one-process-per-engine`` runs that command instead.

Prints a table and writes OUT/summary.json. Exit code 0 unless a correct engine fails or a
mistaken engine passes (the diagnosis' naming rate is reported, not enforced).
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import shlex
import shutil
import subprocess
import sys
import time

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
MESH = "cube-small"
STATES = "uniaxial,random"
TIMEOUT = 120  # seconds an engine may take for one case
# headline findings that observe rather than explain
NOT_A_CAUSE_STRENGTHS = {"observed"}
NOT_A_CAUSE_CODES = {"unexplained"}


def mjed_verify() -> list:
    exe = Path(sys.executable).with_name("mjed-verify")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("mjed-verify")
    if found:
        return [found]
    return [sys.executable, "-m", "mjed.cli"]


def load_manifest(path: Path = HERE / "manifest.toml") -> list:
    """The manifest's engines; `path` may also be a corpus folder holding manifest.toml."""
    path = Path(path)
    if path.is_dir():
        path = path / "manifest.toml"
    return tomllib.loads(path.read_text())["engine"]


def kit_key(entry: dict) -> tuple:
    """(material, precision): an engine declaring float32 gets a kit exported --precision single."""
    return entry["material"], entry.get("precision", "double")


def export_kits(keys, out: Path, states: str, store: Path = None) -> dict:
    """{(material, precision): kit folder}, each kit exported by `mjed-verify export` under
    ``out``/kits; with ``store``, a folder shared by several runs (the corpus test modules of
    one pytest session, on every worker), a kit of the same material, precision and states
    already exported there is used as it is, and a missing one is exported there once (a file
    lock per kit: two runs asking at once export it once).
    """
    kits = {}
    for material, precision in sorted(set(keys)):
        name = material if precision == "double" else f"{material}-{precision}"
        if store is None:
            kits[material, precision] = _export(out / "kits" / name, material, precision, states)
            continue
        kit = Path(store) / f"{name}-{states.replace(',', '+')}"
        Path(store).mkdir(parents=True, exist_ok=True)
        with open(kit.with_suffix(".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
            done = kit.with_suffix(".exported")
            if not done.exists():
                _export(kit, material, precision, states)
                done.touch()  # after the export: a kit interrupted half way is exported again
        kits[material, precision] = kit
    return kits


def _export(kit: Path, material: str, precision: str, states: str) -> Path:
    if kit.exists():
        shutil.rmtree(kit)
    cmd = mjed_verify() + ["export", str(kit), "--material", material, "--mesh", MESH]
    cmd += ["--states", states, "--precision", precision]
    subprocess.run(cmd, check=True, cwd=ROOT, capture_output=True, text=True)
    return kit


def engine_command(entry: dict, corpus: Path) -> str:
    """The engine's command template: this Python running the corpus file on {input} {output}."""
    engine = Path(corpus) / entry["file"]
    return f"{shlex.quote(sys.executable)} {shlex.quote(str(engine))} {{input}} {{output}}"


def run_engine(
    entry: dict,
    kit: Path,
    out: Path,
    timeout: int = TIMEOUT,
    corpus: Path = HERE,
    verdict_only: bool = False,
) -> dict:
    name = Path(entry["file"]).stem
    report_json = out / "json" / f"{name}.json"
    report_json.parent.mkdir(parents=True, exist_ok=True)
    command = engine_command(entry, corpus)
    cmd = mjed_verify() + [
        "check",
        str(kit),
        "--command",
        command,
        "--timeout",
        str(timeout),
        "--out",
        str(out / "reports" / name),
        "--json",
        str(report_json),
        "--quiet",
        *(["--verdict-only"] if verdict_only else []),
    ]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    seconds = time.monotonic() - t0
    results = json.loads(report_json.read_text()) if report_json.exists() else None
    return score(
        entry, results, proc.returncode, seconds, proc.stdout[-2000:] + proc.stderr[-2000:]
    )


def _judge_here(entry: dict, kit: Path, out: Path, corpus: Path, verdict_only: bool, caches):
    """One engine checked in this process, as `mjed-verify check KIT --command ... --json` does
    (the same run_check and results.json); ``caches`` keeps each kit's cases and oracles.
    """
    from forked_engines import run_forked  # beside this script, first on sys.path in --serve

    from common.options import write_json
    from conformance.engine.command import command_evaluator
    from conformance.judge.oracle import OracleCache
    from conformance.kit.read import read_kit
    from conformance.run import run_check

    if str(kit) not in caches:
        read = read_kit(str(kit))
        caches[str(kit)] = (list(read.cases), dict(read.errors), read.precision, OracleCache())
    cases, errors, precision, cache = caches[str(kit)]
    name = Path(entry["file"]).stem
    folder = out / "outputs" / name
    shutil.rmtree(folder, ignore_errors=True)
    command = engine_command(entry, corpus)
    evaluate = command_evaluator(
        command,
        lambda c: c.input_dir or str(kit / "cases" / c.case_id / "input"),
        str(folder),
        TIMEOUT,
        run=run_forked,  # the engine script forked from a warm Python (forked_engines.py)
    )
    t0 = time.monotonic()
    run = run_check(
        cases,
        evaluate,
        input_errors=errors,
        precision=precision,
        read_causes=not verdict_only,
        cache=cache,
    )
    seconds = time.monotonic() - t0
    report_json = out / "json" / f"{name}.json"
    report_json.parent.mkdir(parents=True, exist_ok=True)
    write_json(str(report_json), {"command": command, **run.to_dict(), "fields": {}})
    return score(entry, json.loads(report_json.read_text()), run.exit_code, seconds, "")


def _serve(task_file: Path) -> int:
    """A judging process: the task file lists (entry, kit) pairs, whole kits, in order; each
    engine's row is written beside it as soon as it is scored.
    """
    sys.path.insert(0, str(ROOT))  # the checkout's own checker, beside its corpus
    task = json.loads(task_file.read_text())
    caches: dict = {}
    rows = []
    for entry, kit in task["items"]:
        rows.append(
            _judge_here(
                entry,
                Path(kit),
                Path(task["out"]),
                Path(task["corpus"]),
                task["verdict_only"],
                caches,
            )
        )
        task_file.with_suffix(".rows.json").write_text(json.dumps(rows))
    return 0


def _share_kits(entries, kits, jobs: int) -> list:
    """Whole kits dealt to ``jobs`` processes, the largest first to the least loaded."""
    groups: dict = {}
    for e in entries:
        groups.setdefault(kit_key(e), []).append(e)
    bins = [[] for _ in range(max(1, min(jobs, len(groups))))]
    for key in sorted(groups, key=lambda k: (-len(groups[k]), k)):
        min(bins, key=len).extend((e, str(kits[key])) for e in groups[key])
    return bins


def judge_in_processes(entries, kits, out: Path, corpus: Path, jobs: int, verdict_only: bool):
    """Every engine's row, judged by ``jobs`` processes that each read a kit and build its
    oracles once (:func:`_serve`); an engine whose process died is an "error" row saying so.
    """
    procs = []
    for i, items in enumerate(_share_kits(entries, kits, jobs)):
        task = out / "judges" / f"judge{i}.json"
        task.parent.mkdir(parents=True, exist_ok=True)
        task.with_suffix(".rows.json").unlink(missing_ok=True)
        task.write_text(
            json.dumps(
                {
                    "items": items,
                    "out": str(out),
                    "corpus": str(corpus),
                    "verdict_only": verdict_only,
                }
            )
        )
        cmd = [sys.executable, str(Path(__file__).resolve()), "--serve", str(task)]
        # stderr to a file: a pipe read one process at a time could fill and stall the others
        with open(task.with_suffix(".log"), "w") as log:
            procs.append((items, task, subprocess.Popen(cmd, cwd=ROOT, stderr=log)))
    rows = {}
    for items, task, proc in procs:
        proc.wait()
        err = task.with_suffix(".log").read_text(errors="replace")
        done = task.with_suffix(".rows.json")
        for row in json.loads(done.read_text()) if done.exists() else []:
            rows[row["engine"]] = row
        for entry, _ in items:
            if entry["file"] not in rows:
                rows[entry["file"]] = score(entry, None, proc.returncode, 0.0, err[-2000:])
    return [rows[e["file"]] for e in entries]


def keyword_match(text: str, keywords) -> bool:
    text = text.lower()
    return any(all(part.strip().lower() in text for part in kw.split("&")) for kw in keywords)


def named_cause(case: dict):
    """The diagnosis' headline: its first finding, unless that says "unexplained" or is only an
    observation (a consistency figure). A headline that "partly explains" still names a cause
    (the finite-difference finding is always reported so, no correction making it exact).
    """
    findings = case.get("findings", [])
    if not findings:
        return None
    first = findings[0]
    if first.get("code") in NOT_A_CAUSE_CODES or first.get("strength") in NOT_A_CAUSE_STRENGTHS:
        return None
    return first


def score(entry: dict, results, rc: int, seconds: float, tail: str) -> dict:
    row = {
        "engine": entry["file"],
        "material": entry["material"],
        "family": entry["family"],
        "tag": entry["tag"],
        "exit_code": rc,
        "seconds": round(seconds, 1),
        "cases": [],
    }
    if results is None:
        row.update(
            verdict="no results",
            score="FAIL" if entry["family"] == "correct" else "error",
            cause="",
            detail=tail,
        )
        return row
    cases = results.get("cases", [])
    passed = [
        c
        for c in cases
        if str(c.get("verdict", "")).startswith("passed") or c.get("status") == "passed"
    ]
    failing = [c for c in cases if c not in passed]
    row["verdict"] = f"{len(passed)}/{len(cases)} passed"
    per_case = []
    for c in cases:
        cause = named_cause(c) if c in failing else None
        if c in passed:
            s = "passed"
        elif cause is None:
            s = "unexplained"
        else:
            text = " ".join(str(cause.get(k, "")) for k in ("code", "title", "evidence"))
            s = "named" if keyword_match(text, entry["match"]) else "wrongly named"
        per_case.append(
            {
                "case": c["case"],
                "status": c.get("status"),
                "verdict": c.get("verdict"),
                "errors": c.get("errors"),
                "message": c.get("message", ""),
                "score": s,
                "cause_code": cause.get("code") if cause else "unexplained",
                "cause": (cause.get("title") if cause else "unexplained"),
                "strength": cause.get("strength") if cause else "",
                "findings": [(f.get("code"), f.get("strength")) for f in c.get("findings", [])],
            }
        )
    row["cases"] = per_case
    first = next((pc for pc in per_case if pc["score"] != "passed"), None)
    row["cause"] = f"{first['cause_code']}: {first['cause']} ({first['strength']})" if first else ""
    if entry["family"] == "correct":
        row["score"] = "pass" if cases and not failing and rc == 0 else "FAIL"
    elif not failing:
        row["score"] = "PASSED"
    else:
        scores = [pc["score"] for pc in per_case if pc["score"] != "passed"]
        n_named = scores.count("named")
        if "wrongly named" in scores:
            row["score"] = "wrongly named"
        elif n_named == len(scores):
            row["score"] = "named"
        else:
            row["score"] = "unexplained"
        row["named_cases"] = f"{n_named}/{len(scores)}"
    return row


def run_corpus(
    out: Path,
    states: str = STATES,
    only=(),
    jobs: int = 1,
    entries=None,
    corpus: Path = HERE,
    verdict_only: bool = False,
    one_process_per_engine: bool = False,
    kit_store: Path = None,
) -> dict:
    """Every engine of ``corpus`` checked and scored (see the module docstring); with
    ``verdict_only`` the checks only judge (`--verdict-only`: the verdicts and controls are
    the same, the causes of failed cases are not looked for, so nothing is "named");
    ``one_process_per_engine`` runs `mjed-verify check` for each engine instead of judging the
    engines of a kit in one process; ``kit_store``: a folder of kits shared with other runs
    (:func:`export_kits`).
    """
    corpus = Path(corpus).resolve()
    entries = entries if entries is not None else load_manifest(corpus)
    if only:
        wanted = {Path(o).name for o in only} | {Path(o).stem for o in only}
        entries = [e for e in entries if e["file"] in wanted or Path(e["file"]).stem in wanted]
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    kits = export_kits([kit_key(e) for e in entries], out, states, kit_store)
    if one_process_per_engine:
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            rows = list(
                pool.map(
                    lambda e: run_engine(
                        e, kits[kit_key(e)], out, corpus=corpus, verdict_only=verdict_only
                    ),
                    entries,
                )
            )
    else:
        rows = judge_in_processes(entries, kits, out, corpus, jobs, verdict_only)
    mistakes = [r for r in rows if r["family"] != "correct"]
    counts = {
        k: sum(r["score"] == k for r in mistakes)
        for k in ("named", "wrongly named", "unexplained", "PASSED", "error")
    }
    controls = {r["engine"]: r["score"] for r in rows if r["family"] == "correct"}
    summary = {
        "corpus": str(corpus.relative_to(ROOT) if corpus.is_relative_to(ROOT) else corpus),
        "mesh": MESH,
        "states": states,
        "engines": len(rows),
        "mistakes": len(mistakes),
        "counts": counts,
        "controls": controls,
        "seconds": round(time.monotonic() - t0, 1),
        "rows": rows,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def print_table(summary: dict) -> None:
    rows = summary["rows"]
    w = max(len(r["engine"]) for r in rows)
    head = f"{'engine':<{w}}  {'family':<17} {'verdict':<12} {'score':<14} {'named':<6}"
    print(head + " first named cause (strength)")
    for r in rows:
        print(
            f"{r['engine']:<{w}}  {r['family']:<17} {r.get('verdict', ''):<12} {r['score']:<14} "
            f"{r.get('named_cases', ''):<6} {r.get('cause', '')[:110]}"
        )
    c = summary["counts"]
    print(
        f"\n{summary['mistakes']} mistakes: {c['named']} named, "
        f"{c['wrongly named']} wrongly named, {c['unexplained']} unexplained, "
        f"{c['PASSED']} passed (missed), {c['error']} errors; "
        f"controls: {summary['controls']}; {summary['seconds']} s"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("engines", nargs="*", help="engine files or names (default: all)")
    ap.add_argument(
        "--corpus",
        type=Path,
        default=HERE,
        help="folder of the engines and their manifest.toml (default: %(default)s)",
    )
    ap.add_argument("--out", type=Path, default=ROOT / "reports" / "heldout_mistakes")
    ap.add_argument("--states", default=STATES)
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument(
        "--verdict-only", action="store_true", help="judge only; name no causes (faster)"
    )
    ap.add_argument(
        "--one-process-per-engine",
        action="store_true",
        help="run `mjed-verify check` for each engine (slower: the oracle is built every time)",
    )
    ap.add_argument("--serve", type=Path, help=argparse.SUPPRESS)  # a judging process's tasks
    args = ap.parse_args(argv)
    if args.serve:
        return _serve(args.serve)
    summary = run_corpus(
        args.out,
        args.states,
        args.engines,
        args.jobs,
        corpus=args.corpus,
        verdict_only=args.verdict_only,
        one_process_per_engine=args.one_process_per_engine,
    )
    print_table(summary)
    print(f"summary: {args.out / 'summary.json'}")
    bad = (
        summary["counts"]["PASSED"]
        + summary["counts"]["error"]
        + sum(v != "pass" for v in summary["controls"].values())
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
