"""The shape of the code: files of one job, a reference generated from the code.

No module of the product is longer than about 450 lines unless it says at its top why it
must be. (That models import no runtime and no Zenoh is a rule of the contract of layers,
test_layers.py, with the others.)
"""

from __future__ import annotations

from tests.harness import ROOT

MAX_LINES = 450
REASON_MARK = "Longer than"  # how a module says why it is long, in its docstring


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
