"""The layers of docs/architecture.md, read from the import graph: every module imports only
from its own layer or those below it, and no chain of imports leads back to where it started.

Imports inside functions count too: a lazy import of a higher layer is still a dependency."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("marl_vertiport", "agents")

#: (layer, module prefixes), lowest first; a module belongs to the layer of its longest prefix.
LAYERS = (
    (0, ("marl_vertiport.config", "marl_vertiport.sim")),            # simulator core and its config
    (1, ("marl_vertiport",)),                                         # env APIs
    (2, ("agents.common", "agents.execution", "agents.controllers",
         "agents.gcn")),                                              # controllers
    (3, ("agents.evaluate", "agents.sweep")),                         # evaluation
    (4, ("agents", "agents.training", "agents.train", "agents.render", "agents.bench",
         "agents.studies", "agents.curves", "agents.interop", "agents.checks")),        # training and tools
)
LAYER_NAMES = ("simulator core", "env APIs", "controllers", "evaluation", "training and tools")


def layer_of(module: str) -> int:
    best, layer = -1, None
    for number, prefixes in LAYERS:
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best:
                best, layer = len(prefix), number
    assert layer is not None, f"{module} is in no layer of LAYERS"
    return layer


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (at the top or inside functions)."""
    modules = {module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        targets: set[str] = set()
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:  # relative: resolve against this module's package
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*anchor, base] if base else anchor)
                # ``from pkg import mod`` names a submodule when one exists.
                found = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                         for a in node.names]
            else:
                continue
            targets.update(t for t in found if t.split(".")[0] in PACKAGES and t != name)
        graph[name] = targets
    return graph


GRAPH = import_graph()


def test_every_module_has_a_layer():
    for module in GRAPH:
        layer_of(module)


def upward_imports(module: str, targets: set[str]) -> list[str]:
    """Those of ``targets`` in a layer above ``module``'s."""
    return sorted(t for t in targets if layer_of(t) > layer_of(module))


@pytest.mark.parametrize("module", sorted(GRAPH))
def test_imports_point_down(module):
    mine = layer_of(module)
    upward = upward_imports(module, GRAPH[module])
    assert not upward, (f"{module} ({LAYER_NAMES[mine]}) imports from a layer above it: "
                        + ", ".join(f"{t} ({LAYER_NAMES[layer_of(t)]})" for t in upward))


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """A cycle of ``edges`` (node -> nodes it points to) as the list of its nodes, first node
    repeated at the end; None when there is none (depth-first search for a back edge)."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(edges):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_no_import_cycle():
    cycle = find_cycle(GRAPH)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_checker_flags_upward_imports_and_reads_lazy_ones():
    """The checker itself: the former cycle's edge (inference importing training) is flagged,
    a downward import is not, and an import inside a function is in the graph."""
    assert upward_imports("agents.controllers.gcn", {"agents.training.pipeline"}) == [
        "agents.training.pipeline"]
    assert upward_imports("agents.controllers.dispatcher", {"agents.evaluate.cli"}) == [
        "agents.evaluate.cli"]
    assert upward_imports("agents.evaluate.run", {"agents.controllers.registry",
                                                   "marl_vertiport.sim.core"}) == []
    # registry.py imports the GCN controller inside make_controller only.
    assert "agents.controllers.gcn" in GRAPH["agents.controllers.registry"]


def folder_of(module: str) -> str:
    """The folder (package) a module's file lies in."""
    path = ROOT.joinpath(*module.split("."))
    return module if path.is_dir() else module.rpartition(".")[0]


def test_a_folder_is_one_layer():
    """Every module of a folder is in the same layer: the folder tree shows the layers."""
    layers: dict[str, set[int]] = {}
    for module in GRAPH:
        layers.setdefault(folder_of(module), set()).add(layer_of(module))
    mixed = {folder: sorted(found) for folder, found in layers.items() if len(found) > 1}
    assert not mixed, f"folders holding modules of several layers: {mixed}"


def folder_edges(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Folder -> the other folders its modules import."""
    edges: dict[str, set[str]] = {}
    for module, targets in graph.items():
        here = folder_of(module)
        edges.setdefault(here, set()).update(folder_of(t) for t in targets if folder_of(t) != here)
    return edges


def test_no_import_cycle_between_folders():
    """Folders import each other in one direction only: a loop at folder level (two folders, or
    more) makes several rooms one."""
    loop = find_cycle(folder_edges(GRAPH))
    assert loop is None, "folders in a loop: " + " -> ".join(loop)


def test_the_folder_checks_catch_a_loop_and_a_mixed_folder():
    """The checks themselves, on made-up graphs: a loop through three folders, and the loop of
    the former layout (inference in agents.gcn importing controllers, the registry importing it)."""
    made_up = {"agents.controllers.registry": {"agents.gcn.policy"},
               "agents.gcn.policy": {"agents.controllers.base"}}
    assert find_cycle(folder_edges(made_up)) == ["agents.controllers", "agents.gcn",
                                                 "agents.controllers"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


MAX_LINES = 500


def test_no_python_file_over_500_lines():
    """One job per file: a file past 500 lines holds several, and goes by concern."""
    files = [p for d in (*PACKAGES, "tests", "examples") for p in (ROOT / d).rglob("*.py")]
    assert len(files) > 100, "the walk found too few files to mean anything"
    long = {str(p.relative_to(ROOT)): n for p in files
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"files over {MAX_LINES} lines: {long}"
