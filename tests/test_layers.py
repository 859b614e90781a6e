"""The package layers follow the loop's data flow, and no modules import each other in a circle.

Layers, lowest first (a module may import from its own layer and the layers below it, never above):

    helpers (errors, progress, configfile, vocabulary, _numba_cache, limits, files) -> scene -> sim -> agents
    -> render -> adapt -> curriculum -> report -> cli and bench -> the package entry points
    (``adaptenv/__init__.py`` and ``_gym``, which wire the layers together when asked).

Every import statement of every module under src/adaptenv is read with :mod:`ast`, including
imports inside functions and under ``if TYPE_CHECKING:``. What counts:

- Layers: every import, type-only ones included (a signature naming a higher layer's type is a
  dependency on that layer all the same).
- Cycles: every import that runs, function-local ones included. Imports under ``if TYPE_CHECKING:``
  never run, so two modules may name each other's types there without forming a cycle.
- ``import a.b.c`` also runs the parent packages' ``__init__`` modules; those implicit imports are
  not edges (a package's ``__init__`` importing its own submodules is how packages work).
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

#: Layer of each top-level name under ``adaptenv`` (module or package), lowest first.
LAYERS: dict[str, int] = {
    **dict.fromkeys(("errors", "progress", "configfile", "vocabulary", "_numba_cache", "limits", "files"), 0),
    "scene": 1, "sim": 2, "agents": 3, "render": 4, "adapt": 5, "curriculum": 6, "report": 7,
    "cli": 8, "bench": 8,
    "": 9, "_gym": 9,
}


@dataclass(frozen=True)
class Import:
    """One import of an adaptenv module by another."""

    source: str
    target: str
    line: int
    type_only: bool


def modules(src: Path) -> dict[str, Path]:
    """Dotted name -> file of every module and package under ``src/adaptenv``."""
    out = {}
    for path in sorted((src / "adaptenv").rglob("*.py")):
        parts = list(path.relative_to(src).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _statements(node: ast.AST, type_only: bool = False) -> Iterable[tuple[ast.Import | ast.ImportFrom, bool]]:
    """Every import statement under ``node`` (in functions and classes too), with whether it is type-only."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.Import | ast.ImportFrom):
            yield child, type_only
        elif isinstance(child, ast.If) and _type_checking(child.test):
            for stmt in child.body:
                yield from _statements(ast.Module(body=[stmt], type_ignores=[]), True)
            for stmt in child.orelse:
                yield from _statements(ast.Module(body=[stmt], type_ignores=[]), type_only)
        else:
            yield from _statements(child, type_only)


def _known(name: str, known: Mapping[str, Path]) -> str | None:
    """The module ``name`` names, or its nearest enclosing package (None outside adaptenv)."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(name: str, path: Path, known: Mapping[str, Path]) -> list[Import]:
    """The adaptenv modules module ``name`` (file ``path``) imports, anywhere in its code."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for stmt, type_only in _statements(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(stmt, ast.Import):
            targets = [a.name for a in stmt.names]
        else:
            base = stmt.module or ""
            if stmt.level:
                parent = package.split(".")[: len(package.split(".")) - stmt.level + 1]
                base = ".".join(parent + ([base] if base else []))
            # ``from pkg import sub`` imports the submodule when there is one, else a name of pkg
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in stmt.names]
        for target in targets:
            if target.split(".")[0] == "adaptenv" and (mod := _known(target, known)) and mod != name:
                out.append(Import(name, mod, stmt.lineno, type_only))
    return out


def all_imports(src: Path = SRC) -> list[Import]:
    known = modules(src)
    return [imp for name, path in known.items() for imp in imports_of(name, path, known)]


def layer(module: str) -> int | None:
    """The layer of an adaptenv module (None: a top-level name no layer is given for)."""
    parts = module.split(".")
    return LAYERS.get(parts[1] if len(parts) > 1 else "")


def upward(imports: Iterable[Import]) -> list[Import]:
    """Imports of a module from a higher layer."""
    return [i for i in imports if layer(i.target) > layer(i.source)]


def find_cycle(graph: Mapping[str, Iterable[str]]) -> list[str] | None:
    """One cycle of a directed graph as [a, b, ..., a] (depth-first search), or None when it has none."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


def runtime_graph(imports: Iterable[Import]) -> dict[str, set[str]]:
    """Module -> the modules it imports in code that runs (type-only imports left out)."""
    graph: dict[str, set[str]] = {}
    for i in imports:
        if not i.type_only:
            graph.setdefault(i.source, set()).add(i.target)
    return graph


def _show(imports: Iterable[Import]) -> str:
    return "\n".join(f"  {i.source} (line {i.line}) imports {i.target}" + (" [type-only]" if i.type_only else "")
                     for i in imports)


# -- the package --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def package_imports() -> list[Import]:
    return all_imports()


def test_every_module_has_a_layer():
    missing = sorted(m for m in modules(SRC) if layer(m) is None)
    assert not missing, f"give these modules a layer in tests/test_layers.py LAYERS: {missing}"


def test_no_module_imports_from_a_higher_layer(package_imports):
    bad = upward(package_imports)
    assert not bad, "imports from a higher layer:\n" + _show(bad)


def test_no_import_cycles(package_imports):
    cycle = find_cycle(runtime_graph(package_imports))
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_function_local_and_type_only_imports_are_read(package_imports):
    imports = package_imports
    # the CLI imports its commands' modules inside the command functions (adaptenv --help stays fast)
    assert any(i.source == "adaptenv.cli.agents" and i.target == "adaptenv.agents.evaluate" and not i.type_only
               for i in imports)
    assert any(i.type_only for i in imports)


# -- the checker, on planted violations ----------------------------------------------------------

def test_find_cycle_on_small_graphs():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b", "c"}, "b": {"d"}, "c": {"d"}, "d": set()}) is None  # a diamond is no cycle
    cycle = find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "x": {"a"}})
    assert cycle is not None and cycle[0] == cycle[-1] and set(cycle) == {"a", "b", "c"}
    assert find_cycle({"a": {"a"}}) == ["a", "a"]


def _tree(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / "adaptenv" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return root


@pytest.fixture
def planted(tmp_path):
    """A small adaptenv tree with an upward import and a cycle, both hidden in functions."""
    return _tree(tmp_path, {
        "__init__.py": "",
        "scene/__init__.py": "",
        "scene/house.py": "def load():\n    from adaptenv.scene.validate import check\n    return check\n",
        "scene/validate.py": "from adaptenv.scene.house import load\n\ndef check():\n    return load\n",
        "sim/__init__.py": "",
        "sim/task.py": "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from adaptenv.sim import world\n",
        "sim/world.py": "from adaptenv.sim.task import x\n",
        "adapt/__init__.py": "",
        "adapt/diagnosis.py": "from ..sim import task\n\ndef regret():\n    from adaptenv.curriculum.buffer import r\n",
        "curriculum/__init__.py": "",
        "curriculum/buffer.py": "r = 1\n",
    })


def test_checker_finds_planted_violations(planted):
    imports = all_imports(planted)
    assert [(i.source, i.target, i.line) for i in upward(imports)] == [
        ("adaptenv.adapt.diagnosis", "adaptenv.curriculum.buffer", 4)]
    # a relative import resolves to the module it names
    assert Import("adaptenv.adapt.diagnosis", "adaptenv.sim.task", 1, False) in imports
    cycle = find_cycle(runtime_graph(imports))
    assert cycle is not None and set(cycle) == {"adaptenv.scene.house", "adaptenv.scene.validate"}


def test_type_only_imports_count_for_layers_but_not_cycles(planted):
    imports = all_imports(planted)
    assert Import("adaptenv.sim.task", "adaptenv.sim.world", 4, True) in imports
    graph = runtime_graph(imports)
    assert "adaptenv.sim.world" not in graph.get("adaptenv.sim.task", set())  # sim's mutual import is type-only
    (planted / "adaptenv" / "sim" / "task.py").write_text("from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n"
                                                          "    from adaptenv.adapt import diagnosis\n")
    bad = upward(all_imports(planted))
    assert ("adaptenv.sim.task", "adaptenv.adapt.diagnosis") in [(i.source, i.target) for i in bad]
