"""The folder map of docs/organisation.md against the tree, so that it cannot go stale.

Every package (a folder with ``__init__.py``, two levels deep) is on the map, every path on it
exists, the modules directly in ``comparisons/`` and ``conformance/`` are on it, and a line
that lists modules after its colon (a study, a stage of a check) lists exactly that folder's
modules.
"""

from __future__ import annotations

import pathlib
import re
from typing import Dict, List

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "organisation.md"
TOP = ("comparisons", "conformance", "common", "reference_fem", "meshes", "mjed")
#: Modules listed after a colon: a study's or a stage's modules, names without '.py'.
LISTED = re.compile(r":\s*([a-z_]+(?:,\s*[a-z_]+)*),?\s*$")


def folder_map(text: str) -> Dict[str, List[str]]:
    """Path on the map -> the modules its line (and its continuation lines) lists, if any."""
    block = text.split("<!-- folder-map -->")[1].split("<!-- /folder-map -->")[0]
    entries: Dict[str, List[str]] = {}
    parent = last = said = ""
    for line in block.strip().strip("`").strip("\n").splitlines():
        indent = len(line) - len(line.lstrip())
        name, _, words = line.strip().partition(" ")
        if indent == 0:  # a top folder
            parent = last = name
            said = words
        elif indent == 2:  # a folder or file inside it
            last, said = parent + name, words
        else:  # the line above, continued
            said += " " + line.strip()
        found = LISTED.search(said) if last.endswith("/") else None
        entries[last] = [m.strip() for m in found.group(1).split(",")] if found else []
    return entries


def packages() -> List[str]:
    out = []
    for top in TOP:
        out.append(f"{top}/")
        for init in sorted((ROOT / top).glob("*/__init__.py")):
            out.append(f"{init.parent.relative_to(ROOT)}/")
    return out


def modules(folder: pathlib.Path) -> List[str]:
    return sorted(p.stem for p in folder.glob("*.py") if not p.stem.startswith("__"))


MAP = folder_map(PAGE.read_text())


def test_every_package_is_on_the_map():
    assert [p for p in packages() if p not in MAP] == []


def test_every_path_on_the_map_exists():
    assert [p for p in MAP if not (ROOT / p).exists()] == []


def test_the_applications_top_modules_are_on_the_map():
    missing = [
        f"{app}/{m}.py" for app in ("comparisons", "conformance") for m in modules(ROOT / app)
    ]
    assert [m for m in missing if m not in MAP] == []


def test_a_study_or_stage_lists_exactly_its_modules():
    for path, listed in MAP.items():
        if listed:
            assert sorted(listed) == modules(ROOT / path), path


def test_the_map_reader_sees_lists_and_continuations():
    text = (
        "<!-- folder-map -->\n```\na/      top\n  b/    x: one, two,\n        three\n"
        "  c.py  no list\n```\n<!-- /folder-map -->\n"
    )
    assert folder_map(text) == {"a/": [], "a/b/": ["one", "two", "three"], "a/c.py": []}
