"""Pages the documentation build generates from the code (Sphinx extension).

At ``builder-inited`` (before Sphinx reads the sources) it writes into ``docs/generated/``
(git-ignored):

- ``cli.md``: the command-line reference, from ``comparisons.cli.build_parser()``;
- ``materials.inc``: the materials table of conventions.md (which includes it), from the
  material declarations (``mjed.materials.declaration.docs_table()``); not a page of its own,
  hence the suffix Sphinx does not read;
- ``api/<package>.md``: one autodoc page per package (mjed, reference_fem, common, comparisons,
  meshes, and conformance when it exists), one section per module;
- ``tutorials/<name>.md`` and its figures: each ``docs/tutorials/*.py`` executed by
  ``tutorial_runner`` (reused when its source key matches, see there).

At ``build-finished`` it copies the parts of Debian's MathJax 2 that the pages use into
``_static/mathjax`` so formulas render with no network.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import shutil
import sys
from pathlib import Path
from typing import List, Tuple

from sphinx.errors import ExtensionError
from sphinx.util import logging

sys.path.insert(0, str(Path(__file__).parent))
import tutorial_runner  # noqa: E402

LOG = logging.getLogger(__name__)
ROOT = tutorial_runner.ROOT
API_PACKAGES = ("mjed", "reference_fem", "common", "comparisons", "meshes", "conformance")
MATHJAX_SOURCE = Path("/usr/share/javascript/mathjax")
# What MathJax 2's TeX-AMS_CHTML configuration loads (the fonts are CommonHTML's woff files).
MATHJAX_PARTS = (
    "MathJax.js",
    "config/TeX-AMS_CHTML.js",
    "extensions",
    "jax/input/TeX",
    "jax/output/CommonHTML",
    "jax/element",
    "fonts/HTML-CSS/TeX/woff",
)


def generated_dir(app) -> Path:
    return Path(app.srcdir) / "generated"


# ---------------------------------------------------------------------------- CLI
def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:  # argparse keeps subcommands in a _SubParsersAction
        if isinstance(action, argparse._SubParsersAction):
            return action.choices
    return {}


def _option_rows(parser: argparse.ArgumentParser) -> List[Tuple[str, str, str]]:
    rows = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        names = ", ".join(action.option_strings) or action.dest
        default = "" if action.default in (None, argparse.SUPPRESS, False) else repr(action.default)
        text = (action.help or "").replace("\n", " ")
        if "%(" in text:
            try:
                text = text % {"default": action.default, "prog": parser.prog}
            except (KeyError, TypeError, ValueError):
                pass
        rows.append((names, default, _md_text(text)))
    return rows


def _md_text(text: str) -> str:
    """Help text as Markdown prose: a table cell's bars and angle brackets are literal."""
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("<", "\\<").replace(">", "\\>")


def cli_page() -> str:
    """The command-line reference as MyST, from the live parsers."""
    os.environ["COLUMNS"] = "100"  # stable wrapping of argparse's help text
    from comparisons.cli import build_parser

    parser = build_parser()
    out = [
        "# Command-line reference",
        "",
        "Generated when the site is built, from the parsers themselves "
        "(`comparisons.cli.build_parser()`); each subcommand is one module of "
        "`comparisons/commands/`. Every subcommand refuses bad input before any work with exit "
        "code 2 and exits with 1 when a check fails (see {doc}`../getting_started`).",
        "",
        "```text",
        parser.format_help().rstrip(),
        "```",
        "",
    ]
    for name, sub in _subparsers(parser).items():
        out += [
            f"## `mjed-verify {name}`",
            "",
            _md_text((sub.description or "").strip()),
            "",
            "| option | default | meaning |",
            "|---|---|---|",
        ]
        out += [f"| `{n}` | {'`' + d + '`' if d else ''} | {t} |" for n, d, t in _option_rows(sub)]
        out += ["", "```text", sub.format_help().rstrip(), "```", ""]
    return "\n".join(out)


# ---------------------------------------------------------------------------- API
def _modules(package: str) -> Tuple[List[str], List[Tuple[str, str]]]:
    """Importable modules of ``package`` and (module, reason) for those that fail to import."""
    pkg = importlib.import_module(package)
    names = [package] + sorted(
        info.name
        for info in pkgutil.walk_packages(pkg.__path__, prefix=package + ".")
        if not info.name.rsplit(".", 1)[-1].startswith("__")
    )
    good, bad = [], []
    for name in names:
        try:
            importlib.import_module(name)
            good.append(name)
        except Exception as exc:  # noqa: BLE001 - reported on the page
            bad.append((name, f"{type(exc).__name__}: {exc}"))
    return good, bad


def _is_package(name: str) -> bool:
    # A package's __all__ re-exports its submodules' names; documenting them there too would
    # describe every object twice.
    return hasattr(importlib.import_module(name), "__path__")


def api_page(package: str) -> str:
    good, bad = _modules(package)
    out = [
        f"# `{package}`",
        "",
        f"Generated from the docstrings (autodoc) when the site is built: {len(good)} modules.",
        "",
    ]
    if bad:
        out += [
            "Not documented here because they could not be imported in the build's environment:",
            "",
        ]
        out += [f"- `{name}`: {reason}" for name, reason in bad] + [""]
    for name in good:
        out += (
            [
                f"## `{name}`",
                "",
                "```{eval-rst}",
                f".. automodule:: {name}",
                "   :members:",
                "   :show-inheritance:",
            ]
            + (["   :ignore-module-all:"] if _is_package(name) else [])
            + ["```", ""]
        )
    return "\n".join(out)


def api_packages() -> List[str]:
    return [p for p in API_PACKAGES if (ROOT / p / "__init__.py").exists()]


# ---------------------------------------------------------------------------- tutorials
def tutorial_cache(app) -> Path:
    """Where executed tutorials are kept: $MJED_TUTORIAL_CACHE, else docs/_build/tutorials."""
    env = os.environ.get("MJED_TUTORIAL_CACHE")
    return Path(env) if env else Path(app.srcdir) / "_build" / "tutorials"


def tutorial_page(script: Path, run: "tutorial_runner.Execution", target: Path) -> None:
    """Copy the executed page and figures to ``target/<stem>.md`` and ``target/<stem>/``."""
    fig_dir = target / script.stem
    if fig_dir.exists():
        shutil.rmtree(fig_dir)
    fig_dir.mkdir(parents=True)
    for png in run.outdir.glob("fig*.png"):
        shutil.copy2(png, fig_dir / png.name)
    body = (run.outdir / "page.md").read_text()
    body = body.replace("](fig", f"]({script.stem}/fig")
    header = (
        "```{admonition} Run it yourself\nThis page is the executed file "
        f"{{download}}`docs/tutorials/{script.name} </tutorials/{script.name}>` (jupytext percent "
        "format: `jupytext --to notebook` opens it in Jupyter). From the repository: "
        f"`.venv/bin/python docs/tutorials/{script.name}`. Its `assert` lines are checked by `make "
        f"test` (`tests/test_tutorials.py`); it ran in {run.seconds:.1f} s for this build.\n```\n\n"
    )
    lines = body.splitlines()
    # Put the admonition after the title (the first Markdown heading).
    idx = next((i for i, line in enumerate(lines) if line.startswith("# ")), -1)
    page = "\n".join(lines[: idx + 1]) + "\n\n" + header + "\n".join(lines[idx + 1 :]) + "\n"
    (target / f"{script.stem}.md").write_text(page)


def generate(app) -> None:
    gen = generated_dir(app)
    (gen / "api").mkdir(parents=True, exist_ok=True)
    _write_if_changed(gen / "cli.md", cli_page())
    _write_if_changed(gen / MATERIALS_TABLE, materials_table())
    for package in api_packages():
        _write_if_changed(gen / "api" / f"{package}.md", api_page(package))
    tut_target = gen / "tutorials"
    tut_target.mkdir(parents=True, exist_ok=True)
    scripts = tutorial_runner.tutorial_scripts(Path(app.srcdir) / "tutorials")
    for stale in tut_target.glob("*.md"):
        if stale.stem not in {s.stem for s in scripts}:
            stale.unlink()
    failures = []
    for script in scripts:
        run = tutorial_runner.ensure_executed(script, tutorial_cache(app))
        LOG.info(
            f"tutorial {script.name}: {'reused' if run.reused else 'executed'} ({run.seconds:.1f} "
            "s)"
        )
        if not run.ok:
            failures.append(run.error)
            continue
        tutorial_page(script, run, tut_target)
    if failures:
        raise ExtensionError("tutorials failed:\n\n" + "\n\n".join(failures))


def _write_if_changed(path: Path, text: str) -> None:
    # Unchanged files keep their time stamp, so Sphinx does not re-read them.
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


# ---------------------------------------------------------------------------- materials
#: The materials table, relative to the generated folder (conventions.md includes it).
MATERIALS_TABLE = "materials.inc"


def materials_table() -> str:
    """The table of every declared material: written at each build, so it cannot fall behind."""
    from mjed.materials.declaration import docs_table

    return docs_table() + "\n"


# ---------------------------------------------------------------------------- MathJax
def copy_mathjax(app, exception) -> None:
    if exception is not None or app.builder.format != "html":
        return
    if not (MATHJAX_SOURCE / "MathJax.js").exists():
        raise ExtensionError(
            f"MathJax 2 not found at {MATHJAX_SOURCE} (Debian package libjs-mathjax)"
        )
    dest = Path(app.outdir) / "_static" / "mathjax"
    for part in MATHJAX_PARTS:
        src, dst = MATHJAX_SOURCE / part, dest / part
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            shutil.copytree(src, dst, dirs_exist_ok=True)  # follows Debian's font symlinks
        else:
            shutil.copy2(src, dst)


# ---------------------------------------------------------------------------- docstrings
def escape_bars(app, what, name, obj, options, lines) -> None:
    """The code's docstrings are plain text where |x| is an absolute value or ||A|| a norm;
    reST would read them as substitution references (and emit links to nowhere).
    """
    lines[:] = [line.replace("|", "\\|") for line in lines]


def setup(app):
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", escape_bars)
    app.connect("build-finished", copy_mathjax)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
