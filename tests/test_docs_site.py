"""The documentation site, built from the working tree and looked at in headless Chromium.

The build (tests/docs_support.built_site: Sphinx into a temporary directory, tutorials
executed once per session) must succeed without warnings about the site's own pages. Then
every HTML page is served on 127.0.0.1 and opened in Debian's Chromium through
chromedriver's WebDriver HTTP interface (no Selenium needed):

- the page loads (readyState complete, a title);
- every image has a non-zero natural size (the tutorials' figures are real PNGs);
- every formula was typeset by MathJax: each Sphinx math element holds a rendered CommonHTML
  node with a non-zero width and no MathJax error, and no raw TeX delimiters remain;
- every internal link points to an existing file, and a link with a fragment to an element
  with that id on the target page.

Skipped, saying why, when chromium or chromedriver is not installed.
"""

from __future__ import annotations

import functools
import http.server
import json
import re
import shutil
import socket
import subprocess
import tempfile
import threading
import time
import urllib.error
import urllib.parse
import urllib.request

import pytest
from docs_support import DOCS, ROOT, built_site, tutorial_runner

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-dev-shm-usage",
]

# The toctree lists pages written in other branches by glob patterns; until they land,
# Sphinx says the pattern matched nothing. Any other warning about a file of docs/ is a
# defect, and so is one about the code's docstrings (they name the Python file, or, for a
# module attribute, only "docstring of module.NAME").
TOLERATED = re.compile(r"toctree glob pattern '[^']*' didn't match any documents")

# Runs in the page once it has loaded: waits for MathJax (if the page has math), then reports.
INSPECT = r"""
const done = arguments[arguments.length - 1];
const math = document.querySelectorAll('div.math, span.math');
function report(mathjaxReady) {
  const formulas = Array.from(math).map(el => {
    const out = el.querySelector('.MathJax_CHTML');
    return {rendered: !!out, width: out ? out.getBoundingClientRect().width : 0,
            error: !!el.querySelector('.MathJax_Error, merror, .mjx-merror'),
            raw: /\\\(|\\\[/.test(el.textContent) && !out, tex: el.textContent.slice(0, 80)};
  });
  const images = Array.from(document.images).map(img => ({src: img.src, complete: img.complete,
      w: img.naturalWidth, h: img.naturalHeight}));
  const links = Array.from(document.querySelectorAll('a[href]')).map(a => a.href);
  const ids = Array.from(document.querySelectorAll('[id], a[name]'))
      .map(e => e.id || e.getAttribute('name'));
  done({ready: document.readyState, title: document.title, mathjaxReady, formulas, images, links,
        ids});
}
if (math.length === 0) { report(null); return; }
const t0 = Date.now();
(function wait() {
  if (window.MathJax && MathJax.Hub && MathJax.isReady) {
    MathJax.Hub.Queue(() => report(true));
    return;
  }
  if (Date.now() - t0 > 20000) { report(false); return; }
  setTimeout(wait, 50);
})();
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class WebDriver:
    """The few W3C WebDriver calls this test needs, over chromedriver's HTTP port."""

    def __init__(self, profile: str):
        self.port = _free_port()
        self.proc = subprocess.Popen(
            [CHROMEDRIVER, f"--port={self.port}"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        self.base = f"http://127.0.0.1:{self.port}"
        deadline = time.time() + 20
        while True:
            try:
                if self._call("GET", "/status")["value"]["ready"]:
                    break
            except (urllib.error.URLError, ConnectionError):
                pass
            if time.time() > deadline:
                self.proc.kill()
                raise RuntimeError("chromedriver did not start within 20 s")
            time.sleep(0.1)
        caps = {
            "capabilities": {
                "alwaysMatch": {
                    "browserName": "chrome",
                    "goog:chromeOptions": {
                        "binary": CHROMIUM,
                        "args": CHROMIUM_ARGS + [f"--user-data-dir={profile}"],
                    },
                }
            }
        }
        self.session = self._call("POST", "/session", caps)["value"]["sessionId"]
        self._call(
            "POST", f"/session/{self.session}/timeouts", {"script": 30000, "pageLoad": 30000}
        )

    def _call(self, method: str, path: str, body=None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(
            self.base + path, data=data, method=method, headers={"Content-Type": "application/json"}
        )
        with urllib.request.urlopen(req, timeout=60) as resp:
            return json.loads(resp.read().decode())

    def open(self, url: str) -> None:
        self._call("POST", f"/session/{self.session}/url", {"url": url})

    def run_async(self, script: str):
        return self._call(
            "POST", f"/session/{self.session}/execute/async", {"script": script, "args": []}
        )["value"]

    def quit(self) -> None:
        try:
            self._call("DELETE", f"/session/{self.session}")
        finally:
            self.proc.terminate()
            self.proc.wait(timeout=10)


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@functools.lru_cache(maxsize=None)
def site():
    build = built_site()
    assert build.returncode == 0, f"the site did not build:\n{build.output[-4000:]}"
    return build


@functools.lru_cache(maxsize=None)
def browsed_pages():
    """{relative page path: what INSPECT reported}, for every HTML page of the site."""
    html = site().html
    handler = functools.partial(_QuietHandler, directory=str(html))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    profile = tempfile.mkdtemp(prefix="mjed-chromium-")
    driver = WebDriver(profile)
    base = f"http://127.0.0.1:{server.server_address[1]}/"
    pages = {}
    try:
        for page in sorted(p.relative_to(html).as_posix() for p in html.rglob("*.html")):
            driver.open(base + page)
            pages[page] = driver.run_async(INSPECT)
    finally:
        driver.quit()
        server.shutdown()
        shutil.rmtree(profile, ignore_errors=True)
    return base, pages


needs_browser = pytest.mark.skipif(
    not (CHROMIUM and CHROMEDRIVER),
    reason="Debian's chromium and chromium-driver are not installed (scripts/bootstrap.sh installs "
    "them)",
)


def _own_warnings(output: str) -> list:
    """The warning and error lines of a build's output about the project's own files.

    Those about a page of docs/ or a Python file of the repository (both start with the
    repository's path) and those about a module attribute's docstring (autodoc names no file
    for it: "docstring of module.NAME:line: ..."), less the TOLERATED message.
    """
    return [
        line
        for line in output.splitlines()
        if line.startswith((f"{DOCS}/", f"{ROOT}/", "docstring of "))
        and ("WARNING" in line or "ERROR" in line)
        and not TOLERATED.search(line)
    ]


def test_site_builds_without_warnings_about_its_pages():
    build = site()
    own = _own_warnings(build.output)
    assert not own, "warnings about the site's pages or the code's docstrings:\n" + "\n".join(own)
    for page in (
        "index.html",
        "getting_started.html",
        "generated/cli.html",
        "generated/api/mjed.html",
        "studies/timing.html",
        "_static/mathjax/MathJax.js",
    ):
        assert (build.html / page).is_file(), page
    for script in tutorial_runner.tutorial_scripts():
        assert (build.html / "generated" / "tutorials" / f"{script.stem}.html").is_file(), (
            script.name
        )


def test_cli_reference_lists_every_subcommand_from_the_parser():
    from comparisons.cli import command_modules

    text = (site().html / "generated" / "cli.html").read_text()
    for name in command_modules():
        assert f"mjed-verify {name}" in text, name


def test_conventions_shows_a_row_per_declared_material():
    """The table the build writes from the declarations is on the page, under its heading."""
    from mjed.materials import declarations

    text = (site().html / "conventions.html").read_text()
    table = text[text.index("The materials") :]
    table = table[: table.index("</table>")]
    for declaration in declarations():
        assert f'<span class="pre">{declaration.name}</span>' in table, declaration.name


@needs_browser
def test_every_page_loads():
    _, pages = browsed_pages()
    assert len(pages) >= 20
    bad = [p for p, r in pages.items() if r["ready"] != "complete" or not r["title"]]
    assert not bad, f"pages that did not load: {bad}"


@needs_browser
def test_every_figure_has_a_size():
    _, pages = browsed_pages()
    broken = [
        (p, img["src"])
        for p, r in pages.items()
        for img in r["images"]
        if not (img["complete"] and img["w"] > 0 and img["h"] > 0)
    ]
    assert not broken, f"images that did not load: {broken}"
    for script in tutorial_runner.tutorial_scripts():
        page = pages[f"generated/tutorials/{script.stem}.html"]
        figures = [img for img in page["images"] if "/_images/" in img["src"]]
        assert figures, f"{script.name} shows no figure"
        assert all(img["w"] > 100 and img["h"] > 100 for img in figures), (
            f"{script.name}: a figure is tiny"
        )


@needs_browser
def test_formulas_are_typeset_by_mathjax():
    _, pages = browsed_pages()
    with_math = {p: r for p, r in pages.items() if r["formulas"]}
    assert "generated/tutorials/one_tetrahedron.html" in with_math, (
        "the tutorials' formulas are missing"
    )
    for page, r in with_math.items():
        assert r["mathjaxReady"], (
            f"{page}: MathJax did not load (it is served from _static/mathjax)"
        )
        bad = [
            f["tex"]
            for f in r["formulas"]
            if not f["rendered"] or f["width"] <= 0 or f["error"] or f["raw"]
        ]
        assert not bad, f"{page}: formulas not rendered: {bad}"


@needs_browser
def test_internal_links_resolve():
    base, pages = browsed_pages()
    html = site().html
    broken = []
    for page, r in pages.items():
        for link in r["links"]:
            if not link.startswith(base):
                continue
            parsed = urllib.parse.urlsplit(link)
            target = (
                urllib.parse.unquote(parsed.path[len(urllib.parse.urlsplit(base).path) :])
                or "index.html"
            )
            if target.endswith("/"):
                target += "index.html"
            if not (html / target).is_file():
                broken.append((page, link, "no such file"))
            elif (
                parsed.fragment and target in pages and parsed.fragment not in pages[target]["ids"]
            ):
                broken.append((page, link, "no such anchor"))
    assert not broken, "broken internal links:\n" + "\n".join(map(str, broken))
