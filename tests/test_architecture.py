"""The house's rules, read from the code's own imports (every import statement, including
those inside functions and under TYPE_CHECKING):

- the physics (plant_rt) imports nothing from the bench (hil), the wire protocol (protocol)
  or the benchmarks; it stands on the configuration layer (configfile) alone;
- the configuration layer imports nothing of the project above it;
- hil imports nothing from bench/ (the benchmarks use the bench, not the reverse);
- no import circles among the project's modules.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("configfile", "plant_rt", "protocol", "hil", "bench")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in sorted((REPO / pkg).rglob("*.py"))}


def _imports(path: Path, name: str, known: set[str]) -> set[str]:
    """Project modules `path` imports (a `from pkg import mod` names the submodule)."""
    tree = ast.parse(path.read_text(), str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".") if is_package else name.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{a.name}" for a in node.names] + [base]
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    known = set(modules)
    return {name: _imports(path, name, known) for name, path in modules.items()}


def _top(module: str) -> str:
    return module.split(".")[0]


@pytest.mark.parametrize("lower,forbidden", [
    ("plant_rt", {"hil", "protocol", "bench"}),
    ("configfile", {"hil", "protocol", "bench", "plant_rt"}),
    ("protocol", {"hil", "bench", "plant_rt"}),
    ("hil", {"bench"}),
])
def test_dependencies_point_one_way(lower, forbidden):
    wrong = sorted(f"{m} -> {t}" for m, targets in _graph().items() if _top(m) == lower
                   for t in targets if _top(t) in forbidden)
    assert not wrong, f"{lower} must not import {sorted(forbidden)}: {wrong}"


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_circles():
    graph = _graph()
    # a package's __init__ that re-exports its own modules is not a circle with them
    for name in graph:
        graph[name] = {t for t in graph[name] if not name.startswith(t + ".")}
    assert _circles(graph) == []


def test_the_circle_finder_finds_a_circle():
    """The check above can fail: a made-up graph with a circle is reported."""
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_plant_switch_word_is_the_protocol_gates_word():
    """The bench hands a board's GATES word to the plant unchanged: the two layouts agree."""
    from plant_rt import inverter
    from protocol import messages

    for leg in "ABC":
        for side in ("HIGH", "LOW"):
            assert getattr(inverter, f"SWITCH_{leg}_{side}") == getattr(messages, f"GATE_{leg}_{side}")
