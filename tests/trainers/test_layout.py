"""The trainers' layout shows the architecture (issue 51): subpackages by role, agents only in
``skillchain_torch.agents``, and no import circle among the trainers' modules."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TRAINERS = ROOT / "trainers"
ROLES = {"loop", "config", "outputs", "distributed", "study"}


def test_trainers_top_level_holds_only_its_subpackages():
    modules = sorted(p.name for p in TRAINERS.glob("*.py"))
    packages = {p.name for p in TRAINERS.iterdir() if (p / "__init__.py").is_file()}
    assert modules == ["__init__.py"]
    assert packages == ROLES


def test_no_agent_class_outside_the_agents_package():
    for path in TRAINERS.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                assert not node.name.endswith("Agent"), f"{path}: class {node.name}"


def _trainers_graph() -> dict[str, set[str]]:
    names = {}
    for path in TRAINERS.rglob("*.py"):
        parts = [p for p in path.relative_to(TRAINERS).with_suffix("").parts if p != "__init__"]
        names[".".join(["skillchain_torch.trainers", *parts])] = path
    graph = {name: set() for name in names}
    for name, path in names.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module in names and node.level == 0:
                if not path.name == "__init__.py":
                    graph[name].add(node.module)
    return graph


def test_no_import_circle_among_the_trainers_modules():
    graph = _trainers_graph()
    state: dict[str, int] = {}

    def visit(name, path):
        state[name] = 1
        for nxt in graph[name]:
            if nxt.count(".") < 3:  # a package's __init__ (lazy re-exports), not a module
                continue
            assert state.get(nxt) != 1, f"import circle: {' -> '.join([*path, nxt])}"
            if nxt not in state:
                visit(nxt, [*path, nxt])
        state[name] = 2

    for name in graph:
        if name not in state:
            visit(name, [name])
    assert graph["skillchain_torch.trainers.config.cli"]  # the graph is read, not empty
