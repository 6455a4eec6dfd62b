"""The layout of the package: its top level holds rooms (packages), the imports between them
point one way (read from the sources: every import, at module level or inside a function), and
no module grows past one concept's size."""

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



ROOMS: dict[str, set[str]] = {
    "core": set(),
    "geo": {"core"},
    "sensors": {"core", "geo"},
    "filters": {"core", "geo", "sensors"},
    "sim": {"core", "geo", "sensors"},
    "io": {"core"},
    "metrics": {"core", "geo", "sensors", "filters"},
    "logs": {"core", "geo", "sensors", "filters", "io", "metrics"},
    "replay": {"core", "geo", "sensors", "filters", "io", "metrics"},
    "campaign": {"core", "geo", "sensors", "filters", "sim", "io", "metrics", "logs", "replay"},
    "export": {"core", "geo", "filters", "io", "metrics"},
    "viz": {"core", "geo", "filters", "io", "metrics"},
    "report": {"core", "geo", "filters", "io", "metrics", "export", "viz"},
}
"""What each room may import: the rows of the import table of docs/architecture.md. The
applications (``reproduce``, ``jobs``) and the edge (``cli``) may import any room below them."""
APPLICATIONS = {"reproduce": {"jobs", "cli"}, "jobs": {"cli"}, "cli": set()}
"""The applications and the rooms they must not import."""

MAX_LINES = 800
"""One concept per module: past this size a module holds several (split it where the concepts
part, as the filters' models and compiled kernels are modules of their own)."""

LONGER = {
    "navreplay/filters/kalman.py": 850,
    "navreplay/filters/ins_time_update.py": 900,
}
"""Modules allowed past MAX_LINES, with their ceiling. Both are one concept whose compiled
kernels sit beside the readable equations the tests compare them with: the Kalman prediction
and correction (kalman.py), the INS time update as one compiled entry point and the class that
drives it (ins_time_update.py); the Gauss-Markov GNSS states and the IMU column states took
them past the limit. The next change to either moves its kernels into a module of their own."""


def test_the_top_level_holds_rooms() -> None:
    loose = sorted(p.name for p in ROOT.glob("*.py")
                   if p.name not in ("__init__.py", "__main__.py"))
    assert not loose, f"modules outside a room: {loose}"
    rooms = {p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file()}
    assert rooms == set(ROOMS) | set(APPLICATIONS), rooms ^ (set(ROOMS) | set(APPLICATIONS))


def test_each_room_imports_only_the_rooms_below_it() -> None:
    graph = _graph(_unit)
    for room, allowed in ROOMS.items():
        extra = graph.get(room, set()) - allowed
        assert not extra, f"{room} imports {sorted(extra)}"
    for app, forbidden in APPLICATIONS.items():
        assert not graph.get(app, set()) & forbidden, f"{app} imports {forbidden}"


def test_no_module_exceeds_the_line_limit() -> None:
    sizes = {str(p.relative_to(ROOT.parent)): len(p.read_text().splitlines())
             for p in ROOT.rglob("*.py")}
    assert max(sizes.values()) > 100  # the files were read
    long = {name: n for name, n in sizes.items() if n > LONGER.get(name, MAX_LINES)}
    assert not long, f"modules over {MAX_LINES} lines: {long}"
    assert all(name in sizes for name in LONGER), "LONGER names a module that is gone"


def test_a_run_does_not_import_the_simulation_statistics() -> None:
    """The modules of ``navreplay run`` (its view and exports too) leave scipy.signal and
    scipy.stats unimported: they cost about a second of start-up."""
    import subprocess
    import sys

    code = ("import sys, navreplay.cli, navreplay.jobs.run, navreplay.viz.sink, "
            "navreplay.export; print(sorted(m for m in ('scipy.signal', 'scipy.stats') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
