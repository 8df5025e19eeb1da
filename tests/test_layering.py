"""The rooms of docs/architecture.md, checked on the source.

- The protocol's core imports neither its tools nor the companion, and its subpackages form
  layers (no cycle between them, no import inside a function to dodge one).
- The companion's product imports nothing simulated and nothing from the command line or the
  protocol's tools; the simulation does not import the command line.
- The radio and the credentials are the companion's bottom layers; its subpackages form
  layers too (radio, auth < mission < neighbours < runs < app < sim < cli).
- No product module reaches into another module's private attributes: components are used
  through their interfaces.
- No module of either package is part of an import cycle.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "companion")
COMMAND_LINE = ("companion.cli", "companion.__main__", "protocol.__main__")


def _name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_nodes(tree: ast.AST) -> Iterator[ast.Import | ast.ImportFrom]:
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node


def _names(node: ast.Import | ast.ImportFrom, path: Path, root: Path) -> set[str]:
    """Absolute names an import statement reaches (relative imports resolved)."""
    if isinstance(node, ast.Import):
        return {a.name for a in node.names}
    here = list(path.relative_to(root).with_suffix("").parts)[:-1]
    base = here[: len(here) - node.level + 1] if node.level else []
    module = ".".join([*base, node.module] if node.module else base)
    return {module} | {f"{module}.{a.name}" for a in node.names}


def _imports(path: Path, root: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return set().union(*(_names(n, path, root) for n in _import_nodes(tree)))


def _modules(root: Path = ROOT) -> dict[str, Path]:
    return {_name(p, root): p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))}


def _graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> the modules of ours it imports (a name imported from a package is the package,
    or its submodule when one has that name)."""
    modules = _modules(root)
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        deps = set()
        for target in _imports(path, root):
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                deps.add(target)
        graph[name] = deps
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    top = stack.pop()
                    on_stack.discard(top)
                    component.append(top)
                    if top == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def _offenders(
    room: str, rule: tuple[str, ...], *, outside: tuple[str, ...], root: Path = ROOT
) -> list[str]:
    bad = []
    for path in sorted((root / room).rglob("*.py")):
        name = ".".join(path.relative_to(root).with_suffix("").parts)
        if name.startswith(outside) or name.endswith("__main__"):
            continue
        hits = sorted(m for m in _imports(path, root) if m.startswith(rule))
        bad += [f"{name} imports {m}" for m in hits]
    return bad


def test_the_protocol_core_imports_no_tools_and_no_companion() -> None:
    assert (
        _offenders("protocol", ("protocol.tools", "companion"), outside=("protocol.tools",)) == []
    )
    assert _offenders("protocol", ("companion",), outside=()) == []


def test_the_product_imports_nothing_simulated_and_no_command_line() -> None:
    # the command line (companion.__main__, companion.cli) runs both rooms
    rule = ("companion.sim", "companion.cli", "protocol.tools")
    assert _offenders("companion", rule, outside=("companion.sim", "companion.cli")) == []
    assert _offenders("companion/sim", ("companion.cli",), outside=()) == []


def test_the_radio_and_the_credentials_are_bottom_layers() -> None:
    above = tuple(f"companion.{p}" for p in ("app", "cli", "mission", "neighbours", "runs", "sim"))
    assert _offenders("companion/radio", (*above, "companion.auth", "protocol"), outside=()) == []
    assert _offenders("companion/auth", (*above, "companion.radio"), outside=()) == []


def test_no_module_is_part_of_an_import_cycle() -> None:
    assert _cycles(_graph()) == []


def test_the_protocols_subpackages_are_layers() -> None:
    """protocol.wire < primitives < ot, circuits < geo < messages < run < suites < intersection
    < tools: at the granularity of subpackages, the imports have no cycle."""

    def package(name: str) -> str:
        return ".".join(name.split(".")[:2])

    packages: dict[str, set[str]] = {}
    for name, deps in _graph().items():
        if name.startswith("protocol.") and not name.endswith("__main__"):
            packages.setdefault(package(name), set()).update(
                package(d)
                for d in deps
                if d.startswith("protocol.") and package(d) != package(name)
            )
    assert _cycles(packages) == []


def test_the_companions_subpackages_are_layers() -> None:
    """radio, auth < mission < neighbours < runs < app < sim < cli: a subpackage imports only
    from those below it (and the shared top-level modules: errors, events, roles, tasks,
    logs, state, settings, context) -- the components of one companion are wired by the app,
    not by each other's packages."""
    order = ("radio", "auth", "mission", "neighbours", "runs", "app", "sim", "cli")
    rank = {f"companion.{p}": i for i, p in enumerate(order)}
    rank["companion.auth"] = rank["companion.radio"]  # (side by side at the bottom)
    bad = []
    for name, deps in _graph().items():
        here = ".".join(name.split(".")[:2])
        if here not in rank:
            continue
        for d in sorted(deps):
            there = ".".join(d.split(".")[:2])
            if there in rank and there != here and rank[there] >= rank[here]:
                bad.append(f"{name} imports {d}")
    assert bad == []


def _private_reaches(path: Path) -> list[str]:
    """``x._name`` in ``path`` where ``x`` is not ``self``/``cls`` and nothing in the module
    defines ``_name`` (a class reading its own kind's privates is fine)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    own: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            own.add(node.name)
        elif isinstance(node, ast.Name):
            own.add(node.id)
        elif (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in ("self", "cls")
        ):
            own.add(node.attr)
    return [
        f"{path.name}:{node.lineno} {ast.unparse(node)}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and node.attr.startswith("_")
        and not node.attr.endswith("_")
        and node.attr not in own
        and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))
        and not ast.unparse(node).startswith("argparse.")
    ]


def test_no_product_module_reaches_into_anothers_privates() -> None:
    bad = []
    for name, path in _modules().items():
        if name.startswith(("companion.sim", *COMMAND_LINE, "protocol.tools")):
            continue
        bad += _private_reaches(path)
    assert bad == []


def test_the_private_check_sees_a_reach(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text("class A:\n    def f(self, b):\n        return b._x, self._y\n")
    assert _private_reaches(probe) == ["probe.py:3 b._x"]


def test_no_module_of_ours_is_imported_inside_a_function() -> None:
    """No import hidden in a function to dodge a cycle (the command line may defer its heavy
    imports until a subcommand needs them)."""
    modules = _modules()
    bad = []
    for name, path in modules.items():
        if name.startswith(COMMAND_LINE):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for func in ast.walk(tree):
            if isinstance(func, ast.FunctionDef | ast.AsyncFunctionDef):
                for node in _import_nodes(func):
                    ours = sorted(n for n in _names(node, path, ROOT) if n.startswith(PACKAGES))
                    bad += [f"{name}.{func.name} imports {n}" for n in ours[:1]]
    assert bad == []


def test_the_check_sees_a_violation(tmp_path: Path) -> None:
    """The checker itself: a relative import of a tool from the core is caught."""
    (tmp_path / "protocol" / "tools").mkdir(parents=True)
    (tmp_path / "protocol" / "tools" / "cli.py").write_text("from ..geometry import x\n")
    (tmp_path / "protocol" / "probe.py").write_text("from .tools import cli\n")
    assert _offenders(
        "protocol", ("protocol.tools",), outside=("protocol.tools",), root=tmp_path
    ) == ["protocol.probe imports protocol.tools", "protocol.probe imports protocol.tools.cli"]


def test_the_cycle_check_sees_a_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _cycles(graph) == [["a", "b", "c"]]
