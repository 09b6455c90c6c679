"""The contract of layers (issue 24, STYLE habit 12), checked on every import of the code.

The floors, from the ground up::

    common  <  services  <  lunaris  <  testbed  <  bench | tests

1. **Models are pure.** A model (``services/*/model.py``) and the pure modules the tools and
   the models run (:data:`PURE`) import no runtime (``common.runtime``) and no Zenoh, not even
   through another module (their whole closure is followed, parent packages included).
2. **Each floor imports only the floors below it.** ``common`` imports nothing above it, the
   services nothing of the CLI (``lunaris``), the CLI nothing of the test bed, the benchmarks
   and the tests; ``testbed`` (what the tests and the benchmarks run the twin with) nothing of
   either; ``bench`` nothing of ``tests`` and ``tests`` nothing of ``bench``.
3. **The CLI imports of the services only their public modules** (:data:`PUBLIC_TO_THE_CLI`):
   the bridge's face (``services.bridge``: the mapping format, the shipped mapping, a mapping
   over a fleet) and the models a tool runs in its own process, as ``lunaris sim`` and
   ``lunaris predict`` run the composed twin (the package ``services/composed``, its
   ``budget.py``, ``battery/prediction.py``, any ``services/*/model.py``). Never a service's process
   (``service.py``, ``query.py``, the bridge's outlets) nor the rest of a package: a
   service runs in its own process, started by name (``lunaris run`` loads
   ``services.<name>.service`` with importlib: the one way in, and not an import).
4. **The services stand apart.** A service's modules import of ``services`` only their own
   package's; the package ``services/composed`` alone puts the services' models together.
5. **No circles** among the modules of ``common``, ``services``, ``lunaris``, ``testbed``
   and ``bench``.
6. **The client imports nothing of the console** (``lunaris.client`` is what every tool and
   the console share; the console is one of its users).

Known exceptions (:data:`KNOWN_EXCEPTIONS`): none. Issue 30 removed the last five: the
circle ``runtime -> fault_book / session -> runtime`` (they depend on :mod:`common.host`, a
protocol), the battery's query reading the loads' and PDM's models (one rule of a faulty load's
power in :func:`common.faults.held_power_w`; the rail's reason word in :mod:`common.messages`),
and the traverse budget beside the composed twin (``services/composed/budget.py``). An edge
waived here must still be there and still break a rule.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import pytest

from tests.architecture.imports import Graph, Import, read_tree
from tests.harness import ROOT

FLOORS = {"common": 0, "services": 1, "lunaris": 2, "testbed": 3, "bench": 4, "tests": 4}
CIRCLE_FREE = ("common", "services", "lunaris", "testbed", "bench")
RUNTIME = ("zenoh", "common.runtime")
PURE = ("services.composed", "services.composed.budget", "services.battery.circuit",
        "services.battery.packs", "services.battery.prediction", "services.bridge",
        "services.bridge.mapping", "services.bridge.bindings", "services.bridge.convert",
        "services.bridge.cdr", "services.bridge.rmw_zenoh", "common.config", "common.conditions",
        "common.faults", "common.keys", "common.messages", "common.scenario", "common.traverse")
PUBLIC_TO_THE_CLI = ("services.bridge", "services.composed", "services.composed.budget",
                     "services.battery.prediction")
SERVICE_PACKAGES = ("battery", "bridge", "clock", "drive", "faults", "loads", "power", "radio",
                    "solar")

KNOWN_EXCEPTIONS: dict[tuple[str, str], str] = {}  # none: issue 30 removed the last five


def top(module: str) -> str:
    return module.split(".")[0]


def top_two(module: str) -> str:
    return ".".join(module.split(".")[:2])


def is_model(module: str) -> bool:
    parts = module.split(".")
    return len(parts) == 3 and parts[0] == "services" and parts[2] == "model"


def service_of(module: str) -> str | None:
    """The service package a module belongs to (``battery`` for services.battery.query)."""
    parts = module.split(".")
    return parts[1] if len(parts) >= 2 and parts[0] == "services" and parts[1] in SERVICE_PACKAGES \
        else None


# == the rules: each returns its violations, in words ========================================


def pure_models(g: Graph) -> list[str]:
    """Rule 1: the closure of each model and pure module holds no runtime and no Zenoh."""
    edges = g.edges()
    for i in g.imports:  # importing a.b.c runs a/__init__ and a/b/__init__ first
        parts = i.target.split(".")
        for n in range(1, len(parts)):
            if ".".join(parts[:n]) in g.modules:
                edges[i.importer].add(".".join(parts[:n]))
    runtime = [i for i in g.imports if i.target in RUNTIME]
    out = []
    for source in sorted({m for m in g.modules if is_model(m)} | set(PURE)):
        seen, todo = {source: [source]}, [source]
        while todo:
            m = todo.pop(0)
            for t in sorted(edges.get(m, ())):
                if t not in seen:
                    seen[t] = [*seen[m], t]
                    todo.append(t)
        for i in runtime:
            if i.importer in seen:
                chain = " -> ".join([*seen[i.importer], i.target])
                out.append(f"{source} imports {i.target} ({chain}; {i.where()}): "
                           "a model imports no runtime and no Zenoh")
    return sorted(set(out))


def floors(g: Graph) -> list[str]:
    """Rule 2: no import to a higher floor, nor between bench and tests."""
    out = []
    for i in g.imports:
        a, b = top(i.importer), top(i.target)
        if b not in FLOORS or a == b:
            continue
        if FLOORS[b] > FLOORS[a] or (FLOORS[b] == FLOORS[a] == 4):
            out.append(f"{i.where()}: {i.importer} imports {i.target}: {a} imports nothing of {b} "
                       f"(floors: common < services < lunaris < testbed < bench | tests)")
    return out


def cli_public_only(g: Graph) -> list[str]:
    """Rule 3: the CLI imports of the services only their public modules."""
    return [f"{i.where()}: {i.importer} imports {i.target}: the CLI imports of the services only "
            f"{', '.join(PUBLIC_TO_THE_CLI)} and services/*/model.py"
            for i in g.imports if top(i.importer) == "lunaris" and top(i.target) == "services"
            and not (i.target in PUBLIC_TO_THE_CLI or is_model(i.target))]


def services_apart(g: Graph) -> list[str]:
    """Rule 4: a service imports of services only its own package; composed only the models."""
    out = []
    for i in g.imports:
        if top(i.importer) != "services" or top(i.target) != "services":
            continue
        mine, theirs = service_of(i.importer), service_of(i.target)
        if mine is not None and theirs == mine:
            continue
        if top_two(i.importer) == "services.composed" and (
                is_model(i.target) or top_two(i.target) == "services.composed"):
            continue
        out.append(f"{i.where()}: {i.importer} imports {i.target}: a service imports of services/ "
                   "only its own package, and the package services/composed alone puts the models together")
    return out


def no_circles(g: Graph) -> list[str]:
    """Rule 5: no strongly connected component of more than one module (Tarjan)."""
    edges = {m: {t for t in ts if top(t) in CIRCLE_FREE}
             for m, ts in g.edges().items() if top(m) in CIRCLE_FREE}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            scc = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                scc.append(w)
                if w == v:
                    break
            if len(scc) > 1:
                circles.append(sorted(scc))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    out = []
    for scc in circles:
        ties = [i for i in g.imports if i.importer in scc and i.target in scc]
        out.append("a circle: " + ", ".join(scc) + " - tied by " + "; ".join(
            f"{i.importer} -> {i.target} ({i.where()})" for i in ties))
    return out


def client_apart(g: Graph) -> list[str]:
    """Rule 6: the tools' client (``lunaris.client``: the mirror, the writer, the runner every
    tool shares) imports nothing of the console, which is one of its users."""
    return [f"{i.where()}: {i.importer} imports {i.target}: lunaris.client imports nothing of "
            "lunaris.console (the console uses the client, not the reverse)"
            for i in g.imports if i.importer.startswith("lunaris.client")
            and (i.target == "lunaris.console" or i.target.startswith("lunaris.console."))]


RULES: dict[str, Callable[[Graph], list[str]]] = {
    "models are pure": pure_models,
    "each floor imports only the floors below it": floors,
    "the CLI imports of the services only their public modules": cli_public_only,
    "the services stand apart": services_apart,
    "no circles": no_circles,
    "the client imports nothing of the console": client_apart,
}


@functools.cache
def _as_written() -> Graph:
    return read_tree(ROOT, FLOORS)


def the_house(extra: tuple[str, str] | None = None) -> Graph:
    """The tree's import graph, the known exceptions left out; ``extra``: (module, source) whose
    imports are added as if that module held them (a violation made on purpose)."""
    g = Graph(_as_written().modules)
    g.imports = [i for i in _as_written().imports if (i.importer, i.target) not in KNOWN_EXCEPTIONS]
    if extra is not None:
        module, source = extra
        g.add_source(source, module, g.modules[module])
    return g


@pytest.fixture(scope="module")
def house() -> Graph:
    return the_house()


@pytest.mark.parametrize("rule", RULES)
def test_the_rule_holds(house, rule):
    broken = RULES[rule](house)
    assert not broken, f"{rule}:\n  " + "\n  ".join(broken)


def test_the_contract_sees_the_whole_house(house):
    models = [m for m in house.modules if is_model(m)]
    assert "services.battery.model" in models and len(models) >= 7, models
    named = {*PURE, *PUBLIC_TO_THE_CLI, *RUNTIME[1:], *(a for a, _ in KNOWN_EXCEPTIONS)}
    missing = named - set(house.modules)
    assert not missing, f"named by the contract, not in the tree: {sorted(missing)}"
    assert {top(m) for m in house.modules} == set(FLOORS)
    assert len(house.imports) > 1000


def test_every_known_exception_is_still_there_and_still_an_exception():
    g = _as_written()
    found = {(i.importer, i.target) for i in g.imports}
    gone = [f"{a} -> {b} ({why})" for (a, b), why in KNOWN_EXCEPTIONS.items() if (a, b) not in found]
    assert not gone, "no longer imported: remove from KNOWN_EXCEPTIONS: " + "; ".join(gone)
    kept = Graph(g.modules)
    for (a, b), why in KNOWN_EXCEPTIONS.items():
        kept.imports = [i for i in g.imports if (i.importer, i.target) not in KNOWN_EXCEPTIONS
                        or (i.importer, i.target) == (a, b)]
        assert any(rule(kept) for rule in RULES.values()), \
            f"{a} -> {b} breaks no rule any more: remove it from KNOWN_EXCEPTIONS ({why})"


# A violating import of each rule, added to the real tree: the contract must catch each.
VIOLATIONS = {
    "models are pure": ("services.power.model", "import zenoh\n"),
    "models are pure, through another module": ("services.solar.model",
                                                "from common.connection import write\n"),
    "each floor imports only the floors below it": ("common.keys", "from lunaris.up import main\n"),
    "services import nothing of the CLI": ("services.battery.service", "import lunaris.client\n"),
    "bench imports nothing of tests": ("bench.fleet", "from tests.harness import Probe\n"),
    "the CLI imports of the services only their public modules": (
        "lunaris.pdm", "from services.bridge.service import serve\n"),
    "the services stand apart": ("services.radio.model", "from services.power.model import PowerModel\n"),
    "no circles": ("lunaris.deploy_dashboard", "from lunaris.deploy_secrets import client_config\n"),
    "no circles, the runtime's either": ("common.fault_book", "from common.runtime import Runtime\n"),
    "no circles, nor for the types alone": (
        "common.session",
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from common.runtime import Runtime\n"),
    "the client imports nothing of the console": ("lunaris.client.writer",
                                                   "from lunaris.console.auth import User\n"),
    "the services stand apart, the battery's query too": (
        "services.battery.query", "from services.loads.model import LoadsModel\n"),
}


@pytest.mark.parametrize("case", VIOLATIONS)
def test_a_violating_import_breaks_the_contract(case):
    module, source = VIOLATIONS[case]
    g = the_house((module, source))
    broken = [v for rule in RULES.values() for v in rule(g)]
    assert any(module in v for v in broken), f"{case}: {source.strip()} in {module} went unseen"


def test_the_imports_are_read_wherever_they_stand():
    g = Graph({"p": "p/__init__.py", "p.a": "p/a.py", "p.b": "p/b.py", "bench.s": "bench/s.py",
               "bench.lib": "bench/lib.py"})
    found = g.add_source("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from p.b import X\n"
                         "def f():\n    from . import b\n    import zenoh.ext as z\n", "p.a", "p/a.py")
    assert [(i.target, i.line) for i in found] == [("typing", 1), ("p.b", 3), ("p.b", 5), ("zenoh", 6)]
    assert [i.target for i in g.add_source("from lib import x\n", "bench.s", "bench/s.py")] == ["bench.lib"]
    assert [i.target for i in g.add_source("from p import b\n", "bench.s", "bench/s.py")] == ["p.b"]
    assert [i.target for i in g.add_source("from p.b import thing\n", "bench.s", "bench/s.py")] == ["p.b"]
    assert isinstance(found[0], Import)
