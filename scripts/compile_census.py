"""A pytest plugin that records, per test, what the JIT caches gained: FFCx forms, elements and
expressions (dolfinx's cache, ``$XDG_CACHE_HOME/fenics``), generated MJED kernel sources
(``$MJED_KERNEL_CACHE``) and Numba's compiled overloads (``*.nbc`` under ``$NUMBA_CACHE_DIR``
and ``$MJED_KERNEL_CACHE``), plus the seconds this process spent in FFCx's C compiler and in
Numba's compile step. Files are counted on disk, so what a test's subprocesses (mpirun, the
command line, an engine) compile is counted too.

Used by ``scripts/cold-start.sh``; loaded with ``-p compile_census`` (``scripts/`` on the
path) and switched on by ``MJED_COMPILE_CENSUS=<file.jsonl>``: one JSON line per test, then
a summary at the end of the session. Nothing happens without that variable.
"""

from __future__ import annotations

import json
import os
import time
from collections import Counter
from pathlib import Path

_OUT = os.environ.get("MJED_COMPILE_CENSUS")
_SECONDS = Counter()  # seconds this process spent compiling, by kind, since the last test


def _cache_dirs():
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    fenics = Path(xdg) / "fenics"
    kernels = Path(os.environ.get("MJED_KERNEL_CACHE") or Path(xdg) / "mjed" / "kernels")
    numba = [Path(p) for p in {os.environ.get("NUMBA_CACHE_DIR"), str(kernels)} if p]
    return fenics, kernels, numba


def snapshot() -> Counter:
    """How many cached objects of each kind exist now."""
    fenics, kernels, numba = _cache_dirs()
    count = Counter()
    try:
        for entry in os.scandir(fenics):
            name = entry.name
            if name.endswith(".so"):
                for kind in ("forms", "elements", "expressions"):
                    if name.startswith(f"libffcx_{kind}_"):
                        count[f"ffcx_{kind}"] += 1
    except OSError:
        pass
    try:
        count["kernel_sources"] = sum(1 for e in os.scandir(kernels) if e.name.endswith(".py"))
    except OSError:
        pass
    seen = set()
    for root in numba:
        for dirpath, _, files in os.walk(root):
            for name in files:
                if name.endswith(".nbc"):
                    path = os.path.join(dirpath, name)
                    if path not in seen:
                        seen.add(path)
                        count["numba_overloads"] += 1
                        try:
                            count["numba_bytes"] += os.path.getsize(path)
                        except OSError:
                            pass
    return count


def _install_timers() -> None:
    """Add this process's compile seconds to _SECONDS (FFCx's C build, Numba's compile)."""
    try:
        import ffcx.codegeneration.jit as jit

        original = jit._compile_objects

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                _SECONDS["ffcx_s"] += time.perf_counter() - t0

        jit._compile_objects = timed
    except Exception:  # noqa: BLE001 - no FFCx here: nothing to time
        pass
    try:
        from numba.core import event

        class _Timer(event.Listener):  # the outermost compile only (they nest)
            depth = 0

            def on_start(self, ev):
                if self.depth == 0:
                    self.t0 = time.perf_counter()
                self.depth += 1

            def on_end(self, ev):
                self.depth -= 1
                if self.depth == 0:
                    _SECONDS["numba_s"] += time.perf_counter() - self.t0

        event.register("numba:compile", _Timer())
    except Exception:  # noqa: BLE001 - no Numba here: nothing to time
        pass


def _row(name: str, before: Counter, after: Counter, seconds: float) -> dict:
    row = {"test": name, "s": round(seconds, 3)}
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker:  # a parallel worker: what the others compiled meanwhile is counted here too
        row["worker"] = worker
    for key in ("ffcx_forms", "ffcx_elements", "ffcx_expressions", "kernel_sources"):
        row[key] = after[key] - before[key]
    row["numba_overloads"] = after["numba_overloads"] - before["numba_overloads"]
    row["numba_bytes"] = after["numba_bytes"] - before["numba_bytes"]
    row["ffcx_s"] = round(_SECONDS["ffcx_s"], 3)
    row["numba_s"] = round(_SECONDS["numba_s"], 3)
    return row


def demo(argv) -> int:
    """``mjed-verify`` with ``argv`` (e.g. ``all``), one census row per report study."""
    from comparisons.cli import main
    from comparisons.report import runner

    _install_timers()
    original = runner._run_one

    def counted(study, ctx):
        before = snapshot()
        _SECONDS.clear()
        t0 = time.perf_counter()
        try:
            return original(study, ctx)
        finally:
            row = _row(f"study:{study.key}", before, snapshot(), time.perf_counter() - t0)
            with open(_OUT, "a") as fh:
                fh.write(json.dumps(row) + "\n")

    runner._run_one = counted
    return main(list(argv))


def summary(path: str, top: int = 20) -> None:
    """Print the totals of a census file and what compiled most, by test, test function and
    module (or by study).
    """
    rows = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
    keys = ("ffcx_forms", "ffcx_elements", "numba_overloads", "kernel_sources")
    total = Counter()
    for r in rows:
        for k in (*keys, "numba_bytes", "s", "ffcx_s", "numba_s"):
            total[k] += r.get(k, 0)
    print(f"census {path}: {len(rows)} items, {total['s']:.0f} s")
    workers = {r["worker"] for r in rows if "worker" in r}
    if len(workers) > 1:
        # Counted on disk: a test's count includes what the other workers compiled while it
        # ran, so the sums below overcount; the session's totals are in the log's
        # "compile census" block (the controller's snapshots before and after).
        print(
            f"  {len(workers)} parallel workers: the counts per item overlap and the sums "
            "overcount; the session's totals are in the leg's log, 'compile census'"
        )
    print(
        f"  FFCx forms {total['ffcx_forms']}, elements {total['ffcx_elements']} "
        f"({total['ffcx_s']:.0f} s compiling in the test process); Numba overloads "
        f"{total['numba_overloads']} ({total['numba_bytes'] / 1e6:.1f} MB, "
        f"{total['numba_s']:.0f} s compiling or loading in the test process), "
        f"generated kernel sources {total['kernel_sources']}"
    )

    def group(key_of):
        acc: dict = {}
        for r in rows:
            a = acc.setdefault(key_of(r["test"]), Counter())
            a["n"] += 1
            for k in (*keys, "s"):
                a[k] += r.get(k, 0)
        return acc

    def show(title, acc, by):
        print(f"  {title}, by {by}:")
        ranked = sorted(acc.items(), key=lambda kv: -kv[1][by])[:top]
        for name, a in ranked:
            if a[by] <= 0:
                break
            print(
                f"    {a['ffcx_forms']:5d} forms {a['numba_overloads']:5d} kernels "
                f"{a['s']:7.1f} s {a['n']:4d} items  {name}"
            )

    def module(name):
        return name.split("::")[0]

    def function(name):
        return name.split("[")[0]

    for by in ("ffcx_forms", "numba_overloads"):
        show("modules or studies", group(module), by)
        show("test functions", group(function), by)


if __name__ == "__main__":
    import sys

    if sys.argv[1:2] == ["summary"]:
        for p in sys.argv[2:]:
            summary(p)
        sys.exit(0)
    if sys.argv[1:2] == ["demo"]:
        sys.exit(demo(sys.argv[2:]))
    sys.exit("usage: compile_census.py summary FILE... | demo MJED-VERIFY-ARGS...")

if _OUT and __name__ != "__main__":
    import pytest

    _state = {"before": Counter(), "start": snapshot(), "t": time.time(), "rows": []}

    def pytest_configure(config):
        _install_timers()
        Path(_OUT).parent.mkdir(parents=True, exist_ok=True)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        before = snapshot()
        _SECONDS.clear()
        t0 = time.perf_counter()
        yield
        row = _row(item.nodeid, before, snapshot(), time.perf_counter() - t0)
        with open(_OUT, "a") as fh:
            fh.write(json.dumps(row) + "\n")

    def pytest_terminal_summary(terminalreporter):
        end = snapshot()
        start = _state["start"]
        w = terminalreporter.write_line
        w("")
        w("compile census (what the JIT caches gained during this session):")
        for key in ("ffcx_forms", "ffcx_elements", "ffcx_expressions", "kernel_sources"):
            w(f"  {key:18s} {end[key] - start[key]:6d}")
        w(f"  {'numba_overloads':18s} {end['numba_overloads'] - start['numba_overloads']:6d}")
        mb = (end["numba_bytes"] - start["numba_bytes"]) / 1e6
        w(f"  {'numba_MB':18s} {mb:6.1f}")
        w(f"  per-test records: {_OUT}")
