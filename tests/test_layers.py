"""The package's import graph: no cycle between modules, and no import upward.

Every ``import`` statement of the package counts, at module level or inside
a function. Layers, bottom to top (a package may import only from its own
layer or below):

    exceptions statuses profiles published memory atomic cache packed known native_output
    robot rnn backends metrics formats reference reference_solve reference_pool
    control
    sim
    selection report
    harness scaling sweep executors
    commands cli

``jit`` warms every compiled kernel (the backends', the network's, the
loop's) and so sits beside all of them: the loop calls it before its clock
starts, it imports their modules, and no module cycle results (checked below).
"""

from __future__ import annotations

import ast
from pathlib import Path

import qpbench

ROOT = Path(qpbench.__file__).resolve().parent

LAYERS = [
    {
        "exceptions",
        "statuses",
        "profiles",
        "published",
        "memory",
        "atomic",
        "cache",
        "packed",
        "known",
        "native_output",
        "qpbench",
    },
    {
        "robot",
        "rnn",
        "backends",
        "metrics",
        "formats",
        "reference",
        "reference_solve",
        "reference_pool",
    },
    {"control"},
    {"sim"},
    {"selection", "report"},
    {"harness", "scaling", "sweep", "executors"},
    {"commands", "cli"},
]
#: Allowed across layers in both directions (see the module docstring).
BESIDE_ALL = {"jit"}


def _modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets = [
                f"{module}.{a.name}" if f"{module}.{a.name}" in modules else module
                for a in node.names
            ]
        for target in targets:
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target.startswith("qpbench") and target != name:
                found.add(target)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _group(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "qpbench"


def _layer(group: str) -> int:
    return next(i for i, layer in enumerate(LAYERS) if group in layer)


def test_every_package_has_a_layer():
    groups = {_group(m) for m in _graph()} - BESIDE_ALL
    assert all(any(g in layer for layer in LAYERS) for g in groups), groups


def test_no_upward_import():
    upward = []
    for module, deps in _graph().items():
        a = _group(module)
        for dep in deps:
            b = _group(dep)
            if a in BESIDE_ALL or b in BESIDE_ALL:
                continue
            if _layer(b) > _layer(a):
                upward.append(f"{module} -> {dep}")
    assert upward == []


def test_no_import_cycle():
    graph = _graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(node, path):
        state[node] = 1
        for dep in graph[node]:
            if state.get(dep) == 1:
                cycles.append(path[path.index(dep) :] + [dep])
            elif dep not in state:
                visit(dep, path + [dep])
        state[node] = 2

    for node in graph:
        if node not in state:
            visit(node, [node])
    assert cycles == []


def test_markdown_and_plots_do_not_import_each_other():
    graph = _graph()
    assert "qpbench.report.plots" not in graph["qpbench.report.markdown"]
    assert "qpbench.report.markdown" not in graph["qpbench.report.plots"]
