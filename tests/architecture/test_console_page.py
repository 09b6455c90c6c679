"""The console's page as code: its types generated from the payload Structs, its modules
linted and type-checked, its vendored libraries the published ones, nothing loaded from
elsewhere.

ESLint and the TypeScript checker come from the npm registry (``package.json``,
``package-lock.json`` at the root): ``npm ci`` installs them, ``npm run lint`` runs both.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import pytest

from lunaris.console.types import TARGET, source
from tests.harness import ROOT

STATIC = ROOT / "lunaris" / "console" / "static"
BIN = ROOT / "node_modules" / ".bin"
IMPORT = re.compile(r"""(?:^|\n)\s*(?:import|export)\s[^;'"]*?from\s+["']([^"']+)["']"""
                    r"""|import\(\s*["']([^"']+)["']\s*\)""")  # import ... from "x", import("x")


def modules() -> list:
    return sorted(p for p in STATIC.rglob("*.js") if "vendor" not in p.parts)


def test_the_committed_page_types_are_generated_from_the_messages():
    assert TARGET.read_text() == source(), "lunaris/console/static/types.js is stale: " \
        "run python -m lunaris.console.types"


def test_every_import_of_the_page_is_one_of_its_own_files():
    assert len(modules()) >= 10
    for path in modules():
        text = path.read_text()
        for found in IMPORT.finditer(text):
            spec = found.group(1) or found.group(2)
            assert spec.startswith(("./", "../")), f"{path.name} imports {spec!r}: not a file of the page"
            assert (path.parent / spec).resolve().is_file(), f"{path.name} imports {spec!r}: no such file"
    html = (STATIC / "index.html").read_text()
    assert not re.search(r"(?:src|href)=[\"']?(?:https?:)?//", html), "index.html loads from elsewhere"
    assert re.findall(r"<script[^>]*>", html) == ['<script type="module" src="/static/main.js">']


def _imports(path) -> set:
    return {(path.parent / (f.group(1) or f.group(2))).resolve() for f in IMPORT.finditer(path.read_text())}


def test_a_view_imports_no_other_view():
    """A view (a module views/index.js registers) uses the page's shared modules, never another
    view's internals (issue 30: the Crew and Faults views took clearFault from the Live view,
    the Live and Inputs views the rover files' descriptions from the Map view)."""
    index = STATIC / "views" / "index.js"
    views = {p for p in _imports(index) if p.parent == index.parent}  # (not a type of state.js)
    assert len(views) >= 8
    for view in sorted(views):
        crossing = sorted(p.name for p in _imports(view) & views)
        assert not crossing, f"the view {view.name} imports the view(s) {crossing}: move what they share " \
            "to a module of the page (widgets.js, rovers.js, state.js)"


def test_the_vendored_libraries_are_the_versions_package_json_names():
    dev = json.loads((ROOT / "package.json").read_text())["devDependencies"]
    lock = json.loads((ROOT / "package-lock.json").read_text())["packages"]
    said = (STATIC / "VENDORED.txt").read_text()
    for package, name in (("lit-html", "lit-html"), ("uplot", "uPlot")):
        assert lock[f"node_modules/{package}"]["version"] == dev[package]
        assert f"{name} {dev[package]} (package {package})" in said


COPIES = {  # vendored file -> its file in the npm package
    "lit-html/lit-html.js": "lit-html/lit-html.js", "lit-html/lit-html.d.ts": "lit-html/lit-html.d.ts",
    "lit-html/directive.js": "lit-html/directive.js", "lit-html/directive.d.ts": "lit-html/directive.d.ts",
    "lit-html/directive-helpers.js": "lit-html/directive-helpers.js",
    "lit-html/directive-helpers.d.ts": "lit-html/directive-helpers.d.ts",
    "lit-html/directives/keyed.js": "lit-html/directives/keyed.js",
    "lit-html/directives/keyed.d.ts": "lit-html/directives/keyed.d.ts",
    "lit-html/LICENSE": "lit-html/LICENSE",
    "uplot/uPlot.esm.js": "uplot/dist/uPlot.esm.js", "uplot/uPlot.esm.d.ts": "uplot/dist/uPlot.d.ts",
    "uplot/uPlot.min.css": "uplot/dist/uPlot.min.css", "uplot/LICENSE": "uplot/LICENSE",
}


def _needs_npm_ci() -> None:
    if not (BIN / "eslint").exists() or not (BIN / "tsc").exists():
        pytest.skip("the page's tools are not installed: run npm ci at the repository's root")


def test_the_vendored_files_are_the_published_packages_verbatim():
    vendored = {str(p.relative_to(STATIC / "vendor")) for p in (STATIC / "vendor").rglob("*") if p.is_file()}
    assert vendored == set(COPIES)
    _needs_npm_ci()
    for mine, theirs in COPIES.items():
        assert (STATIC / "vendor" / mine).read_bytes() == (ROOT / "node_modules" / theirs).read_bytes(), mine


@pytest.mark.timeout(300)
def test_the_page_passes_eslint_and_the_type_check():
    _needs_npm_ci()
    node = shutil.which("node")
    assert node is not None
    for tool, args in (("eslint", ["--max-warnings", "0"]), ("tsc", ["-p", "jsconfig.json"])):
        done = subprocess.run([str(BIN / tool), *args], cwd=ROOT, capture_output=True, text=True, timeout=240)
        assert done.returncode == 0, f"{tool}:\n{done.stdout}\n{done.stderr}"
