"""The layout of the package: imports between its packages (and top-level modules) point one
way, read from the sources (every import, at module level or inside a function)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "navreplay"


def _imports(path: Path) -> set[str]:
    """The navreplay modules a source file imports (``from navreplay.x import y`` names
    ``navreplay.x.y`` when that is a module)."""
    tree = ast.parse(path.read_text(), str(path))
    package = ".".join(path.relative_to(ROOT.parent).with_suffix("").parts)
    if path.name == "__init__.py":
        package = package.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("navreplay")}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            if base.startswith("navreplay"):
                modules = {f"{base}.{a.name}" for a in node.names
                           if _is_module(f"{base}.{a.name}")}
                out |= modules
                if len(modules) < len(node.names):  # names defined in ``base`` itself
                    out.add(base)
    return out


def _is_module(name: str) -> bool:
    rel = Path(*name.split(".")[1:])
    return (ROOT / rel).with_suffix(".py").is_file() or (ROOT / rel / "__init__.py").is_file()


def _unit(module: str) -> str:
    """The package (or top-level module) of navreplay a module belongs to."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _graph(level) -> dict[str, set[str]]:  # noqa: ANN001
    graph: dict[str, set[str]] = {}
    for path in ROOT.rglob("*.py"):
        module = ".".join(path.relative_to(ROOT.parent).with_suffix("").parts)
        if path.name == "__init__.py":
            module = module.rsplit(".", 1)[0]
        a = level(module)
        for imported in _imports(path):
            b = level(imported)
            if a and b and a != b:
                graph.setdefault(a, set()).add(b)
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of the graph (its nodes in order), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_no_cycle_between_packages() -> None:
    graph = _graph(_unit)
    assert {"replay", "campaign", "metrics", "io", "filters"} <= set(graph)
    cycle = _cycle(graph)
    assert cycle is None, "packages import each other: " + " -> ".join(cycle)


def test_the_layers_point_one_way() -> None:
    """The engine and the scoring below the campaigns, the outputs and the jobs; filters and
    io below the replay; viz imported by the jobs, the command line and the reproductions only."""
    graph = _graph(_unit)
    for low, high in [("replay", "campaign"), ("metrics", "replay"), ("filters", "replay"),
                      ("io", "replay"), ("filters", "metrics"), ("io", "logs"),
                      ("replay", "jobs"), ("campaign", "jobs")]:
        assert high not in graph.get(low, set()), f"{low} imports {high}"
    for unit, deps in graph.items():
        for pkg in ("filters", "io", "metrics", "replay", "campaign", "sim", "sensors", "geo"):
            if unit == pkg:
                assert "viz" not in deps and "jobs" not in deps and "cli" not in deps, unit
    assert not ({"io", "viz", "replay", "metrics"} & graph.get("filters", set()))

