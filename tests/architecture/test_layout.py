"""The shape of the code: pure models, files of one job.

A model module imports neither Zenoh nor the service runtime (checked in a fresh
interpreter, through ``sys.modules``), and no module of the product is longer than
about 450 lines unless it says at its top why it must be.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.harness import ROOT

MODELS = sorted(str(p.relative_to(ROOT).with_suffix("")).replace("/", ".")
                for p in (ROOT / "services").glob("*/model.py"))
PURE = [*MODELS, "services.composed", "services.drive.budget", "common.traverse",
        "common.scenario", "common.conditions", "common.config",
        "common.faults", "common.keys", "common.messages", "services.bridge.mapping",
        "services.battery.circuit", "services.battery.packs", "services.battery.prediction",
        "services.bridge.convert", "services.bridge.cdr",
        "services.bridge.rmw_zenoh", "services.bridge.bindings"]
MAX_LINES = 450
REASON_MARK = "Longer than"  # how a module says why it is long, in its docstring


def test_there_are_models():
    assert "services.battery.model" in MODELS and len(MODELS) >= 7


@pytest.mark.parametrize("module", PURE)
def test_pure_module_imports_neither_zenoh_nor_the_runtime(module):
    code = (f"import sys, json, {module}; "
            "print(json.dumps(sorted(m for m in sys.modules if m == 'zenoh' "
            "or m.startswith('zenoh.') or m == 'common.runtime')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=60, check=True)
    assert json.loads(out.stdout) == [], f"{module} imports {out.stdout.strip()}"


def test_no_module_is_too_long_without_saying_why():
    long = []
    for folder in ("common", "services", "lunaris"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            text = path.read_text()
            lines = text.count("\n")
            if lines > MAX_LINES and REASON_MARK not in text[:2000]:
                long.append(f"{path.relative_to(ROOT)}: {lines} lines")
    assert not long, "split these, or say at the top why they are long: " + "; ".join(long)


def test_the_committed_reference_is_generated_from_the_code():
    from lunaris.reference import DOCS, pages
    stale = [name for name, text in pages().items()
             if not (DOCS / name).is_file() or (DOCS / name).read_text() != text]
    assert not stale, f"docs/reference is stale: {stale}; run python -m lunaris.reference"
