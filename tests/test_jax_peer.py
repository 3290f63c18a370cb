"""comparisons.timing.jax_peer: the JAX autodiff peer (timed only on a GPU)."""

from __future__ import annotations

import json
import sys

import pytest

from comparisons.timing import jax_peer


def test_without_jax_it_says_not_run(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "jax", None)  # import jax -> ImportError
    assert jax_peer.main(["--sizes", "1e3"]) == 3
    assert "not run: JAX is not installed" in capsys.readouterr().err


def test_figures_are_set_beside_the_project_kernels_of_the_same_session(tmp_path):
    bench = {
        "gpu": {
            "sizes": [
                {
                    "cells": 1000,
                    "timings": [
                        {
                            "method": "mjed",
                            "dtype": "float64",
                            "quantity": "f+K",
                            "tets_per_s": 8e9,
                        },
                        {
                            "method": "classical",
                            "dtype": "float64",
                            "quantity": "f+K",
                            "tets_per_s": 2e9,
                        },
                    ],
                }
            ]
        }
    }
    (tmp_path / "bench.json").write_text(json.dumps(bench))
    fig = {
        "peer": "JAX",
        "jax": "0",
        "device": "dev",
        "date": "today",
        "verification": {
            "float64": {"force_err": 1e-14, "stiffness_err": 2e-15, "tol": 1e-10, "passed": True},
            "float32": {"force_err": 1e-3, "stiffness_err": 1e-6, "tol": 1e-4, "passed": False},
        },
        "timings": [
            {
                "cells": 1000,
                "dtype": "float64",
                "quantity": "f+K",
                "best_s": 1e-3,
                "tets_per_s": 1e6,
            }
        ],
        "skipped": ["10,000 tets float64: XlaRuntimeError: RESOURCE_EXHAUSTED"],
    }
    lines = []
    jax_peer.print_figures(fig, str(tmp_path / "bench.json"), out=lines.append)
    text = "\n".join(lines)
    assert "float32: against mjed's NumPy engine force 1.0e-03" in text
    assert "outside it, timed as it is" in text
    assert "mjed 8000.0x  classical 2000.0x" in text
    assert "skipped: 10,000 tets float64: XlaRuntimeError" in text


def test_the_peer_agrees_with_mjed_where_jax_runs():
    pytest.importorskip("jax")
    fig = jax_peer.measure([300], min_time=0.01)
    assert all(v["passed"] for v in fig["verification"].values()), fig["verification"]
    assert fig["verification"]["float64"]["stiffness_err"] < 1e-12
    assert {(t["dtype"], t["quantity"]) for t in fig["timings"]} == {
        (d, q) for d in ("float64", "float32") for q in ("f", "f+K")
    }
