"""The rooms of docs/architecture.md, checked on the source: the protocol's core imports
neither its tools nor the companion; the companion's product imports nothing simulated."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _imports(path: Path, root: Path) -> set[str]:
    """Absolute names of the modules ``path`` imports (relative imports resolved)."""
    here = list(path.relative_to(root).with_suffix("").parts)[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = here[: len(here) - node.level + 1] if node.level else []
            module = ".".join([*base, node.module] if node.module else base)
            out.add(module)
            out |= {f"{module}.{a.name}" for a in node.names}
    return out


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


def test_the_product_imports_nothing_simulated() -> None:
    # the command line (companion.__main__, companion.commands) runs both rooms
    outside = ("companion.sim", "companion.commands")
    assert _offenders("companion", ("companion.sim",), outside=outside) == []


def test_the_check_sees_a_violation(tmp_path: Path) -> None:
    """The checker itself: a relative import of a tool from the core is caught."""
    (tmp_path / "protocol" / "tools").mkdir(parents=True)
    (tmp_path / "protocol" / "tools" / "cli.py").write_text("from ..geometry import x\n")
    (tmp_path / "protocol" / "probe.py").write_text("from .tools import cli\n")
    assert _offenders(
        "protocol", ("protocol.tools",), outside=("protocol.tools",), root=tmp_path
    ) == ["protocol.probe imports protocol.tools", "protocol.probe imports protocol.tools.cli"]
