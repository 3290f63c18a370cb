"""Paths the studies derive from their own file point into this repository (moving a module
one folder deeper once sent the cross-release study to look for comparisons/.venv, and the GPU
section for comparisons/docs).
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_cross_release_finds_the_repository():
    from comparisons.cross_release.study import REPO

    assert REPO == ROOT and (REPO / "pyproject.toml").is_file()


def test_gpu_figures_live_under_docs_studies():
    from comparisons.timing.gpu_section import DEFAULT_PATH

    assert DEFAULT_PATH.parent == ROOT / "docs" / "studies" and DEFAULT_PATH.parent.is_dir()


def test_provenance_reads_this_repository():
    from comparisons.provenance import _REPO

    assert _REPO == ROOT
