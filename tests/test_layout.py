"""The package's layout, read from its own imports: one way down, no cycles, simulators apart.

Every `import` counts, also those inside functions (the CLI imports lazily). The layers, from
the bottom: the foundation (errors, config, units, workers, rig); `columns/`; the reading and
decoding packages (`remote/`, `logs/`, `lidar/`, `camera/`); then `analysis/`, `calib/`,
`audit/`, `report/`, `writers/`, `simulate/`, `fleet/` and `cli/`. A package may import only
what its row allows.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "syncaudit"
FOUNDATION = {"errors", "config", "units", "workers", "rig", "__init__"}

# What each top-level part may import besides itself and the foundation.
ALLOWED: dict[str, set[str]] = {
    "foundation": set(),
    "__main__": {"cli"},
    "columns": set(),
    "remote": set(),
    "logs": {"remote", "columns"},
    "lidar": {"logs", "columns"},
    "camera": {"logs", "lidar", "columns"},
    "analysis": {"columns"},
    "calib": {"logs", "columns"},
    "audit": {"logs", "remote", "lidar", "camera", "columns", "analysis"},
    "writers": {"logs", "columns"},
    "report": {"columns", "analysis", "audit", "calib", "writers"},
    "simulate": {"lidar", "writers", "columns"},
    "fleet": {"logs", "remote", "lidar", "camera", "columns", "analysis", "audit", "calib"}
    | {"report", "writers"},
}
ALLOWED["cli"] = ALLOWED["fleet"] | {"simulate", "fleet"}
READING = {"logs", "remote", "lidar", "camera", "columns"}


def module_name(path: Path) -> str:
    """`syncaudit.a.b` for src/syncaudit/a/b.py (a package is its `__init__`)."""
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    """Every module of the package by dotted name."""
    return {module_name(p): p for p in PACKAGE.rglob("*.py")}


def imports(path: Path, known: set[str]) -> set[str]:
    """The package's modules that `path` imports anywhere in its body."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("syncaudit"):
                    found.add(_nearest(alias.name, known))
        elif (
            isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("syncaudit")
        ):
            for alias in node.names:
                child = f"{node.module}.{alias.name}"
                found.add(child if child in known else _nearest(node.module, known))
    return found


def _nearest(name: str, known: set[str]) -> str:
    while name not in known and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def part_of(module: str) -> str:
    """The top-level part a module belongs to (its package, or 'foundation')."""
    parts = module.split(".")
    if len(parts) == 1:
        return "foundation"
    head = parts[1]
    return "foundation" if head in FOUNDATION else head


def graph() -> dict[str, set[str]]:
    known = modules()
    names = set(known)
    return {name: imports(path, names) - {name} for name, path in known.items()}


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in edges:
                    continue
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_no_import_cycles() -> None:
    assert cycles(graph()) == []


def test_imports_run_one_way() -> None:
    wrong = []
    for module, targets in sorted(graph().items()):
        part = part_of(module)
        allowed = ALLOWED[part] | {part, "foundation"}
        for target in sorted(targets):
            target_part = part_of(target)
            if target_part not in allowed:
                wrong.append(f"{module} -> {target}")
    assert wrong == []


def test_reading_packages_import_nothing_above_them() -> None:
    above = set(ALLOWED) - READING - {"foundation"}
    wrong = [
        f"{module} -> {target}"
        for module, targets in sorted(graph().items())
        if part_of(module) in READING
        for target in sorted(targets)
        if part_of(target) in above
    ]
    assert wrong == []


def test_simulators_import_nothing_they_check() -> None:
    wrong = [
        f"{module} -> {target}"
        for module, targets in sorted(graph().items())
        if part_of(module) == "simulate"
        for target in sorted(targets)
        if part_of(target) in {"calib", "analysis", "audit"}
    ]
    assert wrong == []


def test_module_names_say_one_job() -> None:
    """No two modules of one name in different packages, but for one job per format.

    `logs.mcap.reader` and `logs.ros1.reader` do one job for two formats (as rosbags'
    `rosbag1/reader.py` and `rosbag2/reader.py`): siblings of one package may share names.
    """
    by_name: dict[str, set[str]] = defaultdict(set)
    for module in modules():
        parts = module.split(".")
        if len(parts) >= 3 and parts[-1] != "__main__":
            by_name[parts[-1]].add(".".join(parts[:-2]))
    assert {name: sorted(homes) for name, homes in by_name.items() if len(homes) > 1} == {}


def test_the_checker_sees_a_cycle_and_a_lazy_import(tmp_path: Path) -> None:
    """The checks above could not pass by reading nothing."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    lazy = tmp_path / "lazy.py"
    lazy.write_text("def f():\n    from syncaudit.audit.run import audit_log\n")
    assert imports(lazy, set(modules())) == {"syncaudit.audit.run"}
    assert part_of("syncaudit.errors") == "foundation"
    assert part_of("syncaudit.logs.mcap.reader") == "logs"
