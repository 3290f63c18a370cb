"""Fuzzing the kit and output readers (Hypothesis): a valid kit with its engine's output is
broken in up to four drawn ways (manifest fields, case.json fields, array bytes, special files,
links, deep JSON, garbage) and checked with ``mjed-verify check``. Whatever is drawn:

- no traceback: the exit code is 0, 1 or 2;
- every case reported as bad input names a file of the kit (its message holds the kit's path);
- nothing is written outside the kit's folder and --out, and the kit itself is not changed;
- memory and time stay bounded (traced allocations under 64 MB, each example under 20 s).

The budget is fixed (max_examples, deadline) so that it runs in well under a minute.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
import tracemalloc
from datetime import timedelta

import numpy as np
import pytest
from conftest import box_mesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import mjed
from comparisons.cli import main
from conformance.kit.cases import build_cases
from conformance.kit.exchange import write_output
from conformance.kit.write import write_kit
from mjed import materials as M
from reference_fem import dolfinx_available

pytestmark = pytest.mark.skipif(
    not dolfinx_available(), reason="check needs the oracle (python3-dolfinx)"
)

MAX_TRACED = 64 << 20
MAX_SECONDS = 20.0
INPUTS = ("case.json", "points.f64", "cells.i64", "positions.f64")
OUTPUTS = (
    "force.f64",
    "stiffness_rows.i64",
    "stiffness_cols.i64",
    "stiffness_values.f64",
    "energy.f64",
)

# Names an attacker or a careless script would try, and arbitrary text.
NAMES = st.one_of(
    st.sampled_from(
        [
            "../escape",
            "../../../../tmp/escape",
            "/etc/hostname",
            "a/b",
            "..",
            ".",
            "",
            "x" * 300,
            "~root",
            "points.f64",
            "cells.i64",
            "case.json",
            "nul\x00byte",
            "ok~probe0",
            "-dash",
            "sp ace",
        ]
    ),
    st.text(max_size=24),
)
JSON = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(2**70), 2**70),
        st.floats(allow_nan=True),
        st.text(max_size=12),
        NAMES,
    ),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=10,
)
MANIFEST_KEYS = (
    "id",
    "role",
    "input",
    "output",
    "mesh",
    "state",
    "probe_of",
    "step",
    "input_sha256",
    "n_nodes",
)
CASE_FIELDS = (
    ("case",),
    ("format_version",),
    ("arrays",),
    ("arrays", "points"),
    ("arrays", "points", "file"),
    ("arrays", "points", "shape"),
    ("arrays", "cells", "dtype"),
    ("arrays", "positions", "shape"),
    ("model",),
    ("model", "name"),
    ("model", "kind"),
    ("model", "parameters"),
    ("model", "parameters", "mu"),
)
SPECIAL = ("link-out", "link-devzero", "fifo", "directory", "huge", "missing")
JSON_FILES = ("manifest.json", "case.json")

OPS = st.one_of(
    st.tuples(st.just("manifest-field"), st.integers(0, 1), st.sampled_from(MANIFEST_KEYS), JSON),
    st.tuples(
        st.just("manifest-top"), st.sampled_from(["format", "format_version", "cases"]), JSON
    ),
    st.tuples(st.just("hash-key"), NAMES),
    st.tuples(st.just("case-field"), st.sampled_from(CASE_FIELDS), JSON, st.booleans()),
    st.tuples(
        st.just("input-bytes"), st.sampled_from(INPUTS[1:]), st.binary(max_size=400), st.booleans()
    ),
    st.tuples(st.just("output-bytes"), st.sampled_from(OUTPUTS), st.binary(max_size=400)),
    st.tuples(
        st.just("special"),
        st.sampled_from(INPUTS + OUTPUTS + ("output",)),
        st.sampled_from(SPECIAL),
    ),
    st.tuples(st.just("deep"), st.sampled_from(JSON_FILES), st.integers(500, 100_000)),
    st.tuples(st.just("garbage"), st.sampled_from(JSON_FILES), st.binary(max_size=200)),
)


def _sha(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def _make_kit(root):
    """Two primary cases, each with a correct output written by MJED."""
    points, cells = box_mesh(1)
    model = M.NeoHookean(mu=1.3, lam=2.1)
    cases = build_cases([model], [("box", points, cells)], ["uniaxial", "shear"], probes=0)
    folder = os.path.join(root, "kit")
    write_kit(folder, cases)
    field = mjed.HyperelasticForceField(mjed.TetMesh(points, cells), model)
    for c in cases:
        f, K = field.force_and_stiffness(c.input.positions)
        write_output(
            os.path.join(folder, "cases", c.case_id, "output"),
            f,
            K,
            field.energy(c.input.positions),
        )
    return folder, [c.case_id for c in cases]


def _set(obj, path, value):
    for key in path[:-1]:
        if not isinstance(obj, dict) or not isinstance(obj.get(key), dict):
            return
        obj = obj[key]
    if isinstance(obj, dict):
        obj[path[-1]] = value


def _apply(op, folder, ids, outside):
    manifest_path = os.path.join(folder, "manifest.json")
    first = os.path.join(folder, "cases", ids[0])
    case_json = os.path.join(first, "input", "case.json")

    def manifest():
        with open(manifest_path, "rb") as fh:
            return json.loads(fh.read())

    def save(m):
        with open(manifest_path, "w") as fh:
            json.dump(m, fh)

    def rehash():  # keep the hashes true, so that the readers behind them are reached
        try:
            m = manifest()
            e = m["cases"][0]
            d = os.path.join(first, "input")
            e["input_sha256"] = {
                n: _sha(os.path.join(d, n)) for n in INPUTS if os.path.isfile(os.path.join(d, n))
            }
            save(m)
        except (ValueError, KeyError, TypeError, IndexError, OSError, RecursionError):
            pass  # the manifest itself is already broken

    kind = op[0]
    try:
        if kind in ("manifest-field", "manifest-top", "hash-key"):
            m = manifest()
            if kind == "manifest-field":
                m["cases"][op[1]][op[2]] = op[3]
            elif kind == "manifest-top":
                m[op[1]] = op[2]
            else:
                m["cases"][0].setdefault("input_sha256", {})[op[1]] = "0" * 64
            save(m)
        elif kind == "case-field":
            data = json.load(open(case_json))
            _set(data, op[1], op[2])
            with open(case_json, "w") as fh:
                json.dump(data, fh)
            if op[3]:
                rehash()
        elif kind == "input-bytes":
            with open(os.path.join(first, "input", op[1]), "wb") as fh:
                fh.write(op[2])
            if op[3]:
                rehash()
        elif kind == "output-bytes":
            with open(os.path.join(first, "output", op[1]), "wb") as fh:
                fh.write(op[2])
        elif kind == "special":
            where = "output" if op[1] in OUTPUTS else "input"
            path = (
                os.path.join(first, "output")
                if op[1] == "output"
                else os.path.join(first, where, op[1])
            )
            if os.path.isdir(path) and not os.path.islink(path):
                shutil.rmtree(path)
            elif os.path.lexists(path):
                os.remove(path)
            if op[2] == "link-out":
                os.symlink(outside, path)
            elif op[2] == "link-devzero":
                os.symlink("/dev/zero", path)
            elif op[2] == "fifo":
                os.mkfifo(path)
            elif op[2] == "directory":
                os.mkdir(path)
            elif op[2] == "huge":
                with open(path, "wb") as fh:
                    fh.truncate(3 << 30)  # 3 GB that cost no disk
        elif kind == "deep":
            path = manifest_path if op[1] == "manifest.json" else case_json
            with open(path, "w") as fh:
                fh.write("[" * op[2] + "]" * op[2])
            if op[1] == "case.json":
                rehash()
        elif kind == "garbage":
            path = manifest_path if op[1] == "manifest.json" else case_json
            with open(path, "wb") as fh:
                fh.write(op[2])
    except (ValueError, KeyError, TypeError, IndexError, RecursionError, OSError):
        pass  # an earlier operation already broke what this one edits


def _tree(root):
    out = set()
    for base, dirs, files in os.walk(root):
        for n in dirs + files:
            p = os.path.join(base, n)
            info = os.lstat(p)
            size = 0 if os.path.isdir(p) else info.st_size
            out.add((os.path.relpath(p, root), size, info.st_mtime_ns))
    return out


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """One check of the intact kit first: the oracle's compilation stays out of the budget."""
    root = str(tmp_path_factory.mktemp("warm"))
    folder, _ = _make_kit(root)
    assert main(["check", folder, "--out", os.path.join(root, "out"), "--quiet"]) == 0


@settings(
    max_examples=50,
    deadline=timedelta(seconds=MAX_SECONDS),
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(ops=st.lists(OPS, min_size=1, max_size=4))
def test_check_holds_against_a_broken_kit(warm, capsys, ops):
    with tempfile.TemporaryDirectory() as root:
        folder, ids = _make_kit(root)
        outside = os.path.join(root, "outside.f64")
        with open(outside, "wb") as fh:
            fh.write(np.zeros((8, 3)).tobytes())
        for op in ops:
            _apply(op, folder, ids, outside)
        before_kit = _tree(folder)
        before_root = {p for p in os.listdir(root)}
        out = os.path.join(root, "out")
        t0 = time.monotonic()
        tracemalloc.start()
        try:
            code = main(["check", folder, "--out", out, "--quiet"])
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        elapsed = time.monotonic() - t0
        err = capsys.readouterr().err
        assert code in (0, 1, 2)
        assert "Traceback" not in err
        assert peak < MAX_TRACED and elapsed < MAX_SECONDS
        assert _tree(folder) == before_kit  # check never writes into the kit
        assert set(os.listdir(root)) - before_root <= {"out"}
        if code == 2 and not os.path.isdir(out):  # the kit as a whole could not be read
            assert folder in err
        elif os.path.isdir(out):
            (run,) = os.listdir(out)
            with open(os.path.join(out, run, "results.json")) as fh:
                res = json.load(fh)
            messages = list(res["input_errors"].values()) + [
                c["message"] for c in res["cases"] if c["status"] == "bad input"
            ]
            assert (code == 2) == bool(messages)
            for msg in messages:
                assert folder in msg, msg
