"""The imports of the house, read from the code (``ast``): who imports what, on which line.

Every ``import`` and ``from ... import`` statement counts wherever it stands: at the top, in a
function (an import put off until it is needed is still a dependency) and under
``TYPE_CHECKING`` (a type is a dependency too). A name is resolved to the deepest module of
the tree it names (``from services.bridge import mapping`` is ``services.bridge.mapping``,
``from common.keys import event`` is ``common.keys``); a script's import of a sibling
(``from benchlib import ...`` in ``bench/``) to that sibling; anything else to its top-level
package (``zenoh``, ``msgspec``). Modules loaded by name at run time (``importlib``: ``lunaris
run`` loading ``services.<name>.service``) are not imports and are not seen.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Graph", "Import", "imports_in", "module_of", "read_tree"]


@dataclass(frozen=True)
class Import:
    importer: str
    target: str
    file: str  # relative to the tree
    line: int

    def where(self) -> str:
        return f"{self.file}:{self.line}"


def module_of(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


class Graph:
    """The modules of some top-level folders of a tree, and their imports."""

    def __init__(self, modules: dict[str, str]):
        self.modules = modules  # module -> its file, relative to the tree
        self.imports: list[Import] = []

    def resolve(self, name: str, importer: str) -> str:
        if name in self.modules:
            return name
        top = name.split(".")[0]
        if any(m == top or m.startswith(top + ".") for m in self.modules):
            while "." in name and name not in self.modules:
                name = name.rsplit(".", 1)[0]
            return name
        sibling = f"{importer.rsplit('.', 1)[0]}.{name}" if "." in importer else name
        if sibling in self.modules:
            return sibling  # a script's import of the script beside it
        return top

    def add_source(self, text: str, importer: str, file: str) -> list[Import]:
        """Read the imports of ``text``, as the module ``importer`` (in ``file``)."""
        package = importer if file.endswith("__init__.py") else importer.rpartition(".")[0]
        found = []
        for node in ast.walk(ast.parse(text, file)):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*anchor, *([base] if base else [])])
                names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in self.modules else base
                         for alias in node.names]
            else:
                continue
            for name in dict.fromkeys(names):
                target = self.resolve(name, importer)
                if target != importer:
                    found.append(Import(importer, target, file, node.lineno))
        self.imports += found
        return found

    def targets(self, module: str) -> set[str]:
        return {i.target for i in self.imports if i.importer == module}

    def edges(self) -> dict[str, set[str]]:
        out: dict[str, set[str]] = {m: set() for m in self.modules}
        for i in self.imports:
            if i.target in self.modules:
                out[i.importer].add(i.target)
        return out


def read_tree(root: Path, folders: Iterable[str]) -> Graph:
    """Every ``.py`` file under ``folders`` of ``root`` (a folder without ``__init__.py``, as
    ``bench/``, is read as a package of scripts)."""
    files = sorted(p for folder in folders for p in (root / folder).rglob("*.py")
                   if "node_modules" not in p.parts)
    graph = Graph({module_of(p, root): str(p.relative_to(root)) for p in files})
    for p in files:
        graph.add_source(p.read_text(), module_of(p, root), str(p.relative_to(root)))
    return graph


def imports_in(graph: Graph, module: str) -> list[Import]:
    return [i for i in graph.imports if i.importer == module]
